"""The error estimators of a recorded pass, and the one rule of a step's error.

``weighted_error`` (with ``floored_errors``) is the norm every step is judged by, in the
step-size control and in the global estimate.  ``estimate_pass`` puts the defect estimate
of every recorded step into its ERR rows; ``event_split_errors`` re-solves the steps that hold
a state event off their ends (moved there by the shooting) split at it.  The global estimate
that carries these local errors to the period integrals is ``periodic.global_error``.
"""
from __future__ import annotations

import math

from numba import njit

from ..model.kinematics import angle_and_rate
from .defect import defect_error, estimate_floor
from .events import clear_exit_memo, find_event, new_exit_memo
from .radau import C1, C2, StepError, dense_value, runtime_bool, step_integrals
from .record import (CORNER_STOP, end_kind, end_kinematics, node_value, recorded_error,
                     recorded_integrals, recorded_kinematics, recorded_solution, recorded_stages,
                     set_error, set_error_floor, stage_values, step_span)
from .steps import sample_kinematics, solve_step, stage_kinematics, start_values
from .switching import SolvedStep


@njit(cache=True, error_model="numpy")
def weighted_error(err, lam, mu, scale_u, scale_p, floor=0.0, h=0.0, pi_u=0.0):
    """A step's error in the norm of U and P: its local error in u carried to the period
    integrals by the node weights lam, mu, plus its own quadrature errors (absolute values:
    no cancellation is counted on).  ``floor`` (``periodic.defect.estimate_floor``) is taken off u's
    error, h floor off int u's and h floor ``pi_u`` (max |dPi/du|) off int Pi's: the stage
    values' own error, which no smaller step reduces.  This is the one rule of a step's
    error, for the step-size control (floor: the stage tolerance's) and the global estimate
    (floor: rounding only, ``periodic.global_error.local_error_estimate``)."""
    e_u, e_v, e_w = floored_errors(err, floor, h, pi_u)
    return max((abs(lam) * e_u + e_v) / scale_u, (abs(mu) * e_u + e_w) / scale_p)


@njit(cache=True, error_model="numpy")
def floored_errors(err, floor, h, pi_u):
    """(|err u|, |err int u|, |err int Pi|) above their floors (``weighted_error``)."""
    return (max(abs(err.u) - floor, 0.0), max(abs(err.int_u) - h * floor, 0.0),
            max(abs(err.int_pi) - h * floor * pi_u, 0.0))


@njit(cache=True, error_model="numpy")
def estimate_pass(code, params, phys, corner_nodes, atol, W, N, options):
    """The defect estimate (``periodic.defect.defect_error``) of every recorded step of ``W``, in
    place (rows ERR), from its stored stages: two evaluations of F per step, and the start
    values where phi has a corner (``corner_nodes``, (N,)) or at tau = 0; and the estimate's
    floor (rows FLOOR) for rounding alone (the stage tolerance ``atol`` is set so that the
    stages' Newton error stays a small share of rtol; subtracting a floor of the tolerance
    here hid true errors of 5 rtol where the node weights reach 4e3).  ``options``: the
    ``DefectOptions``.  Returns how many steps fell back to the embedded estimate."""
    kappa = phys.kappa
    fallbacks = 0
    evaluations = 2 * N
    f0 = J0 = P0 = Pu0 = 0.0
    for n in range(N):
        t0, h = step_span(W, n)
        u = node_value(W, n)
        if n == 0 or corner_nodes[n]:
            f0, J0, P0, Pu0 = start_values(code, params, t0, t0 + 0.5 * h, u, phys)
            evaluations += 1
        step = recorded_solution(W, n)
        err, used = defect_error(u, f0, J0, P0, Pu0, step, h,
                                 sample_kinematics(code, params, t0, h), phys, options)
        fallbacks += not used
        set_error(W, n, err)
        set_error_floor(W, n, estimate_floor(u, step, 0.0, options))
        f0, J0, P0, Pu0 = kappa * step.F3, kappa * step.d3, step.P3, step.Pu3
    return fallbacks, evaluations


@njit(cache=True, error_model="numpy")
def _interior_event(code, params, phys, atol, W, N, n, memo, options):
    """theta of the first event (``find_event``) strictly inside recorded step n (farther
    than ``options.split_share`` from its ends, ``EventOptions``), or -1 (``memo``: the exit
    functions' ``held_exits`` memo, steps visited in order)."""
    t0, h = step_span(W, n)
    if n == 0 or end_kind(W, n - 1) == CORNER_STOP:  # (the step's side of a corner)
        phi0, om0 = angle_and_rate(code, params, t0, t0 + 0.5 * h)
        S0 = math.sin(phi0)
        clear_exit_memo(memo)
    else:
        S0, om0 = end_kinematics(W, n - 1)
    sol = recorded_stages(W, n)
    kin = recorded_kinematics(W, n)
    theta = find_event(code, params, phys, SolvedStep(t0, h, node_value(W, n), sol, kin, S0, om0,
                                                      0.0),
                       atol, runtime_bool(False), memo, options)
    return theta if options.split_share < theta < 1.0 - options.split_share else -1.0


@njit(cache=True, error_model="numpy")
def event_split_errors(code, params, phys, atol, W, N, split, options):
    """The error of the recorded steps that hold a state event off their ends (the shooting
    moved it after the adaptive pass had put it on a node): each such step is solved again
    as two steps split at the event, and the change of its end value and integrals replaces
    its estimate where larger (the defect's samples need not see a corner between them).
    ``split`` (N,) is set for those steps; ``options``: the ``EngineOptions`` (its events'
    and stage solve's).  Returns (their count, evaluations of F)."""
    count = 0
    evaluations = 0
    memo = new_exit_memo()
    for n in range(N):
        split[n] = False
        theta = _interior_event(code, params, phys, atol, W, N, n, memo, options.events)
        if theta < 0.0:
            continue
        t0, h = step_span(W, n)
        u_n = node_value(W, n)
        U1, U2, U3 = stage_values(W, n)
        h1 = theta * h
        h2 = h - h1
        first, its1 = solve_step(u_n, dense_value(C1 * theta, u_n, U1, U2, U3),
                              dense_value(C2 * theta, u_n, U1, U2, U3),
                              dense_value(theta, u_n, U1, U2, U3), h1,
                              stage_kinematics(code, params, t0, h1), phys, atol,
                              options.stage, math.inf, math.nan)
        r = 1.0 - theta
        second, its2 = solve_step(first.U3, dense_value(theta + C1 * r, u_n, U1, U2, U3),
                               dense_value(theta + C2 * r, u_n, U1, U2, U3), U3, h2,
                               stage_kinematics(code, params, t0 + h1, h2), phys, atol,
                               options.stage, math.inf, math.nan)
        evaluations += 3 * (its1 + its2)
        if not (first.ok and second.ok):
            continue
        iu1, ip1 = step_integrals(h1, first)
        iu2, ip2 = step_integrals(h2, second)
        old = recorded_error(W, n)
        int_u, int_p = recorded_integrals(W, n)
        set_error(W, n, StepError(max(abs(old.u), abs(second.U3 - U3)),
                                  max(abs(old.int_u), abs(iu1 + iu2 - int_u)),
                                  max(abs(old.int_pi), abs(ip1 + ip2 - int_p))))
        split[n] = True
        count += 1
    return count, evaluations
