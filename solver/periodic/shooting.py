"""The shooting of the periodic state: the monodromy M = prod_n du_{n+1}/du_n of a sweep
(its log and sign, without cancellation at M ~ 1), the bracketed Newton update of u(0), and
the stage solve's tolerance relative to the speed scale.

Shared by the engine's shooting (``periodic.driver``), its adjoint (``adjoint.gradient``) and the
explicit march (``march.heun``), which thus do not depend on each other.
"""
from __future__ import annotations

import math

from numba import njit


@njit(cache=True, error_model="numpy")
def monodromy_factor(log_m, sign_m, m_minus_1):
    """(log |M|, sign M) of the monodromy M = prod m_n with one more step factor m_n, given
    as m_n - 1 (formed without cancellation; log1p keeps it near m_n = 1)."""
    if m_minus_1 <= -1.0:  # a step that reverses perturbations: track the sign of M
        return log_m + (math.log(-1.0 - m_minus_1) if m_minus_1 < -1.0 else -math.inf), -sign_m
    return log_m + math.log1p(m_minus_1), sign_m


@njit(cache=True, error_model="numpy")
def one_minus_monodromy(log_m, sign_m):
    """1 - M from ``monodromy_factor``'s (log |M|, sign M), without cancellation at M ~ 1."""
    return -math.expm1(log_m) if sign_m > 0.0 else 1.0 + math.exp(log_m)


@njit(cache=True, error_model="numpy")
def bracketed_newton_update(u0, g, one_minus_M, lo, hi):
    """Newton's step on u(0) for the shooting residual g = u(1) - u(0) with 1 - M its
    derivative, kept inside the bracket [lo, hi] of the fixed point (g > 0 below it, g < 0
    above it) and bisecting where Newton leaves the bracket (the map need not be monotone:
    the anisotropic law can amplify, M > 1 or M < 0).  Returns (new u0, lo, hi).

    g = 0 exactly is the fixed point, and u0 stays: as the bracket's new upper end, Newton's
    u0 did not lie strictly inside it, and the bisection threw a loose shooting that stood
    on its fixed point to the bracket's middle (-116 for -2.6e-3; a body that sticks in
    every period forgets u(0), M = 0, and its second sweep returned u(1) = u(0) exactly)."""
    if g == 0.0:
        return u0, lo, hi
    if g > 0.0:
        lo = max(lo, u0)
    else:
        hi = min(hi, u0)
    candidate = u0 + g / one_minus_M
    if not (lo < candidate < hi):
        candidate = 0.5 * (lo + hi)
    return candidate, lo, hi


@njit(cache=True, error_model="numpy")
def stage_tolerance(rtol, vscale):
    """The stage Newton's absolute tolerance in u: max(1e-5 rtol, 1e-14) V, V the speed scale.
    Every converged step carries a residual up to this size."""
    return max(1e-5 * rtol, 1e-14) * vscale
