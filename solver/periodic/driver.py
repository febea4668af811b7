"""The engine over a batch of points: ``solve_points`` deals the sweeps (warm-started
chains of points) to threads, each lane keeping one step record; ``solve`` is the entry of
``solve.solve_periodic(method="periodic")``; ``fixed_grid_points`` solves on given grids
(order tests).  One point is ``periodic.point.solve_point``.
"""
from __future__ import annotations

from concurrent.futures import ThreadPoolExecutor
from typing import NamedTuple

import numpy as np
from numba import get_num_threads, njit

from ..model.physics import PointPhysics
from ..status import CONVERGED, NON_FINITE
from .options import checked_options
from .point import N_COSTS, Orbit, fixed_grid_point, no_orbit, solve_point
from .record import new_workspace, node_series


@njit(cache=True, nogil=True, error_model="numpy")
def _fixed_grid_lane(lane, lanes, points, grids, rtol, vscale, out, options):
    """Points lane, lane + lanes, ... of ``fixed_grid_points``; out: (int_u, int_pi, status)."""
    for i in range(lane, points.params.shape[0], lanes):
        phys = PointPhysics(points.kappa[i], points.mu_n[i], points.mu_s[i], points.p[i],
                            points.dtau[i])
        out[0][i], out[1][i], out[2][i] = fixed_grid_point(
            points.code, points.params[i], grids[i], phys, rtol, vscale[i], points.u_guess[i],
            options)


def fixed_grid_points(points, grids, rtol, vscale, threads, options=None):
    """``fixed_grid_point`` of every point of ``points`` (Points; its corners unused) on its
    row of ``grids``, on ``threads`` Python threads: (int_u, int_pi, status), each (n,).
    ``options``: an ``EngineOptions`` (None: the defaults)."""
    options = checked_options(options)
    n = points.params.shape[0]
    out = (np.full(n, np.nan), np.full(n, np.nan), np.full(n, NON_FINITE, dtype=np.int8))
    lanes = max(min(n, threads), 1)
    if lanes == 1:
        _fixed_grid_lane(0, 1, points, grids, rtol, vscale, out, options)
        return out
    with ThreadPoolExecutor(lanes) as pool:
        for _ in pool.map(lambda lane: _fixed_grid_lane(lane, lanes, points, grids, rtol,
                                                        vscale, out, options), range(lanes)):
            pass
    return out


class Points(NamedTuple):
    """A batch of points for ``solve_points``: the kinematics' ``code``; per point (rows,
    n points) ``params`` (n, k) and ``corners`` (n, c) (``model.kinematics``), the physics
    ``kappa``, ``mu_n``, ``mu_s``, ``p``, ``dtau`` (n,) (``PointPhysics``) and ``u_guess``
    (n,), the start of a cold solve."""

    code: int
    params: np.ndarray
    corners: np.ndarray
    kappa: np.ndarray
    mu_n: np.ndarray
    mu_s: np.ndarray
    p: np.ndarray
    dtau: np.ndarray
    u_guess: np.ndarray


class Outputs(NamedTuple):
    """``solve_points``' results, per point (n,): ``PointSolution``'s fields (evaluations
    (n, N_COSTS)).  A point no thread reached reports NON_FINITE, not status 0 with NaN."""

    int_u: np.ndarray
    int_pi: np.ndarray
    u0: np.ndarray
    status: np.ndarray
    n_steps: np.ndarray
    passes: np.ndarray
    estimate: np.ndarray
    vscale: np.ndarray
    evaluations: np.ndarray
    start: np.ndarray
    estimate_u: np.ndarray
    estimate_p: np.ndarray


@njit(cache=True, error_model="numpy")
def _new_outputs(n):
    return Outputs(np.full(n, np.nan), np.full(n, np.nan), np.full(n, np.nan),
                   np.full(n, NON_FINITE, dtype=np.int8), np.zeros(n, dtype=np.int64),
                   np.zeros(n, dtype=np.int64), np.full(n, np.inf), np.full(n, np.nan),
                   np.zeros((n, N_COSTS), dtype=np.int64), np.zeros(n, dtype=np.int8),
                   np.full(n, np.inf), np.full(n, np.inf))


@njit(cache=True, error_model="numpy")
def _store(out, i, sol):
    out.int_u[i] = sol.int_u
    out.int_pi[i] = sol.int_pi
    out.u0[i] = sol.u0
    out.status[i] = sol.status
    out.n_steps[i] = sol.n_steps
    out.passes[i] = sol.passes
    out.estimate[i] = sol.estimate
    out.vscale[i] = sol.vscale
    out.evaluations[i, :] = sol.evaluations
    out.start[i] = sol.start
    out.estimate_u[i] = sol.estimate_u
    out.estimate_p[i] = sol.estimate_p


@njit(cache=True, error_model="numpy")
def _second_difference_small(a, b, c, share):
    return abs(a - 2.0 * b + c) <= share * max(abs(a), abs(b), abs(c), 1e-300)


@njit(cache=True, error_model="numpy")
def in_line(points, i, j, k, share):
    """Whether points i, j, k lie evenly spaced on a line in parameter space (every
    parameter and physical constant has a second difference within ``share`` of its size,
    ``BatchOptions.in_line_share``): then j's orbit and its change from i predict k's."""
    for c in range(points.params.shape[1]):
        if not _second_difference_small(points.params[i, c], points.params[j, c],
                                        points.params[k, c], share):
            return False
    return (_second_difference_small(points.kappa[i], points.kappa[j], points.kappa[k], share)
            and _second_difference_small(points.mu_n[i], points.mu_n[j], points.mu_n[k], share)
            and _second_difference_small(points.mu_s[i], points.mu_s[j], points.mu_s[k], share)
            and _second_difference_small(points.p[i], points.p[j], points.p[k], share)
            and _second_difference_small(points.dtau[i], points.dtau[j], points.dtau[k],
                                         share))


@njit(cache=True, error_model="numpy")
def predicted_u0(points, out, first, i, share):
    """u(0) of point i predicted from its sweep's points before it (from ``first`` on;
    ``out`` holds their results; point i - 1 converged): by the quadratic through the last
    three where the last four lie evenly on a line (``in_line`` with ``share``), by the line
    through the last two where the last three do, else the last one's."""
    u1 = out.u0[i - 1]
    if (i - 2 < first or out.status[i - 2] != CONVERGED
            or not in_line(points, i - 2, i - 1, i, share)):
        return u1
    u2 = out.u0[i - 2]
    if (i - 3 < first or out.status[i - 3] != CONVERGED
            or not in_line(points, i - 3, i - 2, i - 1, share)):
        return 2.0 * u1 - u2
    return 3.0 * u1 - 3.0 * u2 + out.u0[i - 3]


@njit(cache=True, error_model="numpy")
def _kept(buffer, size):
    """``buffer`` with room for ``size`` values (doubled, contents kept), or itself."""
    if size <= buffer.size:
        return buffer
    bigger = np.empty(max(2 * buffer.size, size))
    bigger[:buffer.size] = buffer
    return bigger


@njit(cache=True, nogil=True, error_model="numpy")
def solve_lane(lane, lanes, points, rtol, max_steps, runs, out, keep_series, options):
    """The sweeps lane, lane + lanes, ... of ``solve_points`` on one workspace: each point
    of a sweep starts from its predecessor's orbit, the first cold.  Releases the GIL (the
    lanes run on Python threads: numba's parallel loops do not take NamedTuples).

    Returns (tau, u): with ``keep_series``, the final pass's nodes (without tau = 1) and u
    there of every point of the lane's sweeps in the order solved, ``out.n_steps[i]`` of
    point i (read from the converged orbit in the workspace, not solved again); else empty."""
    capacity = options.batch.start_capacity
    W = new_workspace(capacity)
    kept_tau = np.empty(capacity if keep_series else 0)
    kept_u = np.empty(capacity if keep_series else 0)
    kept = 0
    for r in range(lane, runs.size - 1, lanes):
        orbit = no_orbit()
        for i in range(runs[r], runs[r + 1]):
            phys = PointPhysics(points.kappa[i], points.mu_n[i], points.mu_s[i], points.p[i],
                                points.dtau[i])
            start = orbit
            if orbit.N > 0:
                start = Orbit(orbit.N, predicted_u0(points, out, runs[r], i,
                                                    options.batch.in_line_share),
                              orbit.scale_u, orbit.scale_p, orbit.largest_weight)
            W, sol, orbit = solve_point(points.code, points.params[i], points.corners[i], phys,
                                        rtol, points.u_guess[i], max_steps, W, start, options)
            _store(out, i, sol)
            if keep_series:
                N = sol.n_steps
                tau, u = node_series(W, N)
                kept_tau = _kept(kept_tau, kept + N)
                kept_u = _kept(kept_u, kept + N)
                kept_tau[kept:kept + N] = tau
                kept_u[kept:kept + N] = u
                kept += N
    return kept_tau[:kept], kept_u[:kept]


def solve_points(points, rtol, max_steps, runs, threads, keep_series=False, options=None):
    """``solve_point`` over every point of ``points`` (Points), as the sweeps ``runs``:
    (n_runs + 1,) offsets from 0 to n, points runs[k] .. runs[k + 1] - 1 one sweep in that
    order (every point its own sweep: all cold).  Returns (``Outputs``, series): with
    ``keep_series`` the series is a list of each point's (u, tau) at its final nodes, else
    None.  The sweeps are dealt to 4 ``threads`` lanes in turn (sweep k to lane k mod
    lanes), so that each thread gets a share of the hard points; each lane keeps one
    workspace.  A sweep's results depend on its points alone, not on the threads.
    ``options``: an ``EngineOptions`` (``periodic.options``; None: the defaults)."""
    options = checked_options(options)
    out = _new_outputs(points.params.shape[0])
    lanes = max(min(runs.size - 1, 4 * threads), 1)
    keep = bool(keep_series)
    if threads <= 1 or lanes == 1:
        kept = [solve_lane(lane, lanes, points, rtol, max_steps, runs, out, keep, options)
                for lane in range(lanes)]
    else:
        with ThreadPoolExecutor(threads) as pool:
            kept = list(pool.map(lambda lane: solve_lane(lane, lanes, points, rtol, max_steps,
                                                         runs, out, keep, options),
                                 range(lanes)))
    if not keep:
        return out, None
    series = [None] * points.params.shape[0]
    for lane, (tau, u) in enumerate(kept):
        start = 0
        for r in range(lane, runs.size - 1, lanes):
            for i in range(runs[r], runs[r + 1]):
                end = start + int(out.n_steps[i])
                series[i] = (u[start:end], tau[start:end])
                start = end
    return out, series


def solve(kinematics, physics, rtol, max_steps, return_series, sweeps=None, options=None):
    """Batched ``solve_point`` for ``solve.solve_periodic(method="periodic")``.

    ``sweeps``: None (every point cold) or the offsets of ``solve_points``' runs; ``options``:
    an ``EngineOptions`` (None: the defaults).  Returns a
    dict with int_u, int_pi, status, estimate (and its parts of int u and int Pi,
    estimate_u and estimate_p), n_tau, iterations (passes over the period), still (phi
    constant: nothing solved), evaluations, start (``PointSolution.start``), options (the
    checked ``EngineOptions`` used) and, with ``return_series``, per point (u nodes, tau
    nodes)."""
    from ..model.limits import fast_limit_velocity

    options = checked_options(options)
    code, params = kinematics.kernel_encoding()
    n = params.shape[0]
    runs = np.arange(n + 1, dtype=np.int64) if sweeps is None else np.asarray(sweeps, np.int64)
    points = Points(code, params, kinematics.corners(), physics.inertia_factor, physics.mu_n,
                    physics.mu_s, physics.p, physics.delta_tau,
                    fast_limit_velocity(kinematics, physics, options.batch.guess_steps))
    out, series = solve_points(points, float(rtol), int(max_steps), runs, get_num_threads(),
                               return_series, options)
    return dict(int_u=out.int_u, int_pi=out.int_pi, status=out.status, estimate=out.estimate,
                estimate_u=out.estimate_u, estimate_p=out.estimate_p, n_tau=out.n_steps, iterations=out.passes, still=out.vscale == 0.0,
                series=series, evaluations=out.evaluations, start=out.start, options=options)

