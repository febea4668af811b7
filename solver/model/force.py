"""The force integral over one link, its derivative in u, and the power density.

All functions here are scalar numba kernels: pure functions of floats, no state.

Geometry (paper, section "Model").  On the upper link, 0 <= s <= 1/2, with
S = sin(phi), C = cos(phi), omega = dphi/dtau and the scaled centre-of-mass
velocity u, the link velocity in scaled time has the components

    v_s(s) = c         = C (u + omega S / 4)                 (tangential, constant in s)
    v_n(s) = w(s)      = a + b s,  a = -u S - omega S^2 / 4,  b = omega   (normal, linear in s)

and the x-component of the resistive force (eqs. frictiondelta, frictionp, vp) is

    f_x(s) = (mu_n S w - mu_s C c) r^(p-1),    r^2 = w^2 + c^2 + delta_tau^2.

With e^2 = c^2 + delta_tau^2 every integral over the link is a moment

    m_k^j = int_0^{1/2} w^k r^(p-1-2j) ds,     k = 0, 1, 2,  j = 0, 1,

and (eq. Newtonu, its u-derivative, and the integrand of eq. powerp)

    F      = 2 [mu_n S m_1^0 - mu_s C c m_0^0]
    dF/du  = 2 [-(mu_n S^2 + mu_s C^2) m_0^0
                + (p-1) (-mu_n S^2 m_2^1 + (mu_n + mu_s) S C c m_1^1 - mu_s C^2 c^2 m_0^1)]
    Pi     = 2 [mu_n m_2^0 + mu_s c^2 m_0^0].

How the moments are computed.  Substituting w for s (ds = dw / b) the moments
have closed forms in w (asinh and square roots for p = 0, polynomials for p = 1,
and for other p a single special function K below).  The closed forms are
differences of boundary terms divided by b, which cancel catastrophically
when the link's velocity varies little along it (|b| small against the
distance d from the w-interval to the singularities w = +-i e of the
integrand).  Exactly there the integrand is analytic in a large Bernstein
ellipse around the interval, so an 8-point Gauss-Legendre rule in s is exact
to rounding.  The switch is at d = 4 h (h the half-length of the
w-interval): beyond it Gauss-Legendre converges like rho^-16 with rho > 8;
below it the boundary terms are at most ~6 h in size against differences of
order h, so the closed form loses at most one digit.  Where the kink
w = 0 lies inside the link and e is small, only the closed form is accurate,
and it is used.

For 0 < p < 2, p != 1, the closed forms need one function,

    K(X) = int_0^X (1 + x^2)^((p-3)/2) dx,     K(inf) = B(1/2, 1 - p/2) / 2,

evaluated by 16-point Gauss-Legendre for |X| <= 2 and by its convergent
series in 1/X^2 for |X| > 2 (differences of two large arguments are taken as
differences of tails, never of K(inf) - tail).  Then with E = e^p [K(x2) - K(x1)],
x = w / e, brackets [.] meaning the difference of boundary values at
w1 = a and w2 = a + b/2:

    M_0^0 = [w r^(p-1)] / p + (p-1)/p E          (integration by parts)
    M_1^0 = [r^(p+1)] / (p+1)
    M_1^1 = [r^(p-1)] / (p-1)
    e^2 M_0^1 = E,   M_2^1 = M_0^0 - E,   M_2^0 = ([w r^(p+1)] - e^2 M_0^0) / (p+2)

and m = M / b.  For p = 0, M_0^0 = asinh(x2) - asinh(x1) (taken as the log of
a ratio when x1, x2 have one sign) and E = [w / r], formed without powers
(``_moments_closed_coulomb``); for w1, w2 of one sign E = e^2 (w2^2 - w1^2) /
((w2 r1 + w1 r2) r1 r2), since w / r -> sign(w) cancels when e << |w| (m_0^1 =
E / e^2, in dF/du, had lost every digit at e ~ 1e-11 with the kink off the link).  Near p = 0 the two terms
of M_0^0 cancel by a factor ~p: for p < 0.05 up to one digit is lost.
"""
from __future__ import annotations

import math

import numpy as np
from numba import njit

# Gauss-Legendre nodes/weights on [0, 1].
_x8, _w8 = np.polynomial.legendre.leggauss(8)
GL8_NODES = 0.5 * (_x8 + 1.0)
GL8_WEIGHTS = 0.5 * _w8
_x16, _w16 = np.polynomial.legendre.leggauss(16)
GL16_NODES = 0.5 * (_x16 + 1.0)
GL16_WEIGHTS = 0.5 * _w16

#: closed form is used when the distance to the singularities is < this many half-lengths
SWITCH_RATIO = 4.0
#: the series for K(X) is used for |X| above this
K_SERIES_START = 2.0
#: floor on e when delta = 0 (p > 0 only): keeps 0 * inf out of the algebra (1e-150 did not:
#: at u = omega = 0, r^(p-3) overflowed and m_2^1 = 0 * inf made dF/du NaN)
E_FLOOR = 1e-100


@njit(cache=True, error_model="numpy")
def k_infinity(p):
    """K(inf) = B(1/2, 1 - p/2) / 2 for 0 <= p < 2."""
    return 0.5 * math.sqrt(math.pi) * math.gamma(1.0 - 0.5 * p) / math.gamma(1.5 - 0.5 * p)


@njit(cache=True, error_model="numpy")
def k_tail(X, p):
    """int_X^inf (1 + x^2)^((p-3)/2) dx for X >= K_SERIES_START (binomial series in 1/X^2)."""
    beta = 0.5 * (p - 3.0)
    inv2 = 1.0 / (X * X)
    term_power = X ** (p - 2.0)
    coef = 1.0
    total = 0.0
    for k in range(200):
        contrib = coef * term_power / (2.0 - p + 2.0 * k)
        total += contrib
        if abs(contrib) <= 1e-17 * abs(total):
            break
        coef *= (beta - k) / (k + 1.0)
        term_power *= inv2
    return total


@njit(cache=True, error_model="numpy")
def k_small(X, p):
    """int_0^X (1 + x^2)^((p-3)/2) dx for 0 <= X <= K_SERIES_START (16-point Gauss-Legendre)."""
    beta = 0.5 * (p - 3.0)
    total = 0.0
    for i in range(16):
        x = X * GL16_NODES[i]
        total += GL16_WEIGHTS[i] * (1.0 + x * x) ** beta
    return X * total


@njit(cache=True, error_model="numpy")
def k_difference(x1, x2, p):
    """K(x2) - K(x1), K odd, without forming K(inf) - tail differences of close tails."""
    if x1 * x2 > 0.0 and abs(x1) > K_SERIES_START and abs(x2) > K_SERIES_START:
        sgn = 1.0 if x1 > 0.0 else -1.0
        return sgn * (k_tail(abs(x1), p) - k_tail(abs(x2), p))
    return k_odd(x2, p) - k_odd(x1, p)


@njit(cache=True, error_model="numpy")
def k_odd(x, p):
    ax = abs(x)
    if ax <= K_SERIES_START:
        val = k_small(ax, p)
    elif math.isinf(ax):
        val = k_infinity(p)
    else:
        val = k_infinity(p) - k_tail(ax, p)
    return val if x >= 0.0 else -val


@njit(cache=True, error_model="numpy")
def radial_power(r2, p):
    """r^(p-1) from r^2: by square roots at the paper's p = 0, 0.5, 1, 1.5, where ``pow``
    made the 8-point rule ~4x slower (128 against 33 ns per p = 0 evaluation)."""
    if p == 0.0:
        return 1.0 / math.sqrt(r2)
    if p == 1.0:
        return 1.0
    if p == 0.5:
        return 1.0 / math.sqrt(math.sqrt(r2))
    if p == 1.5:
        return math.sqrt(math.sqrt(r2))
    return r2 ** (0.5 * (p - 1.0))


@njit(cache=True, error_model="numpy")
def _moments_quadrature(a, b, e2, p):
    """(m00, m10, m20, m01, m11, m21) by 8-point Gauss-Legendre on s in [0, 1/2]."""
    m00 = m10 = m20 = m01 = m11 = m21 = 0.0
    for i in range(8):
        s = 0.5 * GL8_NODES[i]
        wt = 0.5 * GL8_WEIGHTS[i]
        w = a + b * s
        r2 = w * w + e2
        g0 = radial_power(r2, p)
        g1 = g0 / r2
        m00 += wt * g0
        m10 += wt * w * g0
        m20 += wt * w * w * g0
        m01 += wt * g1
        m11 += wt * w * g1
        m21 += wt * w * w * g1
    return m00, m10, m20, m01, m11, m21


@njit(cache=True, error_model="numpy")
def _moments_closed(a, b, e2, p):
    """The same moments from closed forms in w (b != 0, e2 > 0; 0 < p < 2, p != 1: p = 0 is
    ``_moments_closed_coulomb``, p = 1 polynomial)."""
    w1 = a
    w2 = a + 0.5 * b
    e = math.sqrt(e2)
    r1 = math.sqrt(w1 * w1 + e2)
    r2 = math.sqrt(w2 * w2 + e2)
    x1 = w1 / e
    x2 = w2 / e
    E = (e ** p) * k_difference(x1, x2, p)
    M00 = (w2 * r2 ** (p - 1.0) - w1 * r1 ** (p - 1.0)) / p + (p - 1.0) / p * E
    M10 = (r2 ** (p + 1.0) - r1 ** (p + 1.0)) / (p + 1.0)
    M11 = (r2 ** (p - 1.0) - r1 ** (p - 1.0)) / (p - 1.0)
    M20 = (w2 * r2 ** (p + 1.0) - w1 * r1 ** (p + 1.0) - e2 * M00) / (p + 2.0)
    M21 = M00 - E
    M01 = E / e2
    inv_b = 1.0 / b
    return M00 * inv_b, M10 * inv_b, M20 * inv_b, M01 * inv_b, M11 * inv_b, M21 * inv_b


@njit(cache=True, error_model="numpy")
def _moments_closed_coulomb(a, b, e2):
    """``_moments_closed`` at p = 0 with no powers: with r_i = sqrt(w_i^2 + e^2),
    sqrt(1 + x_i^2) = r_i / e, so asinh(x2) - asinh(x1) = log((|w2| + r2) / (|w1| + r1))
    (w1, w2 of one sign: no cancellation of large logs) and E = [w / r]."""
    w1 = a
    w2 = a + 0.5 * b
    r1 = math.sqrt(w1 * w1 + e2)
    r2 = math.sqrt(w2 * w2 + e2)
    # one division for 1 / (r1 r2), shared by M11 = 1/r1 - 1/r2 = (r2 - r1) / (r1 r2) and
    # [w / r] (divisions were ~half of an evaluation's latency after the logs)
    rr = 1.0 / (r1 * r2)
    if w1 * w2 > 0.0:
        M00 = math.log((abs(w2) + r2) / (abs(w1) + r1))
        if w1 < 0.0:
            M00 = -M00
        # [w / r] = e^2 (w2^2 - w1^2) / ((w2 r1 + w1 r2) r1 r2): w / r -> sign(w) cancels
        # when e << |w| (M01 = E / e^2 lost all digits at e ~ 1e-11)
        M01 = (w2 - w1) * (w2 + w1) * rr / (w2 * r1 + w1 * r2)
        E = e2 * M01
    else:
        # w1, w2 of opposite signs: asinh(x2) - asinh(x1) = sign(w2 - w1) (asinh |x2| +
        # asinh |x1|), one log of a product of two factors >= 1 (no cancellation; the sum is
        # >= asinh(|b| / 2e) > asinh(1/2) where the closed form is used, e < |b|).  Two asinh
        # calls (each a log or log1p) were ~9 % of an engine solve's time (bench, perf)
        both = (abs(w2) + r2) * (abs(w1) + r1) / e2
        if both < math.inf:
            M00 = math.copysign(math.log(both), w2 - w1)
        else:  # (overflow: a diverging Newton iterate's huge |u| over a tiny e)
            e = math.sqrt(e2)
            M00 = math.asinh(w2 / e) - math.asinh(w1 / e)
        E = (w2 * r1 - w1 * r2) * rr  # (w2 / r2 - w1 / r1: terms of one sign)
        M01 = E / e2
    M10 = r2 - r1
    M11 = M10 * rr
    M20 = 0.5 * (w2 * r2 - w1 * r1 - e2 * M00)
    inv_b = 1.0 / b
    return (M00 * inv_b, M10 * inv_b, M20 * inv_b, M01 * inv_b, M11 * inv_b, (M00 - E) * inv_b)


@njit(cache=True, error_model="numpy")
def link_moments(a, b, e2, p):
    """Moments m_k^j of the link integrand; see the module docstring."""
    if p == 1.0:
        # r^0: polynomial moments; the j = 1 moments are multiplied by (p - 1) = 0.
        m00 = 0.5
        m10 = 0.5 * a + 0.125 * b
        m20 = 0.5 * a * a + 0.25 * a * b + b * b / 24.0
        return m00, m10, m20, 0.0, 0.0, 0.0
    h = 0.25 * abs(b)
    mid = a + 0.25 * b
    gap = max(abs(mid) - h, 0.0)
    # written as "not <" so that a NaN stage iterate takes the quadrature (NaN moments, which
    # the stage Newton reports) rather than the closed forms' 1 / b: with b = 0 that raised
    # ZeroDivisionError out of the compiled solver (delta 1e-10, power-law corners)
    if not (gap * gap + e2 < (SWITCH_RATIO * h) ** 2):
        return _moments_quadrature(a, b, e2, p)
    if p == 0.0:
        return _moments_closed_coulomb(a, b, e2)
    return _moments_closed(a, b, e2, p)


@njit(cache=True, error_model="numpy")
def link_setup(u, phi, omega, delta_tau, p):
    return link_setup_sc(u, math.sin(phi), math.cos(phi), omega, delta_tau, p)


@njit(cache=True, error_model="numpy")
def link_setup_sc(u, S, C, omega, delta_tau, p):
    a = -u * S - 0.25 * omega * S * S
    b = omega
    c = C * (u + 0.25 * omega * S)
    e2 = c * c + delta_tau * delta_tau
    if e2 < E_FLOOR * E_FLOOR:
        e2 = E_FLOOR * E_FLOOR
    return S, C, a, b, c, e2


@njit(cache=True, error_model="numpy")
def force_and_slope(u, phi, omega, mu_n, mu_s, p, delta_tau):
    """Scaled net x-force F(u, tau) = 2 int_0^{1/2} f_x ds and dF/du.

    Parameters
    ----------
    u : float
        Scaled centre-of-mass velocity (eq. tau).
    phi, omega : float
        Half opening angle [rad] and its tau-derivative [rad per period].
    mu_n, mu_s : float
        Normal and tangential friction (resistance) coefficients.
    p : float
        Resistive force exponent, 0 <= p < 2 (eq. vp).
    delta_tau : float
        Regularisation T * delta (eq. tau).

    Returns
    -------
    F, dF_du : float
        The ODE is u' = T^(2-p) F (eq. Newtonu).  dF_du is mostly negative, but the
        anisotropic law is not the gradient of a convex dissipation, so it can be > 0.
    """
    return force_and_slope_sc(u, math.sin(phi), math.cos(phi), omega, mu_n, mu_s, p, delta_tau)


@njit(cache=True, error_model="numpy")
def force_and_slope_sc(u, S, C, omega, mu_n, mu_s, p, delta_tau):
    """``force_and_slope`` from S = sin(phi), C = cos(phi): a stage's Newton iterations
    evaluate F at one phi several times, and sin and cos were ~15 % of an evaluation."""
    S, C, a, b, c, e2 = link_setup_sc(u, S, C, omega, delta_tau, p)
    return _force_and_slope_from(S, C, c, mu_n, mu_s, p, *link_moments(a, b, e2, p))


@njit(cache=True, error_model="numpy")
def _force_and_slope_from(S, C, c, mu_n, mu_s, p, m00, m10, m20, m01, m11, m21):
    F = 2.0 * (mu_n * S * m10 - mu_s * C * c * m00)
    slope = -(mu_n * S * S + mu_s * C * C) * m00
    if p != 1.0:
        slope += (p - 1.0) * (-mu_n * S * S * m21 + (mu_n + mu_s) * S * C * c * m11
                              - mu_s * C * C * c * c * m01)
    return F, 2.0 * slope


@njit(cache=True, error_model="numpy")
def force_slope_power_sc(u, S, C, omega, mu_n, mu_s, p, delta_tau):
    """``force_and_slope_sc`` and the power density Pi (``power_density``) with dPi/du, from
    the same link moments: the stage Newton iterations carry Pi along, so a converged sweep
    needs no separate power pass (it was a quarter of all evaluations).

    dPi/du differentiates Pi = 2 (mu_n m_2^0 + mu_s c^2 m_0^0) term by term, with the
    moment derivatives of ``adjoint.gradient.force_partials`` for theta = u (w_u = -S, c_u = C).
    """
    S, C, a, b, c, e2 = link_setup_sc(u, S, C, omega, delta_tau, p)
    m00, m10, m20, m01, m11, m21 = link_moments(a, b, e2, p)
    F, slope = _force_and_slope_from(S, C, c, mu_n, mu_s, p, m00, m10, m20, m01, m11, m21)
    q = p - 1.0
    cC = c * C
    d00 = q * (cC * m01 - S * m11)
    d20 = -2.0 * S * m10 + q * (cC * m21 - S * (m10 - e2 * m11))
    power = 2.0 * (mu_n * m20 + mu_s * c * c * m00)
    power_u = 2.0 * (mu_n * d20 + mu_s * (2.0 * cC * m00 + c * c * d00))
    return F, slope, power, power_u


@njit(cache=True, error_model="numpy")
def power_density(u, phi, omega, mu_n, mu_s, p, delta_tau):
    """Pi(tau) = 2 int_0^{1/2} (mu_n v_n^2 + mu_s v_s^2) r^(p-1) ds (integrand of eq. powerp).

    The mean power is P = T^-(p+1) int_0^1 Pi dtau.
    """
    S, C, a, b, c, e2 = link_setup(u, phi, omega, delta_tau, p)
    m00, m10, m20, m01, m11, m21 = link_moments(a, b, e2, p)
    return 2.0 * (mu_n * m20 + mu_s * c * c * m00)
