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

import numpy as np
from numba import njit, prange

from ._force import force_and_slope, power_density
from ._kinematics import angle_and_rate
from ._periodic import batch_outputs, monodromy_factor, node_weights, one_minus_monodromy
from ._status import CONVERGED, NON_FINITE, STEP_BUDGET_EXCEEDED, UNSTABLE

#: Heun's method (explicit trapezoidal RK2).
HEUN_C = np.array([0.0, 1.0])
HEUN_A = np.array([[0.0, 0.0], [1.0, 0.0]])
HEUN_B = np.array([0.5, 0.5])
ORDER = 2


@njit(cache=True, error_model="numpy")
def heun_step(u, h, phi0, om0, phi1, om1, kappa, mu_n, mu_s, p, dtau):
    """One RK2 step (Butcher tableau HEUN_*): pure function, no state.

    Returns (u_{n+1}, du_{n+1}/du_n).
    """
    F1, dF1 = force_and_slope(u, phi0, om0, mu_n, mu_s, p, dtau)
    F2, dF2 = force_and_slope(u + h * kappa * F1, phi1, om1, mu_n, mu_s, p, dtau)
    m = 1.0 + 0.5 * h * kappa * (dF1 + dF2 * (1.0 + h * kappa * dF1))
    return u + 0.5 * h * kappa * (F1 + F2), m


#: a Heun step jumps across the steep part of F (a sticking band of width ~delta_tau)
#: when its stage forces have opposite signs and (F2 - F1) / F1 is below this (a
#: linear F gives 1 + (F2 - F1) / F1 = 1 + z, z = h T^(2-p) dF/du; chatter sits at -2)
JUMP_LIMIT = -1.5


@njit(cache=True, error_model="numpy")
def step_jumps(u, h, phi0, om0, phi1, om1, kappa, mu_n, mu_s, p, dtau):
    """Whether a Heun step from u jumps across a sticking band instead of resolving it."""
    F1, _ = force_and_slope(u, phi0, om0, mu_n, mu_s, p, dtau)
    F2, _ = force_and_slope(u + h * kappa * F1, phi1, om1, mu_n, mu_s, p, dtau)
    return F1 * F2 < 0.0 and (F2 - F1) / F1 < JUMP_LIMIT


@njit(cache=True, error_model="numpy")
def _march_point(code, params, grid, N, kappa, mu_n, mu_s, p, dtau, u_init, vscale, rtol,
                 max_steps, u_out, step_u, step_pi, step_m, step_stiff, stages, weights,
                 step_weights):
    """March on the first N steps of ``grid``; per-step integrals into ``step_u``, ``step_pi``.

    ``step_stiff[n]`` flags the steps of the last period that chatter through a
    sticking phase (consecutive ``step_jumps``).  ``stages`` (>= 2N), ``weights`` and
    ``step_weights`` (>= N) receive what the turning-point and event checks need:
    pseudo-stages (u_n + (u_{n+1} - u_n) / 3, u_{n+1}), on which the check's quadratic
    through theta = 0, 1/3, 1 is the linear interpolant of the march, and the node and step
    weights of ``_periodic.node_weights`` for the trapezoidal integral of u.
    Returns (int_u, int_Pi, u0, status, periods).
    """
    phis = np.empty(2 * N)
    oms = np.empty(2 * N)
    hs = np.empty(N)
    for n in range(N):
        h = grid[n + 1] - grid[n]
        hs[n] = h
        mid = grid[n] + 0.5 * h
        phis[2 * n], oms[2 * n] = angle_and_rate(code, params, grid[n], mid)
        phis[2 * n + 1], oms[2 * n + 1] = angle_and_rate(code, params, grid[n + 1], mid)
    nodes = np.empty(N + 1)
    ms = np.empty(N)
    # |u(0) - fixed point| <= tol_fix: a shift of u(0) carries about one for one into int u,
    # whose norm can be as small as 1e-3 V (``_solve``), so this is 1 % of rtol there
    tol_fix = max(1e-5 * rtol, 1e-13) * vscale
    bound = 1e3 * vscale + 1.0
    max_periods = max(max_steps // N, 3)
    u = u_init
    prev_change = math.nan
    prev_ratio = math.nan
    status = STEP_BUDGET_EXCEEDED
    period = 0
    for period in range(1, max_periods + 1):
        u_begin = u
        nodes[0] = u
        for n in range(N):
            u, ms[n] = heun_step(u, hs[n], phis[2 * n], oms[2 * n], phis[2 * n + 1],
                                 oms[2 * n + 1], kappa, mu_n, mu_s, p, dtau)
            nodes[n + 1] = u
            if not (abs(u) <= bound):
                return math.nan, math.nan, u_begin, UNSTABLE if math.isfinite(u) else NON_FINITE, period
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
        return math.nan, math.nan, u, status, period
    # the last period marched (from u_begin) is periodic to tolerance: trapezoidal quadrature
    int_u = 0.0
    int_pi = 0.0
    for n in range(N):
        h = hs[n]
        P0 = power_density(nodes[n], phis[2 * n], oms[2 * n], mu_n, mu_s, p, dtau)
        P1 = power_density(nodes[n + 1], phis[2 * n + 1], oms[2 * n + 1], mu_n, mu_s, p, dtau)
        step_u[n] = 0.5 * h * (nodes[n] + nodes[n + 1])
        step_pi[n] = 0.5 * h * (P0 + P1)
        int_u += step_u[n]
        int_pi += step_pi[n]
        u_out[n] = nodes[n]
        step_m[n] = ms[n]
        step_stiff[n] = step_jumps(nodes[n], h, phis[2 * n], oms[2 * n], phis[2 * n + 1],
                                   oms[2 * n + 1], kappa, mu_n, mu_s, p, dtau)
    # one jump is a velocity reversal or a stop inside a step (the error indicators see
    # it); consecutive jumps are chatter through a sticking phase: the explicit method
    # stalls at |u| ~ h T^(2-p) mu instead of ~delta_tau, an O(h) error whose sign does
    # not change with h, so the comparison with the bisection does not reliably see it
    first = step_stiff[0]
    prev = step_stiff[N - 1]
    for n in range(N):
        cur = step_stiff[n]
        nxt = step_stiff[n + 1] if n + 1 < N else first
        step_stiff[n] = cur and (prev or nxt)
        prev = cur
    _check_inputs(nodes, ms, hs, N, stages, weights, step_weights)
    return int_u, int_pi, nodes[0], CONVERGED, period


@njit(cache=True, error_model="numpy")
def _check_inputs(nodes, ms, hs, N, stages, weights, step_weights):
    """Pseudo-stages, node weights and step weights of a marched period (see
    ``_march_point``): the trapezoidal integral h_n (u_n + u_{n+1}) / 2 has
    d/du_n = h_n (1 + m_n) / 2."""
    log_m = 0.0
    sign_m = 1.0
    for n in range(N):
        stages[2 * n] = nodes[n] + (nodes[n + 1] - nodes[n]) / 3.0
        stages[2 * n + 1] = nodes[n + 1]
        weights[n] = 0.5 * hs[n] * (1.0 + ms[n])
        step_weights[n] = weights[n]
        log_m, sign_m = monodromy_factor(log_m, sign_m, ms[n] - 1.0)
    node_weights(weights[:N], ms[:N], one_minus_monodromy(log_m, sign_m))


@njit(cache=True, parallel=True, error_model="numpy")
def march_points(code, params, grids, n_steps, kappa, mu_n, mu_s, p, dtau, u_init, vscale, rtol,
                 max_steps):
    """Batched ``_march_point``; ``grids`` row i valid up to ``n_steps[i]`` steps."""
    n, m = grids.shape
    int_u, int_pi, u0_out, status, periods, _, step_u, step_pi, step_m, nodes = \
        batch_outputs(n, m)
    stiff = np.zeros((n, m - 1), dtype=np.bool_)
    stages = np.full((n, 2 * (m - 1)), np.nan)
    weights = np.full((n, m - 1), np.nan)
    step_weights = np.full((n, m - 1), np.nan)
    for i in prange(n):
        int_u[i], int_pi[i], u0_out[i], status[i], periods[i] = _march_point(
            code, params[i], grids[i], n_steps[i], kappa[i], mu_n[i], mu_s[i], p[i], dtau[i],
            u_init[i], vscale[i], rtol, max_steps, nodes[i], step_u[i], step_pi[i], step_m[i],
            stiff[i], stages[i], weights[i], step_weights[i])
    return (int_u, int_pi, u0_out, status, periods, step_u, step_pi, step_m, nodes, stiff,
            stages, weights, step_weights)
