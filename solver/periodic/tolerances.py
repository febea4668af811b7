"""Every tolerance of the engine, derived from rtol in one place.

A solve at relative tolerance rtol aims at |error of U| <= rtol scale_u and |error of P| <=
rtol scale_p (``norm_scales``: scale_u = max(|int u|, U_NORM_FLOOR V), the floor for a body
that hardly moves on average, relative to the speed scale V = (1/4) int |dphi/dtau|;
scale_p = |int Pi|, or 1 where it vanishes).  From rtol and that norm:

- **target** = TARGET_SHARE rtol: what the adaptive passes' steps aim at; the rest of rtol
  is the margin for the converged solution's node weights, which the pass knew only from
  the previous one.
- **loose** = max(LOOSE_RTOL, rtol), **loose_target** = TARGET_SHARE loose: the loose
  shooting (step 2 of ``periodic.point``) only finds the orbit's neighbourhood and the node
  weights, judged in u relative to V (int u is not known yet).
- **stage tolerance** (``stage_atol``) = max(STAGE_SHARE rtol, STAGE_FLOOR) times the norm,
  for p = 0 at most BAND_SHARE delta_tau, and divided by the largest node weight
  (``target_stage_atol``): every converged step carries a stage residual up to it, which
  the node weights carry to U and P, so it must stay a small share of rtol there (at short
  periods lambda reaches 4e3, and stages solved to the plain tolerance left errors of 5
  rtol); inside the friction's band F rises by O(mu) across ~delta_tau, and stages solved
  more loosely land anywhere on the saturated force (delta 1e-10, tolerance 4e-8 V:
  u chattering +-1e-6 around rest, 131,072 steps).
- **shooting** = max(SHOOTING_SHARE rtol, SHOOTING_FLOOR) V (``tol_fix``): the frozen Newton
  on u(0) stops where the fixed point is this close; the converged pass is then shifted
  onto it to first order, so this bounds only the second-order remainder.
- **bound** (``u0_bound``): u(0) is bracketed in +-(BRACKET_SPEEDS V + BRACKET_GUESSES
  |u_guess|).

The factors are ``periodic.options.ToleranceOptions`` (the defaults, documented there, are
the names above), passed to every function here as ``options``.
"""
from __future__ import annotations

from typing import NamedTuple

from numba import njit



class Tolerances(NamedTuple):
    """What ``tolerances`` derives from rtol and V (see the module docstring)."""

    rtol: float
    target: float
    loose: float
    loose_target: float
    shooting: float


@njit(cache=True, error_model="numpy")
def tolerances(rtol, vscale, options):
    """The ``Tolerances`` of a solve at ``rtol`` of a point with speed scale ``vscale``, by
    the factors ``options`` (``ToleranceOptions``)."""
    loose = max(options.loose_rtol, rtol)
    return Tolerances(rtol, options.target_share * rtol, loose, options.target_share * loose,
                      max(options.shooting_share * rtol, options.shooting_floor) * vscale)


@njit(cache=True, error_model="numpy")
def norm_scales(int_u, int_p, vscale, options):
    """(scale_u, scale_p): the norm of U and P (see the module docstring)."""
    return max(abs(int_u), options.u_norm_floor * vscale), (abs(int_p) if int_p != 0.0 else 1.0)


@njit(cache=True, error_model="numpy")
def stage_tolerance(rtol, scale, options):
    """max(stage_share rtol, stage_floor) ``scale``."""
    return max(options.stage_share * rtol, options.stage_floor) * scale


@njit(cache=True, error_model="numpy")
def stage_atol(rtol, scale, phys, options):
    """The stage Newton's tolerance at ``rtol`` in the norm ``scale``, for p = 0 at most
    band_share delta_tau."""
    atol = stage_tolerance(rtol, scale, options)
    if phys.p == 0.0:
        atol = min(atol, options.band_share * phys.dtau)
    return atol


@njit(cache=True, error_model="numpy")
def target_stage_atol(rtol, scale_u, phys, largest_weight, options):
    """``stage_atol`` in U's norm divided by the largest node weight (``periodic.point``'s
    ``largest_weight``)."""
    return stage_atol(rtol, scale_u, phys, options) / largest_weight


@njit(cache=True, error_model="numpy")
def u0_bound(vscale, u_guess, options):
    """The half-width of u(0)'s bracket."""
    return options.bracket_speeds * vscale + options.bracket_guesses * abs(u_guess)
