"""Switching functions of the engine (``periodic.driver``): where F(u(tau), tau) is not smooth.

With the link velocity of ``model.force`` (normal w(s) = a + b s, a = -S g, b = omega,
tangential c = C g, g = u + omega S / 4, S = sin phi, C = cos phi) the force integrand has
a kink where w = 0.  F(u(tau), tau) has a corner in tau (for p = 0 a jump of dF/dtau over a
width ~ delta_tau; a corner of the integrand at an end of the link is a corner of its
integral) where:

- the kink crosses the link's inner end, w(0) = a = 0: S = 0 or g = 0;
- it crosses the outer end, w(1/2) = 0: ``outer_end_velocity`` = -S g + omega / 2 = 0;
- the tangential velocity vanishes, c = 0: C = 0 or g = 0.

And the solution itself changes fast where the links stop rotating, omega = 0 (a turning
point of phi): the whole body then slides one way and feels the full friction, so across a
window ~ |u| / |phi''| the force changes by O(mu) (``periodic.traps.trap_ceiling``).  A step whose stages do not sample such a feature does not see it, nor does its
embedded error estimate.  So every one of them is a step end (diffrax ``JumpStepWrapper``,
DifferentialEquations.jl ``tstops``):

- the functions of tau alone (S, C, omega, and omega' where |omega| has a small interior
  minimum: a near-tangency opens the same window without a zero) and the corners of phi
  are known before the pass: ``kinematic_stops`` finds their zeros once per point;
- the functions of u (g and the outer end's velocity) are state events: a sign change
  across a step is located on the step's collocation polynomial (``illinois_root``,
  scipy ``ivp.py``'s ``solve_event_equation`` on the dense output) and the step is cut
  there.
"""
from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np
from numba import njit

from ..model.force import force_slope_power_sc
from ..model.kinematics import FOURIER, angle_and_rate, rate_slope
from .radau import StageKinematics, StepSolution, dense_value, runtime_int

#: ``turning_stops``' codes
TURNING = 1
SIMPLE_TURNING = 2
#: at most this many kinematic stops per period
MAX_STOPS = 512

#: the state switching functions, by index
TANGENTIAL = 0   # g = u + omega S / 4: the link's tangential velocity is C g, its inner
#                  end's normal velocity -S g
OUTER_END = 1    # -S g + omega / 2: the normal velocity at the link's outer end
STOP = 2         # |g| - band: the junction comes to rest (p = 0: the body sticks)
N_STATE_FUNCTIONS = 2  # those that are located at their sign changes (not STOP)

#: ``illinois_root``'s functions, by kind (``root_function``)
KINEMATIC_ROOT = 0
EXIT_ROOT = 1
STATE_ROOT = 2


class Bracket(NamedTuple):
    """A root's bracket [a, b] and the function's values there, of opposite signs."""

    a: float
    b: float
    fa: float
    fb: float


class SolvedStep(NamedTuple):
    """A solved step of a pass, as its events are sought in it (``periodic.events.find_event``).

    t0, h : its start and length; u_n : u at its start; sol : its stages
    (``periodic.radau.StepSolution``: U1, U2, U3 with u_n define the collocation polynomial,
    ``periodic.radau.dense_value``); kin : the kinematics at its stages; S0, om0 : sin phi and
    dphi/dtau at its start (on the step's side of a corner of phi); f0 : kappa F there.
    """

    t0: float
    h: float
    u_n: float
    sol: StepSolution
    kin: StageKinematics
    S0: float
    om0: float
    f0: float


@njit(cache=True, error_model="numpy")
def state_function(k, u, S, om, band=0.0):
    """State switching function ``k`` (TANGENTIAL, OUTER_END or STOP, with the friction's
    ``band``) at u, S = sin phi, om = dphi/dtau."""
    g = u + 0.25 * om * S
    if k == TANGENTIAL:
        return g
    if k == STOP:
        return abs(g) - band
    return -S * g + 0.5 * om


@njit(cache=True, error_model="numpy")
def exit_functions(code, params, t, side, phys, band):
    """(psi_up, psi_down) at t for a body held in the friction's band, g = u + omega S / 4
    ~ 0 (p = 0): with u_s = -omega S / 4 the velocity that keeps the junction at rest,

        psi_up   = kappa F(u_s + band) - u_s',    psi_down = u_s' - kappa F(u_s - band),

    the force at the band's edges against the one the rest needs.  The body stays in the
    band while both are negative and leaves it (upward, downward) where one turns positive:
    a transversal zero, where g itself leaves zero tangentially (its second derivative
    jumps there).  Functions of tau alone (u is u_s)."""
    return _exit_pair(code, params, t, side, phys.kappa, phys.mu_n, phys.mu_s, phys.p,
                      phys.dtau, band)


@njit(cache=True, error_model="numpy")
def _exit_pair(code, params, t, side, kappa, mu_n, mu_s, p, dtau, band):
    """``exit_functions`` from the physics' fields (``root_function``'s EXIT_ROOT)."""
    phi, om = angle_and_rate(code, params, t, side)
    S = math.sin(phi)
    C = math.cos(phi)
    u_s = -0.25 * om * S
    rate = -0.25 * (rate_slope(code, params, t, side) * S + om * om * C)
    F_up = force_slope_power_sc(u_s + band, S, C, om, mu_n, mu_s, p, dtau)[0]
    F_down = force_slope_power_sc(u_s - band, S, C, om, mu_n, mu_s, p, dtau)[0]
    return kappa * F_up - rate, rate - kappa * F_down


@njit(cache=True, error_model="numpy")
def _kinematic_function(k, code, params, t, side):
    """The functions of tau alone: 0 sin phi, 1 cos phi, 2 omega, 3 omega' (by a central
    difference of the analytic omega: only its zeros are used, then refined on omega)."""
    if k == 3:
        e = 1e-6
        return (angle_and_rate(code, params, t + e, side)[1]
                - angle_and_rate(code, params, t - e, side)[1]) / (2.0 * e)
    phi, om = angle_and_rate(code, params, t, side)
    if k == 0:
        return math.sin(phi)
    if k == 1:
        return math.cos(phi)
    return om


@njit(cache=True, error_model="numpy")
def stop_speed(code, params, stops, n_stops):
    """V = (1/4) int_0^1 |dphi/dtau| dtau (``model.limits.kinematic_speed``) from phi at the
    ``kinematic_stops``: phi is monotone between them (they hold every zero of omega and
    every corner), so a quarter of the sum of |phi| differences across them is exact."""
    total = 0.0
    before = angle_and_rate(code, params, 0.0, 0.0)[0]
    for j in range(1, n_stops + 1):
        t = stops[j] if j < n_stops else 1.0
        phi = angle_and_rate(code, params, t, t)[0]  # (phi is continuous: any side)
        total += abs(phi - before)
        before = phi
    return 0.25 * total


@njit(cache=True, error_model="numpy")
def kinematic_stops(code, params, corners, out, options):
    """The step ends every pass of a point keeps: 0, the corners of phi, the zeros of sin phi,
    cos phi and omega, and the near-tangencies (minima of |omega| below
    ``options.tangency_share`` of its maximum).  Writes them sorted into ``out`` (0 first,
    all in [0, 1)); returns their count and max |omega| over the samples (for
    ``turning_stops``).  ``options``: ``periodic.options.StopOptions``.

    The phases between corners are searched separately (each side of a corner with its own
    phi'), on ``options.samples_per_wavenumber`` K samples per period, K the Fourier
    wavenumber (the power law's phases are monotone: 64 samples per phase by default)."""
    tangency = options.tangency_share
    K = max(int(params[0]), 1) if code == FOURIER else 1
    n_samples = options.samples_per_wavenumber * K
    ends = np.empty(corners.size + 2)
    ends[0] = 0.0
    m = 1
    for c in corners:
        if 0.0 < c < 1.0:
            ends[m] = c
            m += 1
    ends[m] = 1.0
    m += 1
    ends = np.sort(ends[:m])
    count = 0
    out[count] = 0.0
    count += 1
    # the four kinematic functions on the samples, from one evaluation of phi per sample
    # (and two for omega'), and max |omega| over them
    values = np.empty((m - 1, 4, n_samples + 1))
    omax = 0.0
    for j in range(m - 1):
        a, b = ends[j], ends[j + 1]
        side = 0.5 * (a + b)
        for i in range(n_samples + 1):
            t = a + (b - a) * i / n_samples
            phi, om = angle_and_rate(code, params, t, side)
            omax = max(omax, abs(om))
            values[j, 0, i] = math.sin(phi)
            values[j, 1, i] = math.cos(phi)
            values[j, 2, i] = om
            values[j, 3, i] = _kinematic_function(runtime_int(3), code, params, t, side)
    for j in range(m - 1):
        a, b = ends[j], ends[j + 1]
        side = 0.5 * (a + b)
        if j > 0 and count < out.size:
            out[count] = a
            count += 1
        for k in range(4):
            t0 = a
            f0 = values[j, k, 0]
            for i in range(1, n_samples + 1):
                t1 = a + (b - a) * i / n_samples
                f1 = values[j, k, i]
                if f0 * f1 < 0.0 and count < out.size:
                    root = illinois_root(runtime_int(KINEMATIC_ROOT), k, code, params, side,
                                         (0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0),
                                         Bracket(t0, t1, f0, f1), options.root_share,
                                         options.root_iterations)
                    keep = True
                    if k == 3:  # an extremum of omega: a stop only where |omega| is small
                        om = angle_and_rate(code, params, root, side)[1]
                        keep = abs(om) < tangency * omax
                    if keep:
                        out[count] = root
                        count += 1
                elif f1 == 0.0 and 0.0 < i < n_samples and count < out.size:
                    # a zero on a sample (an extremum of omega only where |omega| is small:
                    # sin^3-like motions have omega' = 0 exactly on the middle sample, and
                    # the near-tangency at tau = 0.5 was missed, 1.02 rtol off at 1e-3 with an
                    # estimate of 0.19); and an extremum only where omega' changes sign across
                    # the sample: on a linear phase omega' = 0 on every sample, and each
                    # became a turning stop whose trap cap (u ~ 0 after a concave-up closing)
                    # shrank the whole phase's steps to 4e-11, 131,072 steps
                    # (``test_a_linear_phase_has_no_turning_stops``)
                    if k < 3 or (values[j, k, i - 1] * values[j, k, i + 1] < 0.0
                                 and abs(angle_and_rate(code, params, t1, side)[1])
                                 < tangency * omax):
                        out[count] = t1
                        count += 1
                t0, f0 = t1, f1
    stops = np.sort(out[:count])
    # merge near-duplicates (a corner of phi, not a root next to it, stays: with the root
    # 5e-13 before it kept instead, the corner got no step end and a step ran across it,
    # its stages on the other phase's formula) and drop stops at the period's end (1 is 0)
    kept = 0
    for i in range(count):
        t = stops[i]
        if t >= 1.0 - options.gap or t < 0.0:
            continue
        if kept > 0 and t - out[kept - 1] <= options.gap:
            if _is_corner(t, ends, m) and not _is_corner(out[kept - 1], ends, m):
                out[kept - 1] = t
            continue
        out[kept] = t
        kept += 1
    return kept, omax


@njit(cache=True, error_model="numpy")
def _is_corner(t, ends, m):
    """Whether t is one of the corners of phi in ``ends`` (sorted, ends[0] = 0, ends[m - 1] =
    1: the phases' ends of ``kinematic_stops``)."""
    for j in range(m - 1):
        if ends[j] == t:
            return True
    return False


@njit(cache=True, error_model="numpy")
def root_function(kind, k, x, code, params, side, data):
    """The function whose zero ``illinois_root`` seeks, at x, chosen by ``kind``:

    - KINEMATIC_ROOT: kinematic function ``k`` (``_kinematic_function``) at tau = x;
    - EXIT_ROOT: exit function ``k`` (0 up, 1 down; ``exit_functions``) at tau = x, with
      ``data`` = (kappa, mu_n, mu_s, p, dtau, band, -);
    - STATE_ROOT: state function ``k`` (``state_function``) along a solved step's
      collocation polynomial at theta = x, with ``data`` = (t0, h, u_n, U1, U2, U3, band).

    ``data`` is one float 7-tuple for every kind (one compiled signature), ``side`` the side
    of phi's corners the kinematics take (``model.kinematics.angle_and_rate``)."""
    if kind == KINEMATIC_ROOT:
        return _kinematic_function(k, code, params, x, side)
    if kind == EXIT_ROOT:
        return _exit_pair(code, params, x, side, data[0], data[1], data[2], data[3],
                          data[4], data[5])[k]
    t0, h, u_n, U1, U2, U3, band = data
    phi, om = angle_and_rate(code, params, t0 + x * h, side)
    return state_function(k, dense_value(x, u_n, U1, U2, U3), math.sin(phi), om, band)


@njit(cache=True, error_model="numpy")
def illinois_root(kind, k, code, params, side, data, bracket, tol, max_iterations):
    """Zero of ``root_function(kind, k, ., code, params, side, data)`` in its ``Bracket``
    [a, b] (values of opposite signs) by Illinois regula falsi: the secant point c replaces
    the end of the bracket on its side, and the other end's value is halved when the same
    end was kept twice running.  Stops where the bracket is within tol max(1, |c|), where
    the function vanishes at c, or after ``max_iterations``; returns c.

    The engine's one root finder: kinematic stops (``kinematic_stops``, tau), a held body's
    exits and state events on a step's polynomial (``periodic.events.find_event``, tau and
    theta).  The function is chosen by the integer ``kind``, not passed: a root finder
    taking the function as an argument (numba's first-class functions) returned the same
    bits but made every kernel that calls it uncacheable ("dynamic globals": each process
    recompiled the engine), measured in issue 37."""
    a, b, fa, fb = bracket
    last = 0  # -1 where b was replaced last, 1 where a was, 0 at the start
    c = a
    for _ in range(max_iterations):
        c = (a * fb - b * fa) / (fb - fa)
        if b - a <= tol * max(1.0, abs(c)):
            break
        fc = root_function(kind, k, c, code, params, side, data)
        if fc == 0.0:
            break
        if fc * fa < 0.0:
            if last == -1:
                fa *= 0.5
            b, fb, last = c, fc, -1
        else:
            if last == 1:
                fb *= 0.5
            a, fa, last = c, fc, 1
    return c


@njit(cache=True, error_model="numpy")
def turning_stops(code, params, stops, n_stops, omax, options):
    """Which of the stops are turning points of phi, (n_stops,) int8: TURNING where |omega| on
    one side of the stop is below ``options.tangency_share`` (``StopOptions``) of ``omax``, max |omega|
    (``kinematic_stops``' second output: the same threshold that keeps its near-tangencies;
    sampling it again on 1,025 points here had cost 26 us per solve): its zeros, the
    near-tangencies, flat inflections, and the power law's corners where a phase starts or
    ends with omega = 0; SIMPLE_TURNING where moreover |omega'| there is at least
    ``options.simple_share`` of 2 pi omax (a harmonic motion's turning points: omega' =
    2 pi omax), so that omega grows away from it like a simple zero
    (``periodic.options.TrapOptions.floor``); 0 else."""
    out = np.zeros(n_stops, dtype=np.int8)
    for j in range(n_stops):
        t = stops[j]
        left = angle_and_rate(code, params, t, t - 1e-9 if t > 0.0 else 1.0 - 1e-9)[1]
        right = angle_and_rate(code, params, t, t + 1e-9)[1]
        if min(abs(left), abs(right)) < options.tangency_share * omax:
            out[j] = TURNING
            if (abs(rate_slope(code, params, t, t + 1e-9))
                    >= options.simple_share * 2.0 * math.pi * omax):
                out[j] = SIMPLE_TURNING
    return out
