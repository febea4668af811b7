"""State events inside a solved step and where a step should end for them.

Detection (``first_crossing``: sign changes of the switching functions across the step's
start, stages and end; for p = 0 the body entering the friction's band, or leaving it by an
exit function) and location on the collocation polynomial (the root finder
``periodic.switching.illinois_root``), combined into the earliest event of a step by
``find_event``; stop placement ahead of a step (``stop_reach``: where the slipping body's line reaches the band); and the
exit functions' memo (``held_exits``).
"""
from __future__ import annotations

import math

import numpy as np
from numba import njit

from ..model.kinematics import angle_and_rate
from .radau import C1, C2, runtime_int
from .switching import (EXIT_ROOT, STATE_ROOT, Bracket, N_STATE_FUNCTIONS, STOP, TANGENTIAL,
                        exit_functions, illinois_root, rate_slope, state_function)


@njit(cache=True, error_model="numpy")
def _first_crossing(step, atol, dtau, options):
    """The earliest sign change of a state switching function across the step, sampled at
    its start, its stages and its end along the solution: (k, theta_a, theta_b, f_a, f_b),
    or k = -1 where there is none.

    A value has a sign only beyond the noise of the stage values (``options.noise``, an
    ``EventOptions``, times the stage tolerance ``atol``, and rounding, ``sign_rounding``: a
    body at rest at tau = 0 has g = +-1e-17), and a sign change is a crossing only where one
    side lies beyond ``crossing_band`` delta_tau: inside
    the friction's band F is smooth (a stuck g whose sign changes with the force it must
    hold is no corner; cut there, a pass at delta 1e-10 took 1e5 steps of 1e-11).  Not
    both sides beyond it: a step cut to an event located on a longer step's polynomial can
    end just past the corner, inside the band (measured: such steps kept the corner 3 % of
    the step inside and were rejected, 1e3 rtol over, down to steps of 1e-6).  ``step``: a
    ``periodic.switching.SolvedStep``."""
    u_n, sol, kin, S0, om0 = step.u_n, step.sol, step.kin, step.S0, step.om0
    best_k = -1
    best_a = 2.0
    best_b = 2.0
    best_fa = 0.0
    best_fb = 0.0
    noise = options.noise * atol
    sharp = options.crossing_band * dtau
    rounding = options.sign_rounding
    for k in range(N_STATE_FUNCTIONS):
        f0 = state_function(k, u_n, S0, om0, 0.0)
        f1 = state_function(k, sol.U1, kin.S1, kin.om1, 0.0)
        f2 = state_function(k, sol.U2, kin.S2, kin.om2, 0.0)
        f3 = state_function(k, sol.U3, kin.S3, kin.om3, 0.0)
        # the span over the step's samples, not of the pair around the sign change: a slow
        # crossing of -3.5 to +4.1 delta_tau in steps of 2 delta_tau was missed (2.5 rtol)
        if max(f0, f1, f2, f3) - min(f0, f1, f2, f3) <= sharp:
            continue
        f_prev = f0
        th_prev = 0.0
        signed = abs(f_prev) > max(noise, rounding * (abs(u_n) + abs(om0)))
        for i in range(3):
            if i == 0:
                th, u, om, f = C1, sol.U1, kin.om1, f1
            elif i == 1:
                th, u, om, f = C2, sol.U2, kin.om2, f2
            else:
                th, u, om, f = 1.0, sol.U3, kin.om3, f3
            if abs(f) <= max(noise, rounding * (abs(u) + abs(om))):
                continue
            if signed and f_prev * f < 0.0:
                if th_prev < best_a:
                    best_k, best_a, best_b, best_fa, best_fb = k, th_prev, th, f_prev, f
                break
            f_prev = f
            th_prev = th
            signed = True
    return best_k, best_a, best_b, best_fa, best_fb


@njit(cache=True, error_model="numpy")
def stop_reach(phys, u, f0, band, S, C, om, om_slope):
    """How far from u the line of g = u + omega S / 4, with the slipping body's slope
    kappa F + (omega S / 4)' = f0 + (om_slope S + om^2 C) / 4 (S, C: sin phi, cos phi;
    om_slope: d omega / d tau), reaches the friction's band (p = 0), or -1 where g does not
    approach it (or is in it already).  A prediction where to end the next step (the stop
    itself is located on the solved step, ``find_event``)."""
    if phys.p != 0.0 or band <= 0.0:
        return -1.0
    g = u + 0.25 * om * S
    if abs(g) <= band:
        return -1.0
    slope = f0 + 0.25 * (om_slope * S + om * om * C)
    reach = (math.copysign(band, g) - g) / slope if slope != 0.0 else -1.0
    return reach if reach > 0.0 else -1.0


@njit(cache=True, error_model="numpy")
def stop_reach_at(code, params, phys, t, u, f0, band):
    """``stop_reach`` from (t, u) with the kinematics on the right of t evaluated afresh
    (at tau = 0 and after a corner of phi)."""
    if phys.p != 0.0 or band <= 0.0:
        return -1.0
    phi, om = angle_and_rate(code, params, t, t + 1e-9)
    return stop_reach(phys, u, f0, band, math.sin(phi), math.cos(phi), om,
                       rate_slope(code, params, t, t + 1e-9))


#: d/dtheta at theta = 1 of the quadratic through a step's stages (c1, c2, 1): omega's slope
#: at the step's end from its stage values (``stop_reach`` after an ordinary step)
END_D1 = (1.0 - C2) / ((C1 - C2) * (C1 - 1.0))
END_D2 = (1.0 - C1) / ((C2 - C1) * (C2 - 1.0))
END_D3 = 1.0 / (1.0 - C1) + 1.0 / (1.0 - C2)


#: an ``exit_memo`` (``new_exit_memo``): the exit functions at the last two times they were
#: evaluated, (tau, psi_up, psi_down) twice; NaN times: empty
EXIT_MEMO_SIZE = 6


@njit(cache=True, error_model="numpy")
def new_exit_memo():
    return np.full(EXIT_MEMO_SIZE, np.nan)


@njit(cache=True, error_model="numpy")
def clear_exit_memo(memo):
    """Forget the memo's values (at a corner of phi the next step is on the other side,
    whose kinematics differ at the same tau)."""
    memo[0] = memo[3] = np.nan


@njit(cache=True, error_model="numpy")
def held_exits(code, params, t, side, phys, band, memo):
    """``periodic.switching.exit_functions`` at t, from ``memo`` where it holds t, else evaluated and
    put in it: a held body's steps evaluate them at both ends, and a step's start is the last
    accepted step's end (or a rejected attempt's start), which gave ~9 % of an engine solve's
    time at rtol 1e-4 to repeated evaluations.  The memo must be cleared where ``side``
    crosses a corner of phi (``clear_exit_memo``); it is keyed on tau alone."""
    if memo[0] == t:
        return memo[1], memo[2]
    if memo[3] == t:
        return memo[4], memo[5]
    up, down = exit_functions(code, params, t, side, phys, band)
    memo[0], memo[1], memo[2] = memo[3], memo[4], memo[5]
    memo[3], memo[4], memo[5] = t, up, down
    return up, down


@njit(cache=True, error_model="numpy")
def _locate_state_event(k, code, params, step, bracket, band, options):
    """Zero of state function ``k`` (with the friction's ``band``) along the collocation
    polynomial of ``step`` (a ``SolvedStep``) in its ``Bracket`` of theta (0 <= a < b <= 1),
    by ``periodic.switching.illinois_root`` to ``options.root_share`` (``EventOptions``) of
    the step.  Returns theta."""
    sol = step.sol
    return illinois_root(runtime_int(STATE_ROOT), k, code, params, step.t0 + 0.5 * step.h,
                         (step.t0, step.h, step.u_n, sol.U1, sol.U2, sol.U3, band), bracket,
                         options.root_share, options.root_iterations)


@njit(cache=True, error_model="numpy")
def find_event(code, params, phys, step, atol, first_cut, memo, options):
    """theta in (0, 1] of the earliest event in a solved step (a ``SolvedStep``), or -1 where
    it holds none:

    - a sign change of g or of the outer end's velocity (``_first_crossing``), located on
      the collocation polynomial;
    - for p = 0, a stop: g enters the friction's band (|g| <= ``options.band`` delta_tau)
      from outside and stays in it (no sign change need occur: the body stops and sticks),
      located where |g| reaches the band's edge.  A stage can stick early on a spurious root of the
      stage equations where h kappa mu > |u_n| (the polynomial then stops too early: 2.3
      steps early measured at mu_n/mu_s 3,020), so on a step's first cut (``first_cut``) the
      stop is not put before the line of g from the step's start, whose slope kappa F(u_n)
      + (omega S / 4)' is the slipping body's;
    - for p = 0, an exit: a step that starts in the band, where one of the exit functions
      (``periodic.switching.exit_functions``) turns positive; their values at the step's ends come
      from ``memo`` (``held_exits``) where it has them.

    ``options``: the ``periodic.options.EventOptions``.
    """
    t0, h, u_n, sol, kin, S0, om0, f0 = step
    theta = 2.0
    k, a, b, fa, fb = _first_crossing(step, atol, phys.dtau, options)
    if k >= 0:
        theta = _locate_state_event(k, code, params, step, Bracket(a, b, fa, fb), 0.0, options)
    band = options.band * phys.dtau
    if phys.p == 0.0 and band > 0.0:
        g0 = state_function(runtime_int(TANGENTIAL), u_n, S0, om0, 0.0)
        if abs(g0) > band:
            g1 = state_function(runtime_int(TANGENTIAL), sol.U1, kin.S1, kin.om1, 0.0)
            g2 = state_function(runtime_int(TANGENTIAL), sol.U2, kin.S2, kin.om2, 0.0)
            g3 = state_function(runtime_int(TANGENTIAL), sol.U3, kin.S3, kin.om3, 0.0)
            if abs(g3) <= band:  # the step ends at rest: where did it stop?
                th_a, f_a, th_b, f_b = 0.0, abs(g0) - band, 1.0, abs(g3) - band
                if abs(g2) > band:
                    th_a, f_a = C2, abs(g2) - band
                elif abs(g1) > band:
                    th_a, f_a, th_b, f_b = C1, abs(g1) - band, C2, abs(g2) - band
                else:
                    th_b, f_b = C1, abs(g1) - band
                stop = _locate_state_event(runtime_int(STOP), code, params, step,
                                           Bracket(th_a, th_b, f_a, f_b), band, options)
                if first_cut:
                    phi, om = angle_and_rate(code, params, t0, t0 + 0.5 * h)
                    reach = stop_reach(phys, u_n, f0, band, math.sin(phi), math.cos(phi), om,
                                        rate_slope(code, params, t0, t0 + 0.5 * h))
                    if reach > 0.0:
                        stop = max(stop, min(reach / h, 1.0))
                theta = min(theta, stop)
        else:  # held in the band: does it leave within the step?
            side = t0 + 0.5 * h
            up0, down0 = held_exits(code, params, t0, side, phys, band, memo)
            up1, down1 = held_exits(code, params, t0 + h, side, phys, band, memo)
            data = (phys.kappa, phys.mu_n, phys.mu_s, phys.p, phys.dtau, band, 0.0)
            if up0 <= 0.0 < up1:
                theta = min(theta, (illinois_root(runtime_int(EXIT_ROOT), runtime_int(0), code,
                                                  params, side, data,
                                                  Bracket(t0, t0 + h, up0, up1),
                                                  options.root_share, options.root_iterations)
                                    - t0) / h)
            if down0 <= 0.0 < down1:
                theta = min(theta, (illinois_root(runtime_int(EXIT_ROOT), runtime_int(1), code,
                                                  params, side, data,
                                                  Bracket(t0, t0 + h, down0, down1),
                                                  options.root_share, options.root_iterations)
                                    - t0) / h)
    return theta if theta <= 1.0 else -1.0
