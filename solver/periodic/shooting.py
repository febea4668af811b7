"""The shooting of the periodic state: the monodromy M = prod_n du_{n+1}/du_n of a pass
(its log and sign, without cancellation at M ~ 1), the bracketed Newton update of u(0), and
and Newton on u(0) over a fixed step
sequence (``frozen_newton``: frozen passes of ``periodic.integrator.frozen_pass``), the
period map, the period integrals of a recorded pass and the shift of a converged pass onto
its fixed point.

Shared by the engine's shooting (``periodic.driver``), its adjoint (``adjoint.gradient``) and the
explicit march (``march.heun``), which thus do not depend on each other.
"""
from __future__ import annotations

import math
from typing import NamedTuple

from numba import njit

from ..status import CONVERGED, NON_FINITE, NOT_PERIODIC, STAGE_SOLVE_FAILED
from .integrator import frozen_pass
from .record import monodromy_minus_1, node_value, recorded_integrals, shift_node_value, shift_step
from .tolerances import stage_atol, tolerances, u0_bound


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
    every period forgets u(0), M = 0, and its second pass returned u(1) = u(0) exactly)."""
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
def period_map(W, N, u0):
    """(g = u(1) - u(0), 1 - M) of a pass: the shooting residual and one minus the
    monodromy (``periodic.shooting.one_minus_monodromy``)."""
    log_m = 0.0
    sign_m = 1.0
    for n in range(N):
        log_m, sign_m = monodromy_factor(log_m, sign_m, monodromy_minus_1(W, n))
    return node_value(W, N) - u0, one_minus_monodromy(log_m, sign_m)


@njit(cache=True, error_model="numpy")
def period_integrals(W, N):
    int_u = 0.0
    int_p = 0.0
    for n in range(N):
        step_u, step_p = recorded_integrals(W, n)
        int_u += step_u
        int_p += step_p
    return int_u, int_p


@njit(cache=True, error_model="numpy")
def shift_onto_fixed_point(W, N, shift):
    """Move the converged pass, which starts ``shift`` short of the fixed point, onto it to
    first order along the sensitivities (no force evaluations)."""
    for n in range(N):
        shift = shift_step(W, n, shift)
    shift_node_value(W, N, shift)


class FrozenNewton(NamedTuple):
    """What ``frozen_newton`` returns.

    u0 : the last u(0); g, one_minus_M : the period map there (``period_map``); status :
    CONVERGED (the fixed point within tol_fix, u0 inside the bracket) or the failure;
    restart_u0 : after a failure, where the next round's adaptive pass starts (NaN: the
    failure stands); passes, evaluations : frozen passes made and their evaluations of F."""

    u0: float
    g: float
    one_minus_M: float
    status: int
    restart_u0: float
    passes: int
    evaluations: int


@njit(cache=True, error_model="numpy")
def frozen_newton(code, params, phys, u0, atol, W, N, tol_fix, bound, options):
    """Newton on u(0) over the N recorded steps of ``W`` (``frozen_pass``, in place) until
    |g| <= tol_fix |1 - M|, bracketed in +-bound; ``options``: the ``EngineOptions`` (at
    most ``options.point.max_frozen_passes`` passes, MAX_FROZEN_PASSES; the stage solve's).

    Where the frozen steps do not carry Newton to the fixed point (a stage solve fails on
    them, a pass is not finite, or the passes run out), the next round's adaptive
    pass places its steps anew: from Newton's last proposal after a failed stage solve,
    else from the best u(0) seen (smallest |g / (1 - M)|); where that is the start, the next
    round would repeat this one, and the failure stands (restart_u0 NaN), as it does where
    the period map itself is not finite."""
    lo, hi = -bound, bound
    start = best_u0 = u0
    best_residual = math.inf
    passes = 0
    evaluations = 0
    g = 0.0
    one_minus_M = 1.0
    status = NOT_PERIODIC
    for _ in range(options.point.max_frozen_passes):
        g, one_minus_M = period_map(W, N, u0)
        if not (math.isfinite(g) and math.isfinite(one_minus_M) and one_minus_M != 0.0):
            return FrozenNewton(u0, g, one_minus_M, NON_FINITE, math.nan, passes, evaluations)
        if abs(g) <= tol_fix * abs(one_minus_M):
            status = CONVERGED if abs(u0) < 0.999 * bound else NOT_PERIODIC
            break
        if abs(g / one_minus_M) < best_residual:
            best_u0, best_residual = u0, abs(g / one_minus_M)
        u0, lo, hi = bracketed_newton_update(u0, g, one_minus_M, lo, hi)
        status, e = frozen_pass(code, params, phys, u0, atol, W, N, options.stage)
        passes += 1
        evaluations += e
        if status == STAGE_SOLVE_FAILED:
            return FrozenNewton(u0, g, one_minus_M, status, u0, passes, evaluations)
        if status != CONVERGED:
            break
        status = NOT_PERIODIC
    if status == CONVERGED:
        return FrozenNewton(u0, g, one_minus_M, status, math.nan, passes, evaluations)
    restart = best_u0 if best_u0 != start else math.nan
    return FrozenNewton(u0, g, one_minus_M, status, restart, passes, evaluations)


@njit(cache=True, error_model="numpy")
def frozen_orbit(code, params, phys, u0, rtol, vscale, W, N, options):
    """The periodic solution of the Radau IIA discretisation on the N steps set up in ``W``
    (their times, kinematics and first stage guesses, ``periodic.record.set_grid_step``),
    without error control: a frozen pass from u(0) = ``u0``, Newton on u(0) by frozen passes
    (``frozen_newton``) to the shooting tolerance of ``rtol`` and ``vscale``
    (``periodic.tolerances``), and the converged pass shifted onto the fixed point.  ``W``
    holds that pass afterwards.  The fixed-grid solves of the order tests and of the adjoint.
    ``options``: the ``EngineOptions`` (its tolerances', stage solve's and frozen passes').

    Returns (status, u(0), int u, int Pi): the integrals NaN unless CONVERGED; u(0) the
    last one reached."""
    tols = options.tolerances
    atol = stage_atol(rtol, vscale, phys, tols)
    status, _ = frozen_pass(code, params, phys, u0, atol, W, N, options.stage)
    if status != CONVERGED:
        return status, u0, math.nan, math.nan
    fn = frozen_newton(code, params, phys, u0, atol, W, N,
                       tolerances(rtol, vscale, tols).shooting, u0_bound(vscale, u0, tols),
                       options)
    if fn.status != CONVERGED:
        return fn.status, fn.u0, math.nan, math.nan
    shift = fn.g / fn.one_minus_M
    shift_onto_fixed_point(W, N, shift)
    int_u, int_p = period_integrals(W, N)
    return CONVERGED, fn.u0 + shift, int_u, int_p
