"""The engine: the periodic steady state of eq. (Newtonu) by event-driven
3-stage Radau IIA with one-pass error control.

For each parameter point (``solve_point``, one compiled function, all points batched over
threads by ``solve_points``):

1. **Stops.** The kinematic step ends of the period (``periodic.switching.kinematic_stops``).
2. **Loose shooting.** Adaptive sweeps (``periodic.sweep.adaptive_sweep``) at the loose tolerance
   LOOSE_RTOL from the fast limit's u(0), each followed by a Newton step on u(0) with the
   sweep's monodromy, until u(0) moves by less than the loose tolerance: this finds the
   periodic orbit's neighbourhood and the node weights cheaply.
3. **Target sweep.** One adaptive sweep at the target, its steps judged by the loose
   solution's node weights, then Newton on u(0) by frozen-grid sweeps (``frozen_sweep``:
   on one step sequence the discrete period map is smooth and its monodromy exact) until
   the fixed point is within 1e-3 rtol V (the converged sweep is then shifted to it to first
   order along the stage sensitivities).  Where the frozen steps do not
   carry Newton there (a stage solve fails on them, or MAX_FROZEN_SWEEPS run out), the next
   round starts here again with an adaptive sweep, which places its steps anew.
4. **Estimate.** Every step's local error from its defect (``periodic.sweep.estimate_sweep``), or,
   where the shooting moved a state event off its node, from the step solved again split
   at the event (``periodic.sweep.event_split_errors``), carried to int u and int Pi by the node
   weights of the converged solution (``periodic.global_error``).  If the estimate exceeds rtol,
   the steps that asked for it get ceilings and steps 3-4 run again from the converged
   u(0), so that the new sweep also puts the moved events on nodes (at most MAX_ROUNDS
   times), then TOLERANCE_NOT_REACHED (or the last round's failure).  (Moving nodes onto
   the moved events instead cost more: bench at rtol 1e-7, 9,466 force evaluations per
   solve against 8,592.)

Failures are NaN plus a status code (``status``), never silent.
"""
from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np
from numba import get_num_threads, njit, prange

from .global_error import combine, local_error_estimate, node_weights, refinement_ceiling
from .shooting import (bracketed_newton_update, monodromy_factor, one_minus_monodromy,
                        stage_tolerance)
from .radau import ERROR_ORDER, PointPhysics, runtime_bool
from ..status import (CONVERGED, NO_MOTION, NON_FINITE, NOT_PERIODIC, STAGE_SOLVE_FAILED,
                      TOLERANCE_NOT_REACHED)
from .sweep import (MIN_STEP, CORNER_STOP, END_KIND, INT_P, INT_U, LAMBDA, M_MINUS_1, MU, Q_P, Q_U,
                     SENS, STAGE, T, U, WeightModel, adaptive_sweep, estimate_sweep, frozen_sweep,
                     event_split_errors, new_workspace, stage_kinematics_into, trapped_steps, Stops)
from .switching import MAX_STOPS, kinematic_stops, stop_speed, turning_stops

#: the stage tolerance is at most this share of delta_tau (p = 0; ``stage_atol``)
BAND_SHARE = 0.01
#: tolerance of the loose shooting (step 2)
LOOSE_RTOL = 1e-2
#: at most this many loose sweeps
MAX_LOOSE_SWEEPS = 8
#: the adaptive sweeps aim at this share of the tolerance (the rest is the margin for the
#: node weights of the converged solution, which the sweep only knew approximately)
TARGET_SHARE = 0.8
#: rounds of steps 3-4
MAX_ROUNDS = 4
#: frozen-grid Newton sweeps per round
MAX_FROZEN_SWEEPS = 30
#: a shooting residual kept where the frozen period map jumps over its fixed point counts
#: this many times its first-order effect on the period integrals (``solve_point``)
RESIDUAL_WEIGHT = 2.0
#: the force evaluations of a solve, by phase (``solve_point``'s last output)
COST_LOOSE, COST_ADAPTIVE, COST_FROZEN, COST_ESTIMATE = 0, 1, 2, 3
N_COSTS = 4
#: first step of the first sweep
FIRST_STEP = 1.0 / 16.0
#: workspace capacity a thread starts with (steps; it doubles when a point needs more)
START_CAPACITY = 512


class PointSolution(NamedTuple):
    """What ``solve_point`` returns besides its workspace.

    int_u, int_pi : the period integrals (NaN unless ``status`` is CONVERGED);
    u0 : the last u(0); status : ``status`` code; n_steps : the final sweep's steps (its
    solution is in the workspace's first n_steps columns); sweeps : sweeps made; estimate :
    the global error estimate in rtol's norm (inf: none); evaluations : (N_COSTS,) the
    evaluations of F by phase (COST_LOOSE, COST_ADAPTIVE, COST_FROZEN, COST_ESTIMATE);
    vscale : V = (1/4) int |dphi/dtau| dtau (``periodic.switching.stop_speed``; 0: phi is constant,
    nothing was solved)."""

    int_u: float
    int_pi: float
    u0: float
    status: int
    n_steps: int
    sweeps: int
    estimate: float
    evaluations: np.ndarray
    vscale: float


@njit(cache=True, error_model="numpy")
def stage_atol(rtol, scale, phys):
    """The stage Newton's tolerance: ``periodic.shooting.stage_tolerance`` of the scale, and for p = 0
    at most BAND_SHARE delta_tau: where the body sticks F rises by O(mu) across a band of
    u ~delta_tau wide, and stages solved only to a tolerance wider than it land anywhere on
    the saturated force (measured: delta 1e-10, tolerance 4e-8 V, u chattering +-1e-6 around
    rest, 131,072 steps)."""
    atol = stage_tolerance(rtol, scale)
    if phys.p == 0.0:
        atol = min(atol, BAND_SHARE * phys.dtau)
    return atol


@njit(cache=True, error_model="numpy")
def _largest_weight(model, scale_u, scale_p):
    """max(1, |lambda|, |mu| scale_u / scale_p) over the model's nodes: a stage error e moves
    U by lambda e (relative to scale_u) and P by mu e (relative to scale_p), so the stage
    tolerance is divided by it (at short periods lambda reaches 4e3, and stages solved to the
    plain tolerance left errors of 5 rtol)."""
    largest = 1.0
    for n in range(model.N + 1):
        largest = max(largest, abs(model.lam[n]), abs(model.mu[n]) * scale_u / scale_p)
    return largest


@njit(cache=True, error_model="numpy")
def _period_map(W, N, u0):
    """(g = u(1) - u(0), 1 - M) of a sweep: the shooting residual and one minus the
    monodromy (``periodic.shooting.one_minus_monodromy``)."""
    log_m = 0.0
    sign_m = 1.0
    for n in range(N):
        log_m, sign_m = monodromy_factor(log_m, sign_m, W[M_MINUS_1, n])
    return W[U, N] - u0, one_minus_monodromy(log_m, sign_m)


@njit(cache=True, error_model="numpy")
def _integrals(W, N):
    int_u = 0.0
    int_p = 0.0
    for n in range(N):
        int_u += W[INT_U, n]
        int_p += W[INT_P, n]
    return int_u, int_p


@njit(cache=True, error_model="numpy")
def shift_onto_fixed_point(W, N, shift):
    """Move the converged sweep, which starts ``shift`` short of the fixed point, onto it to
    first order along the sensitivities (no force evaluations)."""
    for n in range(N):
        W[U, n] += shift
        for i in range(3):
            W[STAGE + i, n] += W[SENS + i, n] * shift
        W[INT_U, n] += W[Q_U, n] * shift
        W[INT_P, n] += W[Q_P, n] * shift
        shift *= 1.0 + W[M_MINUS_1, n]
    W[U, N] += shift


@njit(cache=True, error_model="numpy")
def _model(W, N, ceilings):
    return WeightModel(W[T, :N + 1].copy(), W[LAMBDA, :N + 1].copy(), W[MU, :N + 1].copy(),
                       ceilings[:N].copy(), N)


class FrozenNewton(NamedTuple):
    """What ``frozen_newton`` returns.

    u0 : the last u(0); g, one_minus_M : the period map there (``_period_map``); status :
    CONVERGED (the fixed point within tol_fix, u0 inside the bracket) or the failure;
    restart_u0 : after a failure, where the next round's adaptive sweep starts (NaN: the
    failure stands); sweeps, evaluations : frozen sweeps made and their evaluations of F."""

    u0: float
    g: float
    one_minus_M: float
    status: int
    restart_u0: float
    sweeps: int
    evaluations: int


@njit(cache=True, error_model="numpy")
def frozen_newton(code, params, phys, u0, atol, W, N, tol_fix, bound):
    """Newton on u(0) over the N recorded steps of ``W`` (``frozen_sweep``, in place) until
    |g| <= tol_fix |1 - M|, bracketed in +-bound.

    Where the frozen steps do not carry Newton to the fixed point (a stage solve fails on
    them, a sweep is not finite, or MAX_FROZEN_SWEEPS run out), the next round's adaptive
    sweep places its steps anew: from Newton's last proposal after a failed stage solve,
    else from the best u(0) seen (smallest |g / (1 - M)|); where that is the start, the next
    round would repeat this one, and the failure stands (restart_u0 NaN), as it does where
    the period map itself is not finite."""
    lo, hi = -bound, bound
    start = best_u0 = u0
    best_residual = math.inf
    sweeps = 0
    evaluations = 0
    g = 0.0
    one_minus_M = 1.0
    status = NOT_PERIODIC
    for _ in range(MAX_FROZEN_SWEEPS):
        g, one_minus_M = _period_map(W, N, u0)
        if not (math.isfinite(g) and math.isfinite(one_minus_M) and one_minus_M != 0.0):
            return FrozenNewton(u0, g, one_minus_M, NON_FINITE, math.nan, sweeps, evaluations)
        if abs(g) <= tol_fix * abs(one_minus_M):
            status = CONVERGED if abs(u0) < 0.999 * bound else NOT_PERIODIC
            break
        if abs(g / one_minus_M) < best_residual:
            best_u0, best_residual = u0, abs(g / one_minus_M)
        u0, lo, hi = bracketed_newton_update(u0, g, one_minus_M, lo, hi)
        status, e = frozen_sweep(code, params, phys, u0, atol, W, N)
        sweeps += 1
        evaluations += e
        if status == STAGE_SOLVE_FAILED:
            return FrozenNewton(u0, g, one_minus_M, status, u0, sweeps, evaluations)
        if status != CONVERGED:
            break
        status = NOT_PERIODIC
    if status == CONVERGED:
        return FrozenNewton(u0, g, one_minus_M, status, math.nan, sweeps, evaluations)
    restart = best_u0 if best_u0 != start else math.nan
    return FrozenNewton(u0, g, one_minus_M, status, restart, sweeps, evaluations)


@njit(cache=True, error_model="numpy")
def solve_point(code, params, corners, phys, rtol, u_guess, max_steps, W):
    """The periodic solution of one point; see the module docstring.

    Parameters
    ----------
    code, params : the kinematics' kernel encoding (``model.kinematics``), one row.
    corners : (k,) corners of phi in [0, 1).
    phys : PointPhysics
    rtol : float
    u_guess : float
        Starting u(0) (the fast limit).
    max_steps : int
        Steps per period before STEP_BUDGET_EXCEEDED.
    W : workspace (``periodic.sweep.new_workspace``)

    Returns
    -------
    (W, PointSolution): W possibly grown, holding the final sweep.  Where phi is constant
    (V = 0) nothing is solved: status NO_MOTION, the integrals 0.
    """
    stops = np.empty(MAX_STOPS)
    n_stops, omax = kinematic_stops(code, params, corners, stops)
    vscale = stop_speed(code, params, stops, n_stops)
    evals = np.zeros(N_COSTS, dtype=np.int64)
    if vscale == 0.0:
        return W, PointSolution(0.0, 0.0, 0.0, NO_MOTION, 0, 0, 0.0, evals, vscale)
    stop_is_corner = np.zeros(n_stops, dtype=np.bool_)
    for j in range(n_stops):
        for c in corners:
            if stops[j] == c:
                stop_is_corner[j] = True
    stop_is_turning = turning_stops(code, params, stops, n_stops, omax)
    point_stops = Stops(stops, stop_is_corner, stop_is_turning, n_stops)
    tol_fix = max(1e-3 * rtol, 1e-13) * vscale
    loose = max(LOOSE_RTOL, rtol)
    u0 = u_guess
    bound = 1e3 * vscale + 10.0 * abs(u0)
    empty = np.zeros(1)
    model = WeightModel(empty, empty, empty, empty, 0)
    sweeps = 0
    N = 0
    nan = math.nan
    # step 2: loose shooting, judged in u alone, relative to V (int u and int Pi are not
    # known yet: the floor 1e-3 V of U's norm would make it a thousand times too strict)
    h_first = FIRST_STEP
    lo, hi = -bound, bound
    scale_u = scale_p = 1.0
    for _ in range(MAX_LOOSE_SWEEPS):
        sweep = adaptive_sweep(code, params, phys, point_stops, u0, h_first,
                               TARGET_SHARE * loose, vscale, math.inf, model,
                               stage_atol(loose, vscale, phys), W, max_steps, runtime_bool(True),
                               runtime_bool(False))
        W, N, status = sweep.W, sweep.N, sweep.status
        sweeps += 1
        evals[COST_LOOSE] += sweep.evaluations
        if status != CONVERGED:
            return W, PointSolution(nan, nan, u0, status, N, sweeps, math.inf, evals, vscale)
        int_u, int_p = _integrals(W, N)
        scale_u = max(abs(int_u), 1e-3 * vscale)
        scale_p = abs(int_p) if int_p != 0.0 else 1.0
        g, one_minus_M = _period_map(W, N, u0)
        if not (math.isfinite(g) and math.isfinite(one_minus_M) and one_minus_M != 0.0):
            return W, PointSolution(nan, nan, u0, NON_FINITE, N, sweeps, math.inf, evals, vscale)
        node_weights(W, N, one_minus_M)
        model = _model(W, N, np.full(N, math.inf))
        u_new, lo, hi = bracketed_newton_update(u0, g, one_minus_M, lo, hi)
        moved = abs(u_new - u0)
        u0 = u_new
        if moved <= loose * vscale:
            break
    # steps 3 and 4: the stage tolerance relative to U's norm (V is up to 1e3 times larger)
    atol = stage_atol(rtol, scale_u, phys) / _largest_weight(model, scale_u, scale_p)
    h_first = max((W[T, 1] - W[T, 0]) * (rtol / loose) ** (1.0 / ERROR_ORDER), 64.0 * MIN_STEP)
    estimate = math.inf
    ceilings = np.full(N, math.inf)
    failure = TOLERANCE_NOT_REACHED  # the reason of the last round's failure
    for _ in range(MAX_ROUNDS):
        sweep = adaptive_sweep(code, params, phys, point_stops, u0, h_first,
                               TARGET_SHARE * rtol, scale_u, scale_p, model, atol, W, max_steps,
                               runtime_bool(True), runtime_bool(True))
        W, N, status = sweep.W, sweep.N, sweep.status
        sweeps += 1
        evals[COST_ADAPTIVE] += sweep.evaluations
        if status != CONVERGED:
            return W, PointSolution(nan, nan, u0, status, N, sweeps, math.inf, evals, vscale)
        corner_nodes = np.zeros(N, dtype=np.bool_)
        for n in range(N - 1):
            corner_nodes[n + 1] = W[END_KIND, n] == CORNER_STOP
        round_start = u0
        fn = frozen_newton(code, params, phys, u0, atol, W, N, tol_fix, bound)
        sweeps += fn.sweeps
        evals[COST_FROZEN] += fn.evaluations
        u0, g, one_minus_M = fn.u0, fn.g, fn.one_minus_M
        residual = 0.0  # a shooting residual kept and counted (below)
        if fn.status != CONVERGED:
            failure = fn.status
            estimate = math.inf
            if math.isfinite(fn.restart_u0):
                u0 = fn.restart_u0
                continue
            if fn.status != NOT_PERIODIC:
                return W, PointSolution(nan, nan, u0, failure, N, sweeps, estimate, evals,
                                        vscale)
            # The frozen period map jumps over its fixed point (its bisection closed in on a
            # step of g, and its best u(0) is the round's start, so another round would
            # repeat this one): keep that start's solution unshifted and count its shooting
            # residual g in the estimate instead (RESIDUAL_WEIGHT, below).  (Measured:
            # long_period_powerlaw point 356 at rtol 1e-7, g from +5.4e-11 to -2.8e-10 across
            # 1e-21 of u(0), M = 0; NOT_PERIODIC before.)
            u0 = round_start
            status, e = frozen_sweep(code, params, phys, u0, atol, W, N)
            sweeps += 1
            evals[COST_FROZEN] += e
            if status != CONVERGED:
                return W, PointSolution(nan, nan, u0, failure, N, sweeps, estimate, evals,
                                        vscale)
            g, one_minus_M = _period_map(W, N, u0)
            if not (math.isfinite(g) and math.isfinite(one_minus_M) and one_minus_M != 0.0):
                return W, PointSolution(nan, nan, u0, failure, N, sweeps, estimate, evals,
                                        vscale)
            residual = g
        else:
            shift = g / one_minus_M
            shift_onto_fixed_point(W, N, shift)
            u0 += shift
        evals[COST_ESTIMATE] += estimate_sweep(code, params, phys, corner_nodes, atol, W, N)[1]
        split = np.zeros(N, dtype=np.bool_)
        evals[COST_ESTIMATE] += event_split_errors(code, params, phys, atol, W, N, split)[1]
        node_weights(W, N, one_minus_M)
        int_u, int_p = _integrals(W, N)
        scale_u = max(abs(int_u), 1e-3 * vscale)
        scale_p = abs(int_p) if int_p != 0.0 else 1.0
        shares = np.zeros(N)
        e_u, e_p = local_error_estimate(W, N, shares, scale_u, scale_p)
        # a kept shooting residual g is a jump of u at node 0: it moves int u by lambda_0 g
        # and int Pi by mu_0 g to first order (the node weights' meaning), counted twice
        e_u += RESIDUAL_WEIGHT * abs(W[LAMBDA, 0] * residual)
        e_p += RESIDUAL_WEIGHT * abs(W[MU, 0] * residual)
        estimate = combine(e_u, e_p, scale_u, scale_p)
        # the steps next to turning points judged again by the converged u (``trapped_steps``)
        trap_caps = np.full(N, math.inf)
        trapped, e = trapped_steps(code, params, phys, point_stops, W, N, trap_caps)
        evals[COST_ESTIMATE] += e
        if estimate <= rtol and trapped == 0:
            return W, PointSolution(int_u, int_p, u0, CONVERGED, N, sweeps, estimate, evals, vscale)
        failure = TOLERANCE_NOT_REACHED
        ceilings = np.full(N, math.inf)
        if estimate > rtol:
            asked = refinement_ceiling(W, N, shares, TARGET_SHARE * rtol, ceilings)
            if asked == 0:
                shrink = 0.9 * (rtol / estimate) ** (1.0 / ERROR_ORDER)
                for n in range(N):
                    ceilings[n] = shrink * (W[T, n + 1] - W[T, n])
        for n in range(N):
            ceilings[n] = min(ceilings[n], trap_caps[n])
        model = _model(W, N, ceilings)
        h_first = min(h_first, W[T, 1] - W[T, 0])
    return W, PointSolution(nan, nan, u0, failure, N, sweeps, estimate, evals, vscale)


@njit(cache=True, error_model="numpy")
def fixed_grid_point(code, params, grid, phys, rtol, vscale, u_guess):
    """The periodic solution of the Radau IIA discretisation on the given ``grid`` (N + 1,
    nodes from 0 to 1, with the corners of phi among them), without error control: Newton on
    u(0) by frozen sweeps.  For order tests.  Returns (int_u, int_pi, status)."""
    N = grid.size - 1
    W = new_workspace(N)
    phys_atol = stage_atol(rtol, vscale, phys)
    for n in range(N):
        W[T, n] = grid[n]
        W[T, n + 1] = grid[n + 1]
        stage_kinematics_into(code, params, W, n)
        W[U, n] = u_guess
        for i in range(3):
            W[STAGE + i, n] = u_guess
            W[SENS + i, n] = 0.0
    tol_fix = max(1e-3 * rtol, 1e-13) * vscale
    bound = 1e3 * vscale + 10.0 * abs(u_guess)
    status, _ = frozen_sweep(code, params, phys, u_guess, phys_atol, W, N)
    if status != CONVERGED:
        return math.nan, math.nan, status
    fn = frozen_newton(code, params, phys, u_guess, phys_atol, W, N, tol_fix, bound)
    if fn.status != CONVERGED:
        return math.nan, math.nan, fn.status
    shift_onto_fixed_point(W, N, fn.g / fn.one_minus_M)
    int_u, int_p = _integrals(W, N)
    return int_u, int_p, CONVERGED


@njit(cache=True, parallel=True, error_model="numpy")
def fixed_grid_points(code, params, grids, kappa, mu_n, mu_s, p, dtau, rtol, vscale, u_guess):
    """``fixed_grid_point`` over points (rows of ``grids``): (int_u, int_pi, status)."""
    n = grids.shape[0]
    int_u = np.empty(n)
    int_pi = np.empty(n)
    status = np.empty(n, dtype=np.int8)
    for i in prange(n):
        phys = PointPhysics(kappa[i], mu_n[i], mu_s[i], p[i], dtau[i])
        int_u[i], int_pi[i], status[i] = fixed_grid_point(code, params[i], grids[i], phys, rtol,
                                                          vscale[i], u_guess[i])
    return int_u, int_pi, status


@njit(cache=True, error_model="numpy")
def _solve_chunk(c, chunks, code, params, corners, kappa, mu_n, mu_s, p, dtau, rtol, u_guess,
                 max_steps, int_u, int_pi, u0, status, n_steps, sweeps, estimate, evaluations,
                 vscale):
    """The points c, c + chunks, ... of ``solve_points`` on one workspace."""
    W = new_workspace(START_CAPACITY)
    for i in range(c, params.shape[0], chunks):
        phys = PointPhysics(kappa[i], mu_n[i], mu_s[i], p[i], dtau[i])
        W, sol = solve_point(code, params[i], corners[i], phys, rtol, u_guess[i], max_steps, W)
        int_u[i] = sol.int_u
        int_pi[i] = sol.int_pi
        u0[i] = sol.u0
        status[i] = sol.status
        n_steps[i] = sol.n_steps
        sweeps[i] = sol.sweeps
        estimate[i] = sol.estimate
        evaluations[i, :] = sol.evaluations
        vscale[i] = sol.vscale


@njit(cache=True, parallel=True, error_model="numpy")
def solve_points(code, params, corners, kappa, mu_n, mu_s, p, dtau, rtol, u_guess, max_steps,
                 threads):
    """``solve_point`` over every point: (int_u, int_pi, u0, status, n_steps, sweeps,
    estimate, vscale), each (n_points,), and the evaluations of F, (n_points, N_COSTS)
    (``PointSolution``'s fields).  The points are dealt to the threads' chunks in turn (point
    i to chunk i mod chunks), so that numba's static split of the chunks gives each thread
    a share of the hard points; each chunk keeps one workspace."""
    n = params.shape[0]
    int_u = np.full(n, np.nan)
    int_pi = np.full(n, np.nan)
    u0 = np.full(n, np.nan)
    # (a point no thread reached reports a failure, not status 0 with NaN)
    status = np.full(n, NON_FINITE, dtype=np.int8)
    n_steps = np.zeros(n, dtype=np.int64)
    sweeps = np.zeros(n, dtype=np.int64)
    estimate = np.full(n, np.inf)
    evaluations = np.zeros((n, N_COSTS), dtype=np.int64)
    vscale = np.full(n, np.nan)
    chunks = max(min(n, 4 * threads), 1)
    for c in prange(chunks):
        _solve_chunk(c, chunks, code, params, corners, kappa, mu_n, mu_s, p, dtau, rtol, u_guess,
                     max_steps, int_u, int_pi, u0, status, n_steps, sweeps, estimate,
                     evaluations, vscale)
    return int_u, int_pi, u0, status, n_steps, sweeps, estimate, vscale, evaluations


@njit(cache=True, parallel=True, error_model="numpy")
def series_points(code, params, corners, kappa, mu_n, mu_s, p, dtau, rtol, u_guess, max_steps,
                  offsets, tau_out, u_out):
    """``solve_point`` of every point again (it is deterministic), writing the final grid's
    nodes without tau = 1 and u there into ``tau_out`` / ``u_out`` from ``offsets[i]`` on
    (``solve_points``' n_steps apart).  Returns each point's node count."""
    n = params.shape[0]
    counts = np.zeros(n, dtype=np.int64)
    for i in prange(n):
        W = new_workspace(START_CAPACITY)
        phys = PointPhysics(kappa[i], mu_n[i], mu_s[i], p[i], dtau[i])
        W, sol = solve_point(code, params[i], corners[i], phys, rtol, u_guess[i], max_steps, W)
        N = min(sol.n_steps, offsets[i + 1] - offsets[i])
        tau_out[offsets[i]:offsets[i] + N] = W[T, :N]
        u_out[offsets[i]:offsets[i] + N] = W[U, :N]
        counts[i] = N
    return counts


#: the fast limit's u (``model.limits.fast_limit_velocity``) that starts the shooting is taken on
#: this many steps: it is a guess (bench, rtol 1e-4: 64 steps cost 18.7 ms per 2,000 points
#: and the loose shooting 605 evaluations per solve, 8 steps 2.8 ms and 604, u = 0 571)
GUESS_STEPS = 8


def solve(kinematics, physics, rtol, max_steps, return_series):
    """Batched ``solve_point`` for ``solve.solve_periodic(method="periodic")``.

    Returns a dict with int_u, int_pi, status, estimate, n_tau, iterations (sweeps), still
    (phi constant: nothing solved), evaluations and, with ``return_series``, per point
    (u nodes, tau nodes)."""
    from ..model.limits import fast_limit_velocity

    code, params = kinematics.kernel_encoding()
    corners = kinematics.corners()
    u_guess = fast_limit_velocity(kinematics, physics, GUESS_STEPS)
    args = (code, params, corners, physics.inertia_factor, physics.mu_n, physics.mu_s,
            physics.p, physics.delta_tau, float(rtol), u_guess, int(max_steps))
    out = solve_points(*args, get_num_threads())
    int_u, int_pi, u0, status, n_steps, sweeps, estimate, vscale, evaluations = out
    series = None
    if return_series:
        offsets = np.concatenate([[0], np.cumsum(n_steps)])
        tau_out = np.empty(offsets[-1])
        u_out = np.empty(offsets[-1])
        counts = series_points(*args, offsets, tau_out, u_out)
        if not np.array_equal(counts, n_steps):
            raise RuntimeError("periodic: a point's second solve for its series took another grid")
        series = [(u_out[a:b], tau_out[a:b]) for a, b in zip(offsets[:-1], offsets[1:])]
    return dict(int_u=int_u, int_pi=int_pi, status=status, estimate=estimate, n_tau=n_steps,
                iterations=sweeps, still=vscale == 0.0, series=series, evaluations=evaluations)
