"""The ``march`` method: explicit RK2 (Heun) from rest until the motion is periodic.

This is the paper's first method.  Each period is marched on the same
corner-aligned grid as ``periodic``; after every period the change of u(0)
is compared with the contraction of the period map (the ratio of
successive changes, M): the distance to the periodic state is bounded by
|change| / (1 - M), and the march stops when that bound is below the
tolerance.  When the contraction is slow (M close to 1, short scaled
periods) an Aitken extrapolation jumps to the estimated fixed point.

It is explicit, so it is only stable while h T^(2-p) |dF/du| stays below
about 2; on stiff sticking phases it is not, the iterates blow up, and the
point is reported UNSTABLE rather than returned wrong.
"""
from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np
from numba import njit, prange

from ..model.force import force_and_slope, power_density
from ..model.kinematics import angle_and_rate
from ..model.physics import PointPhysics
from ..status import CONVERGED, NON_FINITE, STEP_BUDGET_EXCEEDED, UNSTABLE

#: Heun's method (explicit trapezoidal RK2).
HEUN_C = np.array([0.0, 1.0])
HEUN_A = np.array([[0.0, 0.0], [1.0, 0.0]])
HEUN_B = np.array([0.5, 0.5])
ORDER = 2


class PhysicsColumns(NamedTuple):
    """``PointPhysics``' fields for the n points of one ``march_level``, each of shape (n,)."""

    kappa: np.ndarray   # T^(2-p), the inertia factor in u' = kappa F
    mu_n: np.ndarray
    mu_s: np.ndarray
    p: np.ndarray
    dtau: np.ndarray    # delta_tau = T delta


class PeriodicityTest(NamedTuple):
    """When ``_march_point`` stops: u(0) within max(1e-5 rtol, 1e-13) vscale of the fixed
    point (the module docstring's bound), or ``max_steps`` steps marched."""

    vscale: float    # V, the point's speed scale (``model.limits.kinematic_speed``)
    rtol: float
    max_steps: int


class MarchRecord(NamedTuple):
    """The arrays ``_march_point`` writes (its caller allocates them, one set per thread)."""

    nodes: np.ndarray       # (N + 1,) u at the grid's nodes over the last period marched
    step_m: np.ndarray      # (N,) each step's du_{n+1}/du_n
    step_u: np.ndarray      # (N,) each step's trapezoidal integral of u
    step_pi: np.ndarray     # (N,) ... and of Pi
    step_stiff: np.ndarray  # (N,) bool: the step chatters through a sticking phase


@njit(cache=True, error_model="numpy")
def heun_step(u, h, phi0, om0, phi1, om1, phys):
    """One RK2 step (Butcher tableau HEUN_*) of u' = kappa F for ``phys`` (``PointPhysics``),
    phi and dphi/dtau at the step's ends given: pure function, no state.

    Returns (u_{n+1}, du_{n+1}/du_n).
    """
    kappa = phys.kappa
    F1, dF1 = force_and_slope(u, phi0, om0, phys.mu_n, phys.mu_s, phys.p, phys.dtau)
    F2, dF2 = force_and_slope(u + h * kappa * F1, phi1, om1, phys.mu_n, phys.mu_s, phys.p,
                              phys.dtau)
    m = 1.0 + 0.5 * h * kappa * (dF1 + dF2 * (1.0 + h * kappa * dF1))
    return u + 0.5 * h * kappa * (F1 + F2), m


#: a Heun step jumps across the steep part of F (a sticking band of width ~delta_tau)
#: when its stage forces have opposite signs and (F2 - F1) / F1 is below this (a
#: linear F gives 1 + (F2 - F1) / F1 = 1 + z, z = h T^(2-p) dF/du; chatter sits at -2)
JUMP_LIMIT = -1.5


@njit(cache=True, error_model="numpy")
def step_jumps(u, h, phi0, om0, phi1, om1, phys):
    """Whether a Heun step (``heun_step``'s arguments) from u jumps across a sticking band
    instead of resolving it."""
    F1, _ = force_and_slope(u, phi0, om0, phys.mu_n, phys.mu_s, phys.p, phys.dtau)
    F2, _ = force_and_slope(u + h * phys.kappa * F1, phi1, om1, phys.mu_n, phys.mu_s, phys.p,
                            phys.dtau)
    return F1 * F2 < 0.0 and (F2 - F1) / F1 < JUMP_LIMIT


@njit(cache=True, error_model="numpy")
def _step_kinematics(code, params, grid, N):
    """phi and dphi/dtau at both ends of every step (taken on the step's side of a corner)
    and the step lengths: (phis, oms) of shape (2N,), hs of shape (N,)."""
    phis = np.empty(2 * N)
    oms = np.empty(2 * N)
    hs = np.empty(N)
    for n in range(N):
        h = grid[n + 1] - grid[n]
        hs[n] = h
        mid = grid[n] + 0.5 * h
        phis[2 * n], oms[2 * n] = angle_and_rate(code, params, grid[n], mid)
        phis[2 * n + 1], oms[2 * n + 1] = angle_and_rate(code, params, grid[n + 1], mid)
    return phis, oms, hs


@njit(cache=True, error_model="numpy")
def _march_point(code, params, grid, N, phys, u_init, test, record):
    """March on the first N steps of ``grid`` from u(0) = ``u_init`` until periodic
    (``test``, a ``PeriodicityTest``), for ``phys`` (``PointPhysics``).

    On return (when CONVERGED) ``record`` (a ``MarchRecord``) holds in ``nodes[:N + 1]`` u at
    the grid's nodes over the last period marched, in ``step_m[:N]`` each step's
    du_{n+1}/du_n, in ``step_u``, ``step_pi`` each step's trapezoidal integral of u and Pi,
    and in ``step_stiff[:N]`` the steps that chatter through a sticking phase (consecutive
    ``step_jumps``).
    Returns (int_u, int_Pi, u0, status, periods, force evaluations).
    """
    nodes, step_m, step_u, step_pi, step_stiff = record
    phis, oms, hs = _step_kinematics(code, params, grid, N)
    # |u(0) - fixed point| <= tol_fix: a shift of u(0) carries about one for one into int u,
    # whose norm can be as small as 1e-3 V, so this is 1 % of rtol there
    tol_fix = max(1e-5 * test.rtol, 1e-13) * test.vscale
    bound = 1e3 * test.vscale + 1.0
    max_periods = max(test.max_steps // N, 3)
    u = u_init
    prev_change = math.nan
    prev_ratio = math.nan
    status = STEP_BUDGET_EXCEEDED
    period = 0
    evaluations = 0
    for period in range(1, max_periods + 1):
        u_begin = u
        nodes[0] = u
        for n in range(N):
            u, step_m[n] = heun_step(u, hs[n], phis[2 * n], oms[2 * n], phis[2 * n + 1],
                                     oms[2 * n + 1], phys)
            evaluations += 2
            nodes[n + 1] = u
            if not (abs(u) <= bound):
                status = UNSTABLE if math.isfinite(u) else NON_FINITE
                return math.nan, math.nan, u_begin, status, period, evaluations
        change = u - u_begin
        if change == 0.0:
            status = CONVERGED
            break
        ratio = change / prev_change if period > 1 else math.nan
        if period > 2 and 0.0 <= ratio < 1.0 and 0.0 <= prev_ratio < 1.0:
            contraction = max(ratio, prev_ratio)
            if abs(change) / (1.0 - contraction) <= tol_fix:
                status = CONVERGED
                break
            if contraction > 0.5 and abs(ratio - prev_ratio) < 0.05 * (1.0 - contraction):
                # geometric regime: jump to the fixed point (Aitken delta^2)
                u = u + change * ratio / (1.0 - ratio)
                prev_change = math.nan
                prev_ratio = math.nan
                continue
        prev_ratio = ratio
        prev_change = change
    if status != CONVERGED:
        return math.nan, math.nan, u, status, period, evaluations
    # the last period marched (from u_begin) is periodic to tolerance: trapezoidal quadrature
    int_u = 0.0
    int_pi = 0.0
    for n in range(N):
        h = hs[n]
        P0 = power_density(nodes[n], phis[2 * n], oms[2 * n], phys.mu_n, phys.mu_s, phys.p,
                           phys.dtau)
        P1 = power_density(nodes[n + 1], phis[2 * n + 1], oms[2 * n + 1], phys.mu_n,
                           phys.mu_s, phys.p, phys.dtau)
        step_u[n] = 0.5 * h * (nodes[n] + nodes[n + 1])
        step_pi[n] = 0.5 * h * (P0 + P1)
        int_u += step_u[n]
        int_pi += step_pi[n]
        step_stiff[n] = step_jumps(nodes[n], h, phis[2 * n], oms[2 * n], phis[2 * n + 1],
                                   oms[2 * n + 1], phys)
        evaluations += 2
    # one jump is a velocity reversal or a stop inside a step (harmless: the error
    # estimate sees it); consecutive jumps are chatter through a sticking phase: the
    # explicit method stalls at |u| ~ h T^(2-p) mu instead of ~delta_tau, an O(h) error
    # whose sign does not change with h, so comparing grids does not reliably see it
    first = step_stiff[0]
    prev = step_stiff[N - 1]
    for n in range(N):
        cur = step_stiff[n]
        nxt = step_stiff[n + 1] if n + 1 < N else first
        step_stiff[n] = cur and (prev or nxt)
        prev = cur
    return int_u, int_pi, nodes[0], CONVERGED, period, evaluations


@njit(cache=True, error_model="numpy")
def band_stiffness(phi, h, phys):
    """h T^(2-p) |dF/du| across the sticking band of a link at rest at angle phi:
    z = h kappa (mu_n sin^2 phi + mu_s cos^2 phi) delta_tau^(p-1) (the slope of F there,
    2 (mu_n S^2 + mu_s C^2) int_0^(1/2) r^(p-1) ds with r ~ delta_tau).  Heun resolves the
    band only for z below about 2 (its stability limit on the real axis)."""
    S = math.sin(phi)
    C = math.cos(phi)
    return (h * phys.kappa * (phys.mu_n * S * S + phys.mu_s * C * C)
            * max(phys.dtau, 1e-300) ** (phys.p - 1.0))


@njit(cache=True, parallel=True, error_model="numpy")
def march_level(code, params, grids, physics, u_init, vscale, rtol, max_steps):
    """``_march_point`` on every row of ``grids`` (shape (n, N + 1), one grid per point, all
    of N steps), one thread per point; ``physics`` (``PhysicsColumns``), ``u_init`` and
    ``vscale`` per point, ``rtol`` and ``max_steps`` (``PeriodicityTest``) for all.

    Returns (int_u, int_pi, u0, status, periods, evaluations, chatter_mass, stiffness,
    nodes): per point the period integrals, the periodic u(0), the ``status`` code,
    the periods marched and the force evaluations; ``chatter_mass`` = sum of |u_n| h_n
    over the chattering steps (0: none), ``stiffness`` the largest ``band_stiffness`` of
    a chattering step (0: none); ``nodes`` (n, N) u at the nodes without tau = 1.
    """
    n, m = grids.shape
    N = m - 1
    int_u = np.full(n, np.nan)
    int_pi = np.full(n, np.nan)
    u0 = np.full(n, np.nan)
    status = np.full(n, NON_FINITE, dtype=np.int8)
    periods = np.zeros(n, dtype=np.int64)
    evaluations = np.zeros(n, dtype=np.int64)
    chatter_mass = np.zeros(n)
    stiffness = np.zeros(n)
    nodes_out = np.full((n, N), np.nan)
    for i in prange(n):
        nodes = np.empty(N + 1)
        step_m = np.empty(N)
        step_u = np.empty(N)
        step_pi = np.empty(N)
        stiff = np.zeros(N, dtype=np.bool_)
        phys = PointPhysics(physics.kappa[i], physics.mu_n[i], physics.mu_s[i], physics.p[i],
                            physics.dtau[i])
        int_u[i], int_pi[i], u0[i], status[i], periods[i], evaluations[i] = _march_point(
            code, params[i], grids[i], N, phys, u_init[i],
            PeriodicityTest(vscale[i], rtol, max_steps),
            MarchRecord(nodes, step_m, step_u, step_pi, stiff))
        if status[i] != CONVERGED:
            continue
        nodes_out[i, :] = nodes[:N]
        for k in range(N):
            if stiff[k]:
                h = grids[i, k + 1] - grids[i, k]
                chatter_mass[i] += abs(nodes[k]) * h
                phi, _ = angle_and_rate(code, params[i], grids[i, k] + 0.5 * h,
                                        grids[i, k] + 0.5 * h)
                stiffness[i] = max(stiffness[i], band_stiffness(phi, h, phys))
    return int_u, int_pi, u0, status, periods, evaluations, chatter_mass, stiffness, nodes_out
