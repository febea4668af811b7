"""Turning-point traps: next to a turning point of phi a long implicit step can stop the body
where the solution passes with u != 0.

``trap_ceiling`` / ``trap_limit`` / ``trap_clip`` cap a proposed step next to a turning
stop (``step_turning`` finds it); ``trapped_steps`` checks the converged solution's steps
again and returns ceilings for the next round.
"""
from __future__ import annotations

import math

from numba import njit

from .record import node_time, node_value, step_span
from .steps import start_values
from .switching import SIMPLE_TURNING


@njit(cache=True, error_model="numpy")
def trap_ceiling(code, params, phys, t_z, side, u, traps):
    """The longest step next to a turning point t_z of phi: ``traps.share`` |u| /
    (kappa |F(u, t_z)|) (``periodic.options.TrapOptions``, default TRAP_SHARE).
    Where the links stop rotating the whole body slides one way and feels the full friction;
    a longer step's implicit stage at t_z can stop the body there although the solution
    passes with u != 0 (the trap of ``_turning``: measured at scaled period 0.023, steps of
    0.18 next to tau = 0.5 returned U = 1.7e-4 for -3.6e-5, 6 rtol off at rtol 1e-3, the
    defect estimate blind to it)."""
    kF = start_values(code, params, t_z, side, u, phys)[0]
    if kF == 0.0:
        return math.inf
    # (|u| itself, not the friction's band when smaller: at scaled period 0.0085 a body at
    # |u| ~ 1e-6 ~ the band was trapped, 3.3 rtol off; a body at rest, u ~ 1e-18, gets
    # steps of ACCEPT_STEP from the pass)
    return traps.share * abs(u) / abs(kF)


@njit(cache=True, error_model="numpy")
def step_turning(stops, stop_is_turning, n_stops, j_end, j_start):
    """The turning point of phi a step is next to, (tau, its stop's index) or (-1, -1): the
    stop the step ends on (index ``j_end``; n_stops is tau = 1, stop 0 of the next period),
    else the one it starts from (``j_start``); -1: the step does not end / start on a stop."""
    if j_end >= 0:
        i = j_end if j_end < n_stops else 0
        if stop_is_turning[i]:
            return (stops[j_end] if j_end < n_stops else 1.0), i
    if j_start >= 0 and stop_is_turning[j_start]:
        return stops[j_start], j_start
    return -1.0, -1


@njit(cache=True, error_model="numpy")
def trap_limit(code, params, phys, turning, i, stop_is_corner, stop_is_turning, side, u,
               traps):
    """``trap_ceiling`` at the turning point of stop i, floored at ``traps.floor`` (TRAP_FLOOR)
    where it is simple (``periodic.switching.SIMPLE_TURNING``: a simple zero of omega, no
    corner of phi)."""
    cap = trap_ceiling(code, params, phys, turning, side, u, traps)
    if stop_is_turning[i] == SIMPLE_TURNING and not stop_is_corner[i]:
        cap = max(cap, traps.floor)
    return cap


@njit(cache=True, error_model="numpy")
def trap_clip(h, cap, accept_step):
    """The proposed step h clipped to a turning point's trap ceiling ``cap``: at least
    ``accept_step`` (``StepOptions``, ACCEPT_STEP), but never longer than h.  (Clipped to
    max(cap, ACCEPT_STEP) instead, a step 4e-12 short of a power law's corner was taken
    1.5e-11 long, across the corner, with its stages on the other side's formula; and steps
    below ACCEPT_STEP were lengthened.)"""
    return min(h, max(cap, accept_step))


@njit(cache=True, error_model="numpy")
def trapped_steps(code, params, phys, point_stops, W, N, ceilings, traps, accept_step):
    """The ``trap_ceiling`` of ``adaptive_pass`` checked again on the converged solution of
    ``W``: the pass judged the steps next to a turning point by its own u, and the frozen
    Newton can move u there into the friction's band, where the ceiling is far smaller.  A
    step ending on such a node with its last stage in the band is damped as if the body
    stuck over the stage's share of the step (kappa dF/du ~ kappa mu / delta_tau): the step's
    value stays accurate, but its du_{n+1}/du_n is not (measured 0.29 .. 0.72 for a step
    into tau = 0 of a sin^3 motion, the period's true monodromy 0.99), so the discrete period
    map gains a fixed point in the band that the node weights (by 1 / (1 - M) of the
    discrete M) do not see as ill-conditioned: estimates of 0.1 .. 0.9 rtol for errors up to
    10 rtol.  Each step over ``traps.slack`` (TRAP_SLACK) times its ceiling gets it in
    ``ceilings`` (min with what is there), but at least the step over ``traps.span``
    (TRAP_SPAN).  Not at a corner of phi (a power law's turning point), where a body at rest
    in the band has a ceiling of ACCEPT_STEP: judged there too, the stress power laws' steps
    doubled (mean n_tau 222 -> 434 at rtol 1e-3) and 22 solves exceeded the step budget (2
    without), where no solve had been off.  Returns (how many, evaluations of F)."""
    stops, stop_is_corner = point_stops.times, point_stops.is_corner
    stop_is_turning, n_stops = point_stops.is_turning, point_stops.count
    count = 0
    evaluations = 0
    j = 0  # the stop at or after W[T, n]
    for n in range(N):
        t, h = step_span(W, n)
        while j < n_stops and stops[j] < t:
            j += 1
        starts = j < n_stops and stops[j] == t
        k = j + 1 if starts else j  # the next stop after t (n_stops: tau = 1)
        ends = node_time(W, n + 1) == (stops[k] if k < n_stops else 1.0)
        turning, i = step_turning(stops, stop_is_turning, n_stops, k if ends else -1,
                                  j if starts else -1)
        if turning < 0.0 or stop_is_corner[i]:
            continue
        cap = max(trap_limit(code, params, phys, turning, i, stop_is_corner, stop_is_turning,
                             t + 0.5 * h, node_value(W, n), traps), accept_step)
        evaluations += 1
        if h > traps.slack * cap:
            ceilings[n] = min(ceilings[n], max(cap, h / traps.span))
            count += 1
    return count, evaluations
