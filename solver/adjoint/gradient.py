"""Exact gradients of the discretised periodic problem by the adjoint method.

The discrete problem (one parameter point, a fixed grid tau_0 = 0 < ... < tau_N = 1, by
default the step sequence of the order-5 engine's converged solve, ``adaptive_grid``).
The method is the engine's 3-stage Radau IIA (order 5, ``periodic.radau``: nodes
c = ((4 - sqrt 6)/10, (4 + sqrt 6)/10, 1), matrix A, weights b = last row of A =
((16 - sqrt 6)/36, (16 + sqrt 6)/36, 1/9)).  The unknowns are the stages
x_n = (U1_n, U2_n, U3_n) of every step, U_i at tau_n + c_i h_n; the method is stiffly
accurate, so u_{n+1} = U3_n and periodicity closes the cycle, u_0 = U3_{N-1}.  With
F_j = F(U_j; phi_j, omega_j, delta_tau) (eq. Newtonu; phi, omega on the step's side of a
corner) and kappa = T^(2-p) the residuals are

    R_i,n = U_i,n - U3_{n-1} - h_n kappa sum_j a_ij F_j,n        (i = 1, 2, 3; n - 1 mod N)

and the objectives are built from the Radau-weighted period integrals (the engine's own,
``periodic.radau.step_integrals``)

    I_u = sum_n h_n b . U_n,   I_Pi = sum_n h_n b . Pi(U_n)   [Pi: eq. powerp's integrand],
    U = I_u / T,  P = T^-(p+1) I_Pi,  lambda = sign(U) |U|^(p+1) / P   (eqs. U, powerp, lambdap).

The forward solve is the engine's fixed-grid solve (``periodic.driver.fixed_grid_point``:
frozen sweeps, Newton on u(0), the converged sweep shifted onto the fixed point), with the
nonlinear tolerances at rounding level (rtol 1e-13), so I_u and I_Pi are the engine's
numbers on that grid (tests/test_gradient.py: equal to ``fixed_grid_point``'s).

Adjoint.  For I in {I_u, I_Pi}: dI/dtheta = dI/dtheta|_x - l^T dR/dtheta with
(dR/dx)^T l = (dI/dx)^T.  dR/dx is cyclic block-bidiagonal: the 3 x 3 stage Jacobian
J_n = I - h_n kappa A diag(F_u at the stages) on the diagonal and -1 e_3^T coupling step n
to U3_{n-1}.  Its transpose gives, with sigma_n = 1 . l_n,

    J_n^T l_n = g_n + e_3 sigma_{n+1},     sigma_n = c_n + m_n sigma_{n+1},

where g_n = h_n b (I_u) or h_n b diag(Pi_u) (I_Pi), s_n = J_n^-1 1 = dU_n/du_n,
c_n = s_n . g_n and m_n = (s_n)_3 = du_{n+1}/du_n, the step derivative whose product over
the period is the monodromy M.  So the adjoint is one backward sweep:
sigma_0 = (sum_n (prod_{k<n} m_k) c_n) / (1 - M), with m_n - 1 = (J_n^-1 h_n kappa A F_u)_3
formed without cancellation and 1 - M accumulated as -expm1(sum log m_n) (``periodic.shooting``),
then l_n and sigma_n step by step backward by 3 x 3 transposed solves (``periodic.radau.solve3``,
pivoted: stiff stages make J_n's columns differ by ~1e10; |m_n| <~ 1, so the backward
recursion is stable; it is O(N), both functionals in the same sweep).  With q_n = A^T l_n,

    dI/dtheta = sum_n [ dh_n/dtheta (b . G(U_n) + kappa q_n . F_n) + h_n kappa q_n . dF_n/dtheta
                        + h_n b . dG/dtheta ],   G = u or Pi,

dF/dtheta = F_phi dphi/dtheta + F_omega domega/dtheta (+ F_delta for delta_tau), and the
kappa column sum_n h_n q_n . F_n.

Parameter dependence.  phi and omega at the stages depend on the family's parameters
(Harmonic A0, A1; Fourier A_k, B_k; power law A0, A1, tau0, gamma_c, gamma_o); for the
power law the grid moves with tau0: every node keeps its fraction of its phase (closing
[0, tau0], opening [tau0, 1]), so the stage fractions are fixed, phi there does not depend
on tau0, omega ~ 1/(phase length) does, and so do the step lengths h_n.  T enters through
kappa, delta_tau = T delta and the prefactors of U and P.

Cost of one gradient (bench_optimize's problem, Kmax = 7, mu_n/mu_s = 2^-4, seed 1: the
engine's grid at rtol 1e-6 has 200 steps, the order-3 engine's had 1,592): forward solve
from a warm u(0) 0.19 ms plus adjoint 0.10 ms (order 3: 0.59 + 0.38 ms); the adjoint
evaluates the closed-form partials at the 3 stages of every step and solves three 3 x 3
systems per step (~0.5 us a step against ~0.24 for order 3's two stages and 2 x 2 systems).

A frozen grid is not error-controlled away from where it was made: far from it a step can
carry h kappa F_u > 0 at a stage (the anisotropic friction's destabilising slope) up to a
fold of the stage equations, det J_n -> 0, where the discrete solution branch ends, the
objective jumps and its exact gradient grows like 1 / det J_n (bench_optimize seed 3:
h kappa F_u = 2.7 at a stage, det J_n = 2e-5, the line search failed there).

Partial derivatives of F and Pi.  ``force_partials`` forms them in closed form from
the forward solve's own link moments, the omega partials by homogeneity, falling back
to the quadrature below for those two where homogeneity cancels (near omega = 0); on
inputs concentrated on the hard cases the two agree to 1e-11 of the natural scales
(tests/test_gradient.py), and the closed forms made a gradient ~2.8x cheaper (measured on
the order-3 discretisation, Kmax = 7, 1592 steps: 9.8 -> 3.4 ms).
``force_partials_quadrature``: integrals over the
link of the s-derivatives of the integrands, evaluated by composite 10-point
Gauss-Legendre.  The integrand is analytic in s except at s* +- i eta, where
w(s*) = 0 and eta = e / |omega| (e^2 = c^2 + delta_tau^2).  The panels are graded
geometrically (ratio 1/2) toward the nearest real point s_c of [0, 1/2] down to
a panel no longer than the distance rho = |s* - s_c + i eta|; every panel then
sees the singularity outside the Bernstein ellipse of parameter >= 4.6, so each
panel is exact to ~4.6^-20 ~ 1e-13 of its own size.  Near the kink w is formed
from the offset s - s_c (see ``_panel``): forming it as -u S + omega (s - S^2/4)
lost up to 3 digits of dF/du there.  Measured (2700 inputs concentrated on the
hard cases: kink inside the link, apex at rest, omega from 1e-6 to 10; p in
{0, 0.5, 1.5}; delta_tau in {1e-2, 1e-5, 1e-9}): F and Pi agree with the closed
forms of ``force_and_slope`` / ``power_density`` to <= 7e-15 relative, dF/du to
<= 1e-11.  Against 30-digit mpmath quadrature of the differentiated integrands
(96 of those inputs, p in {0, 0.5, 1, 1.5}), relative to |ref| + int |integrand|:
F_u 6e-12, F_phi 2e-14, F_delta 5e-11, Pi and its partials <= 3e-14, F_omega
<= 1e-13 except at u ~ 0, where F_omega vanishes pointwise (F is homogeneous of
degree 0 in (u, omega) at p = 0) and the error is ~1e-18 absolute against the
natural scale mu / |omega|.  The phi, omega, delta_tau derivatives also match
Richardson-extrapolated central differences of the closed forms to the
differences' own accuracy (tests/test_gradient.py).  At most 2 x 57 panels (56 halvings: the last panel
carries < 2^-56 of the link).
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import NamedTuple

import numpy as np
from numba import njit

from ..model.force import E_FLOOR, link_moments, link_setup_sc, radial_power
from ..model.kinematics import FOURIER, POWER_LAW, Fourier, Harmonic, PowerLaw, period_grid
from ..model.limits import fast_limit_velocity
from ..model.kinematics import angle_and_rate
from ..model.physics import PointPhysics
from .. import periodic
from ..periodic import (RADAU5_A, RADAU5_C, frozen_orbit, monodromy_factor, new_workspace,
                        one_minus_monodromy, set_grid_step, solve3, stage_columns, stage_matrix)
from ..status import CONVERGED

# the engine's tableau as scalars for the compiled kernels (as ``periodic.radau``'s)
C1, C2 = RADAU5_C[0], RADAU5_C[1]
A11, A12, A13 = RADAU5_A[0]
A21, A22, A23 = RADAU5_A[1]
A31, A32, A33 = RADAU5_A[2]

_x10, _w10 = np.polynomial.legendre.leggauss(10)
GL10_NODES = 0.5 * (_x10 + 1.0)
GL10_WEIGHTS = 0.5 * _w10
#: most halvings of a side of the link toward the near-singular point
MAX_GRADING_LEVELS = 56

OBJECTIVES = ("efficiency", "speed", "power")


# ---------------------------------------------------------------------------------------------
# partial derivatives of the force and the power density


class LinkIntegrand(NamedTuple):
    """What the force and power integrands along the link depend on besides s: the state at
    one time and the force law (``force_and_slope``'s arguments, phi as its sine and cosine)."""

    u: float       # body velocity
    S: float       # sin phi
    C: float       # cos phi
    omega: float   # dphi/dtau
    mu_n: float
    mu_s: float
    p: float
    dtau: float    # delta_tau


@njit(cache=True, error_model="numpy")
def _panel(s_c, w_c, lo, hi, link, acc):
    """Add 10-point Gauss-Legendre sums over s in [s_c + lo, s_c + hi] of the integrands of
    ``link`` (a ``LinkIntegrand``) to ``acc``.

    w = w_c + omega (s - s_c) is formed from the offset s - s_c, with w_c = w(s_c)
    (0 at an interior kink): near the kink w is then exact to rounding relative to
    itself, where -u S + omega (s - S^2/4) would carry an absolute error ~1e-16 |u S|
    that the peak of width e in w magnifies by 1/e.

    acc: [G, G_u, G_phi, G_omega, G_delta, H, H_u, H_phi, H_omega, H_delta] with
    G = (mu_n S w - mu_s C c) r^(p-1) (force) and H = (mu_n w^2 + mu_s c^2) r^(p-1) (power).
    """
    u, S, C, omega, mu_n, mu_s, p, dtau = link
    length = hi - lo
    c = C * (u + 0.25 * omega * S)
    c_u = C
    c_phi = -S * u + 0.25 * omega * (C * C - S * S)
    c_om = 0.25 * C * S
    e2 = c * c + dtau * dtau
    if e2 < E_FLOOR * E_FLOOR:
        e2 = E_FLOOR * E_FLOOR
    w_u = -S
    w_phi = -u * C - 0.5 * omega * S * C
    for q in range(10):
        t = lo + length * GL10_NODES[q]
        wt = length * GL10_WEIGHTS[q]
        s = s_c + t
        w = w_c + omega * t
        w_om = s - 0.25 * S * S
        r2 = w * w + e2
        g0 = radial_power(r2, p)
        g1 = (p - 1.0) * g0 / r2  # d(r^(p-1)) / d(r^2 / 2)
        # d(r^2/2) along each variable
        q_u = w * w_u + c * c_u
        q_phi = w * w_phi + c * c_phi
        q_om = w * w_om + c * c_om
        q_del = dtau
        N = mu_n * S * w - mu_s * C * c
        N_u = mu_n * S * w_u - mu_s * C * c_u
        N_phi = mu_n * (C * w + S * w_phi) - mu_s * (-S * c + C * c_phi)
        N_om = mu_n * S * w_om - mu_s * C * c_om
        H = mu_n * w * w + mu_s * c * c
        H_u = 2.0 * (mu_n * w * w_u + mu_s * c * c_u)
        H_phi = 2.0 * (mu_n * w * w_phi + mu_s * c * c_phi)
        H_om = 2.0 * (mu_n * w * w_om + mu_s * c * c_om)
        acc[0] += wt * N * g0
        acc[1] += wt * (N_u * g0 + N * g1 * q_u)
        acc[2] += wt * (N_phi * g0 + N * g1 * q_phi)
        acc[3] += wt * (N_om * g0 + N * g1 * q_om)
        acc[4] += wt * (N * g1 * q_del)
        acc[5] += wt * H * g0
        acc[6] += wt * (H_u * g0 + H * g1 * q_u)
        acc[7] += wt * (H_phi * g0 + H * g1 * q_phi)
        acc[8] += wt * (H_om * g0 + H * g1 * q_om)
        acc[9] += wt * (H * g1 * q_del)


@njit(cache=True, error_model="numpy")
def _graded_side(s_c, w_c, end, rho, link, acc):
    """``_panel``s on [s_c, end] (either order), halving toward s_c down to length <= rho."""
    L = abs(end - s_c)
    if L == 0.0:
        return
    direction = 1.0 if end > s_c else -1.0
    levels = 0
    if rho < L:
        levels = min(int(math.ceil(math.log2(L / rho))), MAX_GRADING_LEVELS)
    outer = L
    for _ in range(levels):
        inner = 0.5 * outer
        a = direction * inner
        b = direction * outer
        _panel(s_c, w_c, min(a, b), max(a, b), link, acc)
        outer = inner
    b = direction * outer
    _panel(s_c, w_c, min(0.0, b), max(0.0, b), link, acc)


@njit(cache=True, error_model="numpy")
def force_partials(u, phi, omega, mu_n, mu_s, p, delta_tau):
    """F, Pi and their partial derivatives in u, phi, omega and delta_tau.

    Parameters as ``force_and_slope``; returns as ``force_partials_quadrature``
    (``force_partials_into`` without the allocation, from sin and cos of phi).

    Closed forms from the link moments of ``model.force`` (the forward solve's own): for
    theta in (u, phi, delta_tau) the normal velocity's derivative w_theta is constant
    along the link (w_u = -S, w_phi = -u C - omega S C / 2, w_delta = 0), so with
    q_theta = c c_theta + delta_tau delta_theta

        d m_k^0 / d theta = k w_theta m_(k-1)^0 + (p - 1) (w_theta m_(k+1)^1 + q_theta m_k^1),
        m_3^1 = m_1^0 - e^2 m_1^1,

    and F, Pi (``model.force``) differentiate term by term.  omega enters w as omega s and
    has no such form; it follows from homogeneity: scaling (u, omega, delta_tau) by
    lambda scales F by lambda^p and Pi by lambda^(p+1), so

        omega F_omega = p F - u F_u - delta_tau F_delta,   same for Pi with p + 1.

    Where that difference cancels (|omega F_omega| below 1e-4 of its terms, e.g. near a
    turning point, omega ~ 0) the graded quadrature ``force_partials_quadrature`` is
    used for the two omega partials, so their relative error stays ~1e-11; the other
    columns are always the closed forms (F_u equals ``force_and_slope``'s slope to rounding:
    the adjoint's Jacobian is the derivative of what the forward residual evaluates).
    """
    out = np.empty(10)
    force_partials_into(LinkIntegrand(u, math.sin(phi), math.cos(phi), omega, mu_n, mu_s, p,
                                      delta_tau), phi, out)
    return out


@njit(cache=True, error_model="numpy")
def force_partials_into(link, phi, out):
    """``force_partials`` at ``link`` (a ``LinkIntegrand``: sin and cos of phi given) written
    into ``out`` (10,): the adjoint calls it at every stage, and the allocation and the sine
    and cosine were ~1/3 of its cost."""
    u, S, C, omega, mu_n, mu_s, p, delta_tau = link
    S, C, a, b, c, e2 = link_setup_sc(u, S, C, omega, delta_tau, p)
    m00, m10, m20, m01, m11, m21 = link_moments(a, b, e2, p)
    m31 = m10 - e2 * m11
    q = p - 1.0
    out[0] = 2.0 * (mu_n * S * m10 - mu_s * C * c * m00)
    out[5] = 2.0 * (mu_n * m20 + mu_s * c * c * m00)
    c_phi = -S * u + 0.25 * omega * (C * C - S * S)
    # (column of out, w_theta, c_theta, q_theta, dS/dtheta, d(C c)/dtheta)
    for col, w_t, c_t, q_t, S_t, Cc_t in (
            (1, -S, C, c * C, 0.0, C * C),
            (2, -u * C - 0.5 * omega * S * C, c_phi, c * c_phi, C, -S * c + C * c_phi),
            (4, 0.0, 0.0, delta_tau, 0.0, 0.0)):
        d00 = q * (w_t * m11 + q_t * m01)
        d10 = w_t * m00 + q * (w_t * m21 + q_t * m11)
        d20 = 2.0 * w_t * m10 + q * (w_t * m31 + q_t * m21)
        out[col] = 2.0 * (mu_n * (S_t * m10 + S * d10) - mu_s * (Cc_t * m00 + C * c * d00))
        out[col + 5] = 2.0 * (mu_n * d20 + mu_s * (2.0 * c * c_t * m00 + c * c * d00))
    fallback = False
    for k, degree in ((0, p), (5, p + 1.0)):
        terms = degree * out[k] - u * out[k + 1] - delta_tau * out[k + 4]
        size = abs(degree * out[k]) + abs(u * out[k + 1]) + abs(delta_tau * out[k + 4])
        if omega == 0.0 or not abs(terms) > 1e-4 * size:
            fallback = True
        else:
            out[k + 3] = terms / omega
    if fallback:
        quadrature = force_partials_quadrature(u, phi, omega, mu_n, mu_s, p, delta_tau)
        out[3] = quadrature[3]
        out[8] = quadrature[8]


@njit(cache=True, error_model="numpy")
def force_partials_quadrature(u, phi, omega, mu_n, mu_s, p, delta_tau):
    """F, Pi and their partial derivatives in u, phi, omega and delta_tau, by quadrature.

    Parameters as ``force_and_slope``.  Accuracy ~1e-12 relative (module docstring).

    Returns
    -------
    ndarray, shape (10,)
        [F, F_u, F_phi, F_omega, F_delta_tau, Pi, Pi_u, Pi_phi, Pi_omega, Pi_delta_tau];
        F = 2 int_0^{1/2} f_x ds (eq. Newtonu), Pi the integrand of eq. (powerp).
    """
    S = math.sin(phi)
    C = math.cos(phi)
    link = LinkIntegrand(u, S, C, omega, mu_n, mu_s, p, delta_tau)
    acc = np.zeros(10)
    c = C * (u + 0.25 * omega * S)
    e = max(math.sqrt(c * c + delta_tau * delta_tau), E_FLOOR)  # as in _panel: rho > 0
    a = -u * S - 0.25 * omega * S * S
    if omega == 0.0 or p == 1.0:
        # polynomial or constant in s: one panel is exact
        _panel(0.0, a, 0.0, 0.5, link, acc)
    else:
        s_star = -a / omega
        eta = e / abs(omega)
        s_c = min(max(s_star, 0.0), 0.5)
        rho = math.hypot(s_star - s_c, eta)
        if s_c == s_star:
            w_c = 0.0
        elif s_c == 0.0:
            w_c = a
        else:
            w_c = a + 0.5 * omega
        _graded_side(s_c, w_c, 0.5, rho, link, acc)
        _graded_side(s_c, w_c, 0.0, rho, link, acc)
    for k in range(10):
        acc[k] *= 2.0
    return acc


# ---------------------------------------------------------------------------------------------
# parameter derivatives of the kinematics at the stages


@njit(cache=True, error_model="numpy")
def n_family_parameters(code, params):
    """Number of free parameters of the encoding.

    Fourier: [A0..AK, B1..BK]; power law: [A0, A1, tau0, gamma_c, gamma_o].
    """
    if code == FOURIER:
        return 2 * int(params[0]) + 1
    return 5


@njit(cache=True, error_model="numpy")
def _z_power_log(z, g):
    """(z^g ln z, z^(g-1) ln z) with the z -> 0 limits 0 (exact for g > 1)."""
    if z <= 0.0:
        return 0.0, 0.0
    lz = math.log(z)
    return z ** g * lz, z ** (g - 1.0) * lz


@njit(cache=True, error_model="numpy")
def angle_partials(code, params, t, tau_phase, dphi, domega):
    """d phi / d theta and d omega / d theta at time ``t`` of a step around ``tau_phase``.

    For the power law the time moves with tau0 (fixed fraction of its phase), so these
    are total derivatives along the moving grid.  Writes ``dphi``, ``domega`` (n_par,).
    """
    if code == FOURIER:
        K = int(params[0])
        dphi[0] = 1.0
        domega[0] = 0.0
        c1 = math.cos(2.0 * math.pi * t)
        s1 = math.sin(2.0 * math.pi * t)
        ca, sa = 1.0, 0.0
        for k in range(1, K + 1):  # cos, sin of 2 pi k t by angle addition (error ~k eps)
            wk = 2.0 * math.pi * k
            ca, sa = ca * c1 - sa * s1, sa * c1 + ca * s1
            dphi[k] = ca
            domega[k] = -wk * sa
            dphi[K + k] = sa
            domega[K + k] = wk * ca
        return
    A1, tau0, gc, cup, go, oup = params[1], params[2], params[3], params[4], params[5], params[6]
    for k in range(5):
        dphi[k] = 0.0
        domega[k] = 0.0
    dphi[0] = 1.0
    tt = t - math.floor(tau_phase)
    tp = tau_phase - math.floor(tau_phase)
    if tp <= tau0:  # closing: phi falls, phase length tau0
        x = min(max(tt / tau0, 0.0), 1.0)
        length, dlength, sign, g, gi, x_case = tau0, 1.0, -1.0, gc, 3, cup < 0.5
    else:
        x = min(max((tt - tau0) / (1.0 - tau0), 0.0), 1.0)
        length, dlength, sign, g, gi, x_case = 1.0 - tau0, -1.0, 1.0, go, 4, oup > 0.5
    # phi = A0 - s_phi A1 + 2 s_phi A1 z^g,  omega = sign 2 A1 g z^(g-1) / length
    if x_case:
        z = x
        s_phi = sign
    else:
        z = 1.0 - x
        s_phi = -sign
    zg = z ** g
    zg1 = z ** (g - 1.0)
    zgl, zg1l = _z_power_log(z, g)
    omega = sign * 2.0 * A1 * g * zg1 / length
    dphi[1] = s_phi * (2.0 * zg - 1.0)
    dphi[gi] = 2.0 * s_phi * A1 * zgl
    domega[1] = sign * 2.0 * g * zg1 / length
    domega[2] = -omega * dlength / length
    domega[gi] = sign * 2.0 * A1 * (zg1 + g * zg1l) / length


@njit(cache=True, error_model="numpy")
def step_length_partials(code, params, h, tau_phase, dh):
    """d h / d theta for a step of length h around ``tau_phase`` (nonzero only for tau0)."""
    for k in range(dh.shape[0]):
        dh[k] = 0.0
    if code == POWER_LAW:
        tau0 = params[2]
        tp = tau_phase - math.floor(tau_phase)
        dh[2] = h / tau0 if tp <= tau0 else -h / (1.0 - tau0)


# ---------------------------------------------------------------------------------------------
# forward solve with the stages kept, and the adjoint sweep


@njit(cache=True, error_model="numpy")
def _forward(code, params, nodes, N, phys, u0, rtol, W, stage_kinematics, options):
    """Periodic solution of the 3-stage Radau IIA discretisation on ``nodes`` (N steps).

    The engine's own fixed-grid solve (``periodic.frozen_orbit``: a frozen pass, Newton on
    u(0) by frozen passes, the converged pass shifted onto the fixed point), on the
    workspace ``W`` (``periodic.new_workspace(N)``), which holds the converged stages
    afterwards (``periodic.stage_columns``).  Writes phi, dphi/dtau, sin phi, cos phi at the
    stage times tau_n + c_i h_n (each on its step's side of a corner) into
    ``stage_kinematics`` (4, 3N).  The first sweep starts every stage at its step's start
    value (``fixed_grid_point`` starts it at u0; the two agree to the stage tolerance).

    Returns (status, u0, I_u, I_Pi); the speed scale V = (1/4) int |dphi/dtau| dtau (Radau
    rule) sets the nonlinear tolerances as in the engine (``periodic.tolerances``, by the
    factors of ``options``, an ``EngineOptions``: ``discrete_solution`` passes the defaults).
    """
    vscale = 0.0
    for n in range(N):
        t0 = nodes[n]
        h = nodes[n + 1] - t0
        side = t0 + 0.5 * h
        for i in range(3):
            c = C1 if i == 0 else (C2 if i == 1 else 1.0)
            phi, om = angle_and_rate(code, params, t0 + c * h, side)
            S = math.sin(phi)
            C = math.cos(phi)
            stage_kinematics[0, 3 * n + i] = phi
            stage_kinematics[1, 3 * n + i] = om
            stage_kinematics[2, 3 * n + i] = S
            stage_kinematics[3, 3 * n + i] = C
            b = A31 if i == 0 else (A32 if i == 1 else A33)
            vscale += 0.25 * h * b * abs(om)
        # the first pass's stage prediction, stage + sensitivity (u_n - u0), is u_n
        set_grid_step(W, n, t0, nodes[n + 1], stage_kinematics[2, 3 * n:3 * n + 3],
                      stage_kinematics[3, 3 * n:3 * n + 3], stage_kinematics[1, 3 * n:3 * n + 3],
                      u0, u0, 1.0)
    return frozen_orbit(code, params, phys, u0, rtol, max(vscale, 1e-300), W, N, options)


@njit(cache=True, error_model="numpy")
def _adjoint(code, params, nodes, N, phys, stages, stage_kinematics, grad):
    """Gradients of the period integrals from the converged stages (3N,) and phi, dphi/dtau,
    sin phi, cos phi there (4, 3N) (``_forward``'s), for ``phys`` (``PointPhysics``); see the
    module docstring.

    ``grad`` has shape (2, n_par + 2): rows I_u and I_Pi; columns the family
    parameters, then kappa, then delta_tau (each held independent of the others).
    Returns 1 - M; the period integrals come from the forward solve (``_forward``).
    """
    kappa, mu_n, mu_s, p, dtau = phys
    n_par = grad.shape[1] - 2
    jac = np.empty((N, 9))       # J_n = I - h kappa A diag(F_u), row-major
    sens = np.empty((N, 3))      # s_n = J_n^-1 1 = dU_i/du_n
    part = np.empty((N, 3, 10))  # force_partials at the three stages
    log_m = 0.0
    sign_m = 1.0
    phis, oms, sins, coss = (stage_kinematics[0], stage_kinematics[1], stage_kinematics[2],
                             stage_kinematics[3])
    for n in range(N):
        hk = (nodes[n + 1] - nodes[n]) * kappa
        for j in range(3):
            i = 3 * n + j
            force_partials_into(LinkIntegrand(stages[i], sins[i], coss[i], oms[i], mu_n, mu_s,
                                              p, dtau), phis[i], part[n, j])
        # F_u of force_partials is the closed-form slope of the forward residual
        z1 = hk * part[n, 0, 1]
        z2 = hk * part[n, 1, 1]
        z3 = hk * part[n, 2, 1]
        J = stage_matrix(hk, part[n, 0, 1], part[n, 1, 1], part[n, 2, 1])
        for k in range(9):
            jac[n, k] = J[k]
        # s - 1 = J^-1 (h kappa A diag(F_u) 1): m_n - 1 without cancellation
        e1, e2, e3 = solve3(J, A11 * z1 + A12 * z2 + A13 * z3, A21 * z1 + A22 * z2 + A23 * z3,
                            A31 * z1 + A32 * z2 + A33 * z3)
        sens[n, 0] = 1.0 + e1
        sens[n, 1] = 1.0 + e2
        sens[n, 2] = 1.0 + e3
        log_m, sign_m = monodromy_factor(log_m, sign_m, e3)
    one_minus_M = one_minus_monodromy(log_m, sign_m)

    # sigma_0 = S_0 / (1 - M), S_n = c_n + m_n S_{n+1}, S_N = 0, for both functionals: the
    # right-hand side g_n of step n is h b for I_u and h b diag(Pi_u) for I_Pi
    sigma_u = 0.0
    sigma_p = 0.0
    for n in range(N - 1, -1, -1):
        h = nodes[n + 1] - nodes[n]
        s1, s2, s3 = sens[n, 0], sens[n, 1], sens[n, 2]
        sigma_u = h * (A31 * s1 + A32 * s2 + A33 * s3) + s3 * sigma_u
        sigma_p = h * (A31 * s1 * part[n, 0, 6] + A32 * s2 * part[n, 1, 6]
                       + A33 * s3 * part[n, 2, 6]) + s3 * sigma_p
    sigma_u /= one_minus_M
    sigma_p /= one_minus_M

    for k in range(grad.shape[1]):
        grad[0, k] = 0.0
        grad[1, k] = 0.0
    dphi = np.empty((3, n_par))
    dom = np.empty((3, n_par))
    dh = np.empty(n_par)
    coef = np.empty((2, 3, 2))  # (functional, stage, d/dphi or d/domega)
    h_fixed = np.empty(2)  # dI/dh at fixed stages, per functional
    moving = code == POWER_LAW  # only the power law's steps move with a parameter (tau0)
    for n in range(N - 1, -1, -1):
        t0 = nodes[n]
        h = nodes[n + 1] - t0
        hk = h * kappa
        mid = t0 + 0.5 * h
        angle_partials(code, params, t0 + C1 * h, mid, dphi[0], dom[0])
        angle_partials(code, params, t0 + C2 * h, mid, dphi[1], dom[1])
        angle_partials(code, params, t0 + h, mid, dphi[2], dom[2])
        J = jac[n]
        JT = (J[0], J[3], J[6], J[1], J[4], J[7], J[2], J[5], J[8])
        P1 = part[n, 0]
        P2 = part[n, 1]
        P3 = part[n, 2]
        # l_n from J_n^T l_n = g_n + e_3 sigma_{n+1}; q = A^T l; then
        # dI/dtheta = dI/dtheta|_x + d(h kappa)/dtheta (q.F) + h kappa sum_j q_j dF_j/dtheta,
        # collected as coefficients of dphi_j, domega_j and dh for the parameter loop
        for f in range(2):
            if f == 0:
                r1, r2, r3 = h * A31, h * A32, h * A33 + sigma_u
            else:
                r1, r2, r3 = h * A31 * P1[6], h * A32 * P2[6], h * A33 * P3[6] + sigma_p
            l1, l2, l3 = solve3(JT, r1, r2, r3)
            if f == 0:
                sigma_u = l1 + l2 + l3
            else:
                sigma_p = l1 + l2 + l3
            q1 = A11 * l1 + A21 * l2 + A31 * l3
            q2 = A12 * l1 + A22 * l2 + A32 * l3
            q3 = A13 * l1 + A23 * l2 + A33 * l3
            qF = q1 * P1[0] + q2 * P2[0] + q3 * P3[0]
            grad[f, n_par] += h * qF
            grad[f, n_par + 1] += hk * (q1 * P1[4] + q2 * P2[4] + q3 * P3[4])
            coef[f, 0, 0], coef[f, 0, 1] = hk * q1 * P1[2], hk * q1 * P1[3]
            coef[f, 1, 0], coef[f, 1, 1] = hk * q2 * P2[2], hk * q2 * P2[3]
            coef[f, 2, 0], coef[f, 2, 1] = hk * q3 * P3[2], hk * q3 * P3[3]
            if f == 0:
                h_fixed[0] = (A31 * stages[3 * n] + A32 * stages[3 * n + 1]
                              + A33 * stages[3 * n + 2] + kappa * qF)
            else:
                # I_Pi depends on the parameters at fixed stages through Pi itself
                h_fixed[1] = A31 * P1[5] + A32 * P2[5] + A33 * P3[5] + kappa * qF
                grad[1, n_par + 1] += h * (A31 * P1[9] + A32 * P2[9] + A33 * P3[9])
                coef[1, 0, 0] += h * A31 * P1[7]
                coef[1, 0, 1] += h * A31 * P1[8]
                coef[1, 1, 0] += h * A32 * P2[7]
                coef[1, 1, 1] += h * A32 * P2[8]
                coef[1, 2, 0] += h * A33 * P3[7]
                coef[1, 2, 1] += h * A33 * P3[8]
        for f in range(2):
            for k in range(n_par):
                acc = 0.0
                for j in range(3):
                    acc += coef[f, j, 0] * dphi[j, k] + coef[f, j, 1] * dom[j, k]
                grad[f, k] += acc
        if moving:
            step_length_partials(code, params, h, mid, dh)
            for k in range(n_par):
                grad[0, k] += h_fixed[0] * dh[k]
                grad[1, k] += h_fixed[1] * dh[k]
    return one_minus_M


# ---------------------------------------------------------------------------------------------
# Python layer: parameter maps, the fixed grid, the objective and its gradient


def family_parameters(kinematics):
    """(names, values) of the continuous parameters of a one-point family, in gradient order."""
    if isinstance(kinematics, Harmonic):
        return ["A0", "A1"], np.array([kinematics.A0[0], kinematics.A1[0]])
    if isinstance(kinematics, Fourier):
        K = kinematics.max_wavenumber
        names = [f"A{k}" for k in range(K + 1)] + [f"B{k}" for k in range(1, K + 1)]
        return names, np.concatenate([kinematics.A[0], kinematics.B[0]])
    if isinstance(kinematics, PowerLaw):
        names = ["A0", "A1", "duty_cycle", "closing_exponent", "opening_exponent"]
        return names, np.array([kinematics.A0[0], kinematics.A1[0], kinematics.duty_cycle[0],
                                kinematics.closing_exponent[0], kinematics.opening_exponent[0]])
    raise TypeError(f"kinematics: unsupported family {type(kinematics).__name__}")


def with_family_parameters(template, values):
    """A one-point family like ``template`` with its continuous parameters set to ``values``."""
    values = np.asarray(values, dtype=float)
    if isinstance(template, Harmonic):
        return Harmonic(values[0], values[1])
    if isinstance(template, Fourier):
        K = template.max_wavenumber
        return Fourier(values[None, :K + 1], values[None, K + 1:])
    if isinstance(template, PowerLaw):
        return PowerLaw(values[0], values[1], values[2], values[3], template.closing_concave_up,
                        values[4], template.opening_concave_up)
    raise TypeError(f"template: unsupported family {type(template).__name__}")


@dataclass(frozen=True)
class FixedGrid:
    """A grid that is part of the discretisation, fixed while parameters change.

    For the power law the nodes are stored as fractions of their phase (closing
    [0, tau0], opening [tau0, 1]) and move with tau0; otherwise as times.

    Attributes
    ----------
    closing, opening : ndarray
        Power law: node fractions 0 = xi_0 < ... < xi_m = 1 of each phase.
        Other families: ``closing`` holds the nodes 0 = tau_0 < ... < tau_N = 1 and
        ``opening`` is empty.
    two_phase : bool
    """

    closing: np.ndarray
    opening: np.ndarray
    two_phase: bool

    @classmethod
    def from_nodes(cls, kinematics, nodes):
        """From the nodes of ``kinematics`` (one point), e.g. a converged solve's final grid."""
        nodes = np.asarray(nodes, dtype=float)
        if nodes[-1] != 1.0:
            nodes = np.append(nodes, 1.0)
        if nodes[0] != 0.0 or np.any(np.diff(nodes) <= 0):
            raise ValueError("nodes: must increase from 0 to 1")
        if isinstance(kinematics, PowerLaw):
            tau0 = kinematics.duty_cycle[0]
            j = int(np.argmin(np.abs(nodes - tau0)))
            if abs(nodes[j] - tau0) > 1e-14:
                raise ValueError("nodes: the power law's grid must have a node at tau0")
            closing = nodes[:j + 1] / tau0
            opening = (nodes[j:] - tau0) / (1.0 - tau0)
            closing[-1] = opening[-1] = 1.0
            opening[0] = 0.0
            return cls(closing, opening, True)
        return cls(nodes, np.zeros(0), False)

    @classmethod
    def uniform(cls, kinematics, n_steps):
        """``period_grid`` of ``n_steps`` steps (a multiple of 8)."""
        return cls.from_nodes(kinematics, period_grid(kinematics, n_steps)[0])

    def nodes(self, kinematics):
        """Node times tau_0 = 0 < ... < tau_N = 1 for ``kinematics`` (one point)."""
        if not self.two_phase:
            return self.closing.copy()
        tau0 = kinematics.duty_cycle[0]
        return np.concatenate([self.closing * tau0, tau0 + self.opening[1:] * (1.0 - tau0)])

    @property
    def n_steps(self):
        return self.closing.size - 1 + max(self.opening.size - 1, 0)


#: the finest grid ``adaptive_grid`` allows by default (steps per period)
MAX_STEPS_PER_PERIOD = 2 ** 17


def adaptive_grid(kinematics, physics, *, rtol=1e-6, max_steps_per_period=None):
    """The step sequence of the order-5 engine's converged solve at ``rtol`` (one point) as a
    ``FixedGrid``: its adaptive steps, with the corners of phi, the other kinematic stops and
    the state events as step ends (``periodic.solve(..., return_series=True)``)."""
    max_steps = MAX_STEPS_PER_PERIOD if max_steps_per_period is None else int(max_steps_per_period)
    out = periodic.solve(kinematics, physics, rtol, max_steps, True)
    status = int(out["status"][0])
    if status != CONVERGED:
        raise RuntimeError(f"adaptive solve did not converge (status {status})")
    return FixedGrid.from_nodes(kinematics, np.append(out["series"][0][1], 1.0))


@dataclass(frozen=True)
class GradientResult:
    """Objective values and exact gradients of the discretised problem (one point).

    names : parameter names, the family's then "period"
    U, P, efficiency : mean speed, mean power, lambda (eqs. U, powerp, lambdap)
    grad_U, grad_P, grad_efficiency : ndarray, shape (n_params,)  (same order as names)
    value, gradient : the selected objective and its gradient
    status : 0 converged; u0 : u(0) (warm start for the next solve); one_minus_monodromy : 1 - M
    """

    names: list
    U: float
    P: float
    efficiency: float
    grad_U: np.ndarray
    grad_P: np.ndarray
    grad_efficiency: np.ndarray
    value: float
    gradient: np.ndarray
    status: int
    u0: float
    one_minus_monodromy: float


def _prepare(kinematics, physics, grid):
    if len(kinematics) != 1 or len(physics) != 1:
        raise ValueError("one parameter point at a time (len(kinematics) == len(physics) == 1)")
    code, params = kinematics.kernel_encoding()
    nodes = grid.nodes(kinematics)
    return code, params[0].copy(), nodes


def _select(objective, U, P, lam, gU, gP, gL):
    if objective == "efficiency":
        return lam, gL
    if objective == "speed":
        return U, gU
    if objective == "power":
        return P, gP
    raise ValueError(f"objective: expected one of {OBJECTIVES}, got {objective!r}")


@dataclass(frozen=True)
class DiscreteSolution:
    """The converged periodic solution on a fixed grid (one point): all the adjoint needs.

    ``discrete_solution`` makes it; ``objective_gradient(..., solution=...)`` then costs only
    the adjoint sweep, so a line search can solve at trial points and differentiate only
    the one it accepts.

    stages : ndarray, shape (3 N,)
        Radau IIA stages (U1_0, U2_0, U3_0, U1_1, ...) of the converged sweep [link lengths
        per period]; U3_n = u_{n+1}.
    stage_kinematics : ndarray, shape (4, 3 N)
        phi [rad], dphi/dtau [rad per period], sin phi and cos phi at the stage times
        tau_n + c_i h_n.
    int_u, int_pi : float
        The Radau-weighted period integrals I_u, I_Pi.
    status : int
        0 converged (else the ``status`` code; the other fields are then nan).
    u0 : float
        u(0), the warm start of the next solve.
    """

    kinematics: object
    physics: object
    nodes: np.ndarray
    stages: np.ndarray
    stage_kinematics: np.ndarray
    int_u: float
    int_pi: float
    status: int
    u0: float

    def outputs(self):
        """(U, P, lambda) (eqs. U, powerp, lambdap), nan unless converged."""
        if self.status != CONVERGED:
            return math.nan, math.nan, math.nan
        return _physics_outputs(self.int_u, self.int_pi, self.physics)


def discrete_solution(kinematics, physics, grid, *, rtol=1e-13, u0=None):
    """Solve the discretised problem on ``grid`` (one point) by shooting; see ``DiscreteSolution``.

    ``rtol`` sets the nonlinear tolerances (shooting, stage Newton), not the grid;
    ``u0`` the starting u(0) (default: the fast-motion limit).
    """
    code, params, nodes = _prepare(kinematics, physics, grid)
    N = nodes.size - 1
    if u0 is None:
        u0 = float(fast_limit_velocity(kinematics, physics)[0])
    phys = PointPhysics(float(physics.inertia_factor[0]), float(physics.mu_n[0]),
                        float(physics.mu_s[0]), float(physics.p[0]), float(physics.delta_tau[0]))
    W = new_workspace(N)
    stage_kinematics = np.empty((4, 3 * N))
    status, u0, int_u, int_pi = _forward(code, params, nodes, N, phys, float(u0), float(rtol), W,
                                         stage_kinematics, periodic.checked_options(None))
    stages = np.ascontiguousarray(stage_columns(W, N).T).reshape(-1)
    return DiscreteSolution(kinematics, physics, nodes, stages, stage_kinematics, int_u, int_pi,
                            int(status), u0)


def discrete_objective(kinematics, physics, grid, *, objective="efficiency", rtol=1e-13, u0=None):
    """The objective of the discretised problem without its gradient.

    Returns (value, U, P, efficiency, status, u0).
    """
    sol = discrete_solution(kinematics, physics, grid, rtol=rtol, u0=u0)
    U, P, lam = sol.outputs()
    value = {"efficiency": lam, "speed": U, "power": P}[objective]
    return value, U, P, lam, sol.status, sol.u0


def _physics_outputs(int_u, int_pi, physics):
    T = float(physics.period[0])
    p = float(physics.p[0])
    U = int_u / T
    P = int_pi * T ** -(p + 1.0)
    lam = math.copysign(abs(U) ** (p + 1.0), U) / P
    return U, P, lam


def objective_gradient(kinematics, physics, grid, *, objective="efficiency", rtol=1e-13, u0=None,
                       solution=None):
    """Objective of the discretised problem on ``grid`` and its exact gradient (adjoint method).

    Parameters
    ----------
    kinematics : Harmonic | Fourier | PowerLaw
        One parameter point.
    physics : Physics
        One point; the gradient includes d/dT (last entry) at fixed mu_n, mu_s, p, delta.
    grid : FixedGrid
        The discretisation (moves with tau0 for the power law).
    objective : {"efficiency", "speed", "power"}
        lambda (eq. lambdap), U or P.
    rtol : float
        Tolerance of the nonlinear iterations (shooting, stage Newton), not of the grid.
    u0 : float, optional
        Starting u(0) for the shooting (default: the fast-motion limit).
    solution : DiscreteSolution, optional
        ``discrete_solution`` of this kinematics, physics and grid: only the adjoint is run.

    Returns
    -------
    GradientResult
    """
    names, _ = family_parameters(kinematics)
    if solution is None:
        solution = discrete_solution(kinematics, physics, grid, rtol=rtol, u0=u0)
    code, params = kinematics.kernel_encoding()
    params = params[0].copy()
    nodes, stages = solution.nodes, solution.stages
    N = nodes.size - 1
    T = float(physics.period[0])
    p = float(physics.p[0])
    delta = float(physics.delta[0])
    kappa = float(physics.inertia_factor[0])
    dtau = float(physics.delta_tau[0])
    n_out = len(names) + 1
    if solution.status != CONVERGED:
        nan = np.full(n_out, np.nan)
        return GradientResult(names + ["period"], math.nan, math.nan, math.nan, nan, nan, nan,
                              math.nan, nan, solution.status, solution.u0, math.nan)
    n_par = n_family_parameters(code, params)
    grad = np.empty((2, n_par + 2))
    stage_kinematics = solution.stage_kinematics
    if stage_kinematics.shape[0] < 4:  # a solution stored with phi and dphi/dtau only
        phi = stage_kinematics[0]
        stage_kinematics = np.vstack([stage_kinematics[:2], np.sin(phi), np.cos(phi)])
    phys = PointPhysics(kappa, float(physics.mu_n[0]), float(physics.mu_s[0]), p, dtau)
    one_minus_M = _adjoint(code, params, nodes, N, phys, stages, stage_kinematics, grad)
    n_fam = len(names)  # the harmonic encoding carries B1 = 0: drop its column
    d_int = np.empty((2, n_out))
    d_int[:, :n_fam] = grad[:, :n_fam]
    # T enters through kappa = T^(2-p) and delta_tau = T delta
    d_int[:, n_fam] = grad[:, n_par] * (2.0 - p) * kappa / T + grad[:, n_par + 1] * delta
    U, P, lam = solution.outputs()
    gU = d_int[0] / T
    gU[n_fam] -= U / T
    gP = d_int[1] * T ** -(p + 1.0)
    gP[n_fam] -= (p + 1.0) * P / T
    # lambda = sign(U) |U|^(p+1) / P
    gL = lam * ((p + 1.0) * gU / U - gP / P)
    value, gradient = _select(objective, U, P, lam, gU, gP, gL)
    return GradientResult(names + ["period"], U, P, lam, gU, gP, gL, value, gradient,
                          solution.status, solution.u0, one_minus_M)


def with_period(physics, period):
    """``physics`` (one point) with the period T replaced (``Physics.with_period``)."""
    return physics.with_period(period)


# ---------------------------------------------------------------------------------------------
# U at fixed P: the period eliminated by the constraint


#: relative accuracy of P(theta, T) = power in the period root (rounding level of P)
POWER_ROOT_RTOL = 1e-14
#: most Newton steps in log T; each is one forward solve and one adjoint sweep
POWER_ROOT_MAX_ITERATIONS = 40
#: status of ``speed_at_power`` when P cannot be brought to the target (P not monotonic in T)
POWER_ROOT_FAILED = 100


@dataclass(frozen=True)
class ConstrainedGradient:
    """|U| at fixed power: U on the constraint P(theta, T) = power, with T = T(theta).

    names : the family's parameter names (the period is not a variable: the constraint fixes it)
    period : T(theta) solving P(theta, T) = power
    value : U there; gradient : dU/dtheta along the constraint, shape (n_family,)
    at : GradientResult at (theta, period) (U, P, lambda and their unconstrained gradients)
    status : 0, a solver status, or POWER_ROOT_FAILED; root_iterations : Newton steps in log T
    u0 : u(0) at the solution (warm start)
    """

    names: list
    period: float
    value: float
    gradient: np.ndarray
    at: GradientResult
    status: int
    root_iterations: int
    u0: float


def _failed_constraint(names, period, at, status, iterations):
    nan = np.full(len(names), np.nan)
    u0 = at.u0 if at is not None else math.nan
    return ConstrainedGradient(names, period, math.nan, nan, at, status, iterations, u0)


def speed_at_power(kinematics, physics, grid, power, *, rtol=1e-13, u0=None,
                   max_root_iterations=POWER_ROOT_MAX_ITERATIONS):
    """U at fixed mean power P = ``power`` and its exact gradient along the constraint.

    The well-posed form of "maximise |U| at fixed P" used here.  U and P both depend
    on the period: P ~ T^-(p+1) I_Pi (eq. powerp), and I_Pi itself changes with T
    through kappa = T^(2-p) (eq. Newtonu), so P is not a simple rescaling and the
    constraint is handled exactly rather than by normalisation: for the shape
    parameters theta the period T(theta) is the root of log P(theta, T) = log power,
    found by safeguarded Newton steps in log T with the adjoint dP/dT (steps capped at a
    factor e in T).  On that curve (implicit function theorem, P_T != 0)

        dU/dtheta |_P = U_theta - U_T P_theta / P_T,

    exact for the discretised problem once the root is at rounding level
    (``POWER_ROOT_RTOL``).  Each evaluation costs one forward solve and adjoint sweep
    per root step (typically 2-4 from a nearby period).

    Parameters
    ----------
    kinematics : Harmonic | Fourier | PowerLaw
        One point; theta are its ``family_parameters``.
    physics : Physics
        One point; mu_n, mu_s, p, delta fixed; its period is the first guess of T.
    grid : FixedGrid
    power : float
        Target mean power P > 0 (eq. powerp, in the units of ``physics``).
    rtol : float
        Tolerance of the nonlinear iterations of the periodic solve.
    u0 : float, optional
        Warm start of the shooting.
    max_root_iterations : int

    Returns
    -------
    ConstrainedGradient
        status POWER_ROOT_FAILED when the root is not reached (P_T >= 0: P not decreasing
        in T there, or no T gives the target within the iteration budget).
    """
    if not power > 0:
        raise ValueError(f"power: must be > 0, got {power!r}")
    names, _ = family_parameters(kinematics)
    period = float(physics.period[0])
    target = math.log(power)
    at = None
    for iteration in range(max_root_iterations + 1):
        at = objective_gradient(kinematics, with_period(physics, period), grid,
                                objective="speed", rtol=rtol, u0=u0)
        if at.status != CONVERGED or not at.P > 0:
            return _failed_constraint(names, period, at, at.status or POWER_ROOT_FAILED,
                                      iteration)
        u0 = at.u0
        residual = math.log(at.P) - target
        slope = period * at.grad_P[-1] / at.P  # d log P / d log T
        if abs(residual) <= POWER_ROOT_RTOL:
            break
        if not slope < 0 or iteration == max_root_iterations:
            return _failed_constraint(names, period, at, POWER_ROOT_FAILED, iteration)
        period *= math.exp(min(max(-residual / slope, -1.0), 1.0))
    n_fam = len(names)
    gradient = at.grad_U[:n_fam] - at.grad_U[n_fam] * at.grad_P[:n_fam] / at.grad_P[n_fam]
    return ConstrainedGradient(names, period, at.U, gradient, at, CONVERGED, iteration, at.u0)
