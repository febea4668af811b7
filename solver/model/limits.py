"""The two limits of section "Model".

T -> 0 (fast motions): u is constant, the constant making the period-averaged
force zero.  T -> infinity (slow motions): inertia drops out of eq. (Newtonu)
and u(tau) solves the algebraic equation F(u, tau) = 0 at each tau; then
u = phi' h(phi) and U -> 0.

Both equations are solved by Newton's method inside a bisection bracket:
F opposes u once |u| exceeds the largest link speed |dphi/dtau|/4, which
brackets the root.
"""
from __future__ import annotations

import math

import numpy as np
from numba import njit, prange

from .force import force_and_slope
from .kinematics import angle_and_rate, evaluate_grid, period_grid
from .._threads import serial_when_single

_GL_X, _GL_W = np.polynomial.legendre.leggauss(4)
GL4_NODES = 0.5 * (_GL_X + 1.0)
GL4_WEIGHTS = 0.5 * _GL_W


@njit(cache=True, error_model="numpy")
def _weighted_force(u, phis, oms, wts, mu_n, mu_s, p, dtau):
    """sum_j w_j F(u, tau_j) and its u-derivative."""
    g = 0.0
    dg = 0.0
    for j in range(phis.shape[0]):
        F, dF = force_and_slope(u, phis[j], oms[j], mu_n, mu_s, p, dtau)
        g += wts[j] * F
        dg += wts[j] * dF
    return g, dg


@njit(cache=True, error_model="numpy")
def _force_root(phis, oms, wts, mu_n, mu_s, p, dtau, bound):
    """Root of the weighted force in [-bound, bound] (g(-bound) > 0 > g(bound)): Newton in bisection."""
    lo = -bound
    hi = bound
    tol = 1e-15 * bound
    u = 0.0
    for _ in range(200):
        g, dg = _weighted_force(u, phis, oms, wts, mu_n, mu_s, p, dtau)
        if g > 0.0:
            lo = u
        else:
            hi = u
        new = u - g / dg if dg != 0.0 else math.nan
        if not (lo < new < hi):
            new = 0.5 * (lo + hi)
        if abs(new - u) <= tol or hi - lo <= tol:
            return new
        u = new
    return u


@njit(cache=True, parallel=True, error_model="numpy")
def _fast_limit(code, params, grids, mu_n, mu_s, p, dtau, nodes, weights):
    n, m = grids.shape
    out = np.empty(n)
    nq = nodes.shape[0]
    for i in prange(n):
        N = m - 1
        phis = np.empty(N * nq)
        oms = np.empty(N * nq)
        wts = np.empty(N * nq)
        for k in range(N):
            h = grids[i, k + 1] - grids[i, k]
            mid = grids[i, k] + 0.5 * h
            for q in range(nq):
                j = k * nq + q
                phis[j], oms[j] = angle_and_rate(code, params[i], grids[i, k] + nodes[q] * h, mid)
                wts[j] = weights[q] * h
        bound = np.max(np.abs(oms)) + 1e-300  # |u| > max|phi'|/4 makes F oppose u everywhere
        out[i] = _force_root(phis, oms, wts, mu_n[i], mu_s[i], p[i], dtau[i], bound)
    return out


@njit(cache=True, parallel=True, error_model="numpy")
def _quasi_static(code, params, tau, mu_n, mu_s, p, dtau):
    n, m = tau.shape
    out = np.empty((n, m))
    one = np.ones(1)
    for i in prange(n):
        for j in range(m):
            phi, om = angle_and_rate(code, params[i], tau[i, j], tau[i, j])
            out[i, j] = _force_root(np.array([phi]), np.array([om]), one, mu_n[i], mu_s[i], p[i],
                                    dtau[i], abs(om) + 1e-300)
    return out


def fast_limit_velocity(kinematics, physics, n_steps=64):
    """T -> 0 limit: the constant u with zero period-averaged force.

    Returns
    -------
    ndarray, shape (n_points,)
        The constant scaled velocity u (U = u / T).
    """
    code, params = kinematics.kernel_encoding()
    grids = period_grid(kinematics, n_steps)
    with serial_when_single(params.shape[0]):
        return _fast_limit(code, params, grids, physics.mu_n, physics.mu_s, physics.p,
                           physics.delta_tau, GL4_NODES, GL4_WEIGHTS)


def quasi_static_velocity(kinematics, physics, tau):
    """T -> infinity limit: u(tau) solving F(u, tau) = 0 at each tau (eq. Newtonu without inertia).

    Uses physics.delta_tau as given: pass a small delta for the paper's delta -> 0 limit.

    Returns
    -------
    ndarray, shape (n_points, n_tau)
    """
    code, params = kinematics.kernel_encoding()
    tau = np.broadcast_to(np.asarray(tau, dtype=float), (params.shape[0], np.size(tau))).copy()
    with serial_when_single(params.shape[0]):
        return _quasi_static(code, params, tau, physics.mu_n, physics.mu_s, physics.p,
                             physics.delta_tau)


def kinematic_speed(kinematics, n_samples=512):
    """V = (1/4) int_0^1 |dphi/dtau| dtau: a deformation speed scale (link lengths per period).

    Computed as a quarter of the total variation of phi on a corner-aligned grid
    (exact for the monotone phases of the harmonic and power-law families).
    """
    grid = period_grid(kinematics, n_samples)
    code, params = kinematics.kernel_encoding()
    # phi is continuous: one value per node (the side of a corner only matters for dphi/dtau)
    side = np.empty_like(grid)
    side[:, :-1] = 0.5 * (grid[:, 1:] + grid[:, :-1])
    side[:, -1] = side[:, -2]
    with serial_when_single(params.shape[0]):
        phi, _ = evaluate_grid(code, params, grid, side)
    return 0.25 * np.abs(np.diff(phi, axis=1)).sum(axis=1)
