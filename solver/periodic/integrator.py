"""One period of the engine: an adaptive pass and a frozen-grid pass.

A pass integrates eq. (Newtonu) over one period from u(0) with the Radau IIA step of
``periodic.radau`` and records every step in the step record (``periodic.record``), which is what the
shooting, the adjoint weights and the error estimators read.

- ``adaptive_pass`` chooses the steps (diffrax's loop: the step kernel proposes, the
  controller ``periodic.control.predict_factor`` decides).  The error of a step is its
  embedded estimate weighted by the sensitivities of int u and int Pi of the periodic
  solution to it, lambda and mu (the node weights of the previous pass, ``WeightModel``),
  per unit length and relative to the norm of U and P: a step is accepted when

      max((|lambda err_u| + |err_int_u|) / scale_U, (|mu err_u| + |err_int_pi|) / scale_P)
          <= target h,

  so the accepted steps' weighted errors sum to at most ``target`` over the period.  Steps
  end at every kinematic stop (``periodic.switching.kinematic_stops``: corners of phi, zeros of
  sin phi, cos phi, omega) and at every state event (``periodic.events.find_event``),
  and never exceed the previous estimators' ceilings (``WeightModel.max_step``).
- ``frozen_pass`` solves the same steps again from another u(0) (the shooting's Newton
  iterations: on a fixed step sequence the period map is smooth and its derivative, the
  monodromy, is exact), starting each stage at the previous pass's value moved along its
  sensitivity, and records the embedded estimates of the new solution.
"""
from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np
from numba import njit

from ..model.kinematics import angle_and_rate
from ..status import (CONVERGED, NON_FINITE, STAGE_SOLVE_FAILED, STEP_BUDGET_EXCEEDED,
                      TOLERANCE_NOT_REACHED)
from .control import predict_factor
from .defect import defect_error, estimate_floor
from .estimators import weighted_error
from .events import (END_D1, END_D2, END_D3, clear_exit_memo, find_event, new_exit_memo,
                     stop_reach, stop_reach_at)
from .radau import C1, C2, dense_value, embedded_error, runtime_int
from .record import (CORNER_STOP, KINEMATIC_STOP, ORDINARY, STATE_EVENT, close_period, end_kind,
                     grown, predicted_stages, record_step, recorded_error, recorded_kinematics,
                     step_span)
from .steps import sample_kinematics, solve_step, stage_kinematics, start_values
from .switching import SolvedStep
from .traps import step_turning, trap_clip, trap_limit


class Stops(NamedTuple):
    """A point's kinematic step ends, which every pass keeps (``periodic.switching``):
    ``times`` (count,) sorted in [0, 1), times[0] = 0; ``is_corner`` (count,) whether phi has
    a corner there (the next step's start values are re-evaluated on its side);
    ``is_turning`` (count,) whether the links (nearly) stop rotating there (``trap_ceiling``;
    ``switching.turning_stops``' codes); ``count``."""

    times: np.ndarray
    is_corner: np.ndarray
    is_turning: np.ndarray
    count: int


class PeriodPass(NamedTuple):
    """What ``adaptive_pass`` returns: the workspace ``W`` (possibly grown, its first ``N``
    steps the pass's), ``status`` (CONVERGED when the pass reached tau = 1), ``h_next``
    (the controller's last proposal) and the ``evaluations`` of F made."""

    W: np.ndarray
    N: int
    status: int
    h_next: float
    evaluations: int


class PassAim(NamedTuple):
    """What an ``adaptive_pass`` aims at: accepted steps keep their weighted error
    (``weighted_error``, in the norm ``scale_u``, ``scale_p``, weighted by ``model``, a
    ``WeightModel``) <= ``target`` h; stages solved to ``atol``; at most ``max_steps`` steps;
    ``events``: cut steps at the state events (``_first_crossing``); ``sharp``: judge steps
    by the defect estimate and solve every stage afresh (the target pass), else by the
    embedded estimate with a carried Newton constant (the loose passes).  (Flags in a bundle
    are run-time values: no specialisation per constant, ``periodic.radau.runtime_bool``.)"""

    target: float
    scale_u: float
    scale_p: float
    model: "WeightModel"
    atol: float
    max_steps: int
    events: bool
    sharp: bool


class WeightModel(NamedTuple):
    """What an adaptive pass knows from the previous one: node times ``t`` (N + 1,), the
    node weights ``lam`` and ``mu`` there (int u's and int Pi's sensitivity to a jump of u),
    and ``max_step`` (N,), the ceiling the estimators put on the steps inside each of its
    steps (inf: none).  ``N`` = 0: no previous pass (unit weights, no ceilings)."""

    t: np.ndarray
    lam: np.ndarray
    mu: np.ndarray
    max_step: np.ndarray
    N: int


@njit(cache=True, error_model="numpy")
def _ceiling_over(model, t, h, k):
    """The smallest ceiling of the model steps that [t, t + h] overlaps (k: the one holding
    t): a step may not cross a flagged step whole (one across a flagged step of 1e-3 with a
    ceiling of 1e-5 was taken in one piece)."""
    if model.N == 0:
        return math.inf
    ceiling = model.max_step[k]
    j = k + 1
    while j < model.N and model.t[j] < t + min(h, ceiling):
        ceiling = min(ceiling, model.max_step[j])
        j += 1
    return ceiling


@njit(cache=True, error_model="numpy")
def _model_at(model, t, k):
    """(lambda, mu, ceiling) of the weight model at t, with k the index of the model step
    holding t (advanced from the last call's); returns (lam, mu, ceiling, k)."""
    if model.N == 0:
        return 1.0, 0.0, math.inf, 0
    while k > 0 and model.t[k] > t:  # (a rejected trial step had looked further on)
        k -= 1
    while k < model.N - 1 and model.t[k + 1] < t:
        k += 1
    # the larger weight of the model step's two nodes: the weights can change fast across a
    # step (at a stop or a corner), and a step's error is judged by its end's weight
    j = k + 1 if k + 1 < model.N else 0
    lam = max(abs(model.lam[k]), abs(model.lam[j]))
    mu = max(abs(model.mu[k]), abs(model.mu[j]))
    return lam, mu, model.max_step[k], k


@njit(cache=True, error_model="numpy")
def adaptive_pass(code, params, phys, point_stops, u0, h_first, aim, W, options):
    """Integrate one period from u(0) = u0 with step-size control; see the module docstring.

    Parameters
    ----------
    code, params : the kinematics' kernel encoding, one row; phys : PointPhysics
    point_stops : Stops
    h_first : float
        The first step's size (the controller's proposal carried from an earlier pass).
    aim : PassAim
        What the steps are judged by (target, norm, weight model, stage tolerance, step
        budget, events, sharp).
    W : workspace, grown as needed
    options : EngineOptions (``periodic.options``): the controller's (``options.control``)
        the traps' (``options.traps``), the events' (``options.events``), the step
        lengths' (``options.steps``), the stage solve's (``options.stage``) and the defect
        estimate's (``options.defect``)

    Returns
    -------
    Pass
    """
    target, scale_u, scale_p, model = aim.target, aim.scale_u, aim.scale_p, aim.model
    atol, max_steps, events, sharp = aim.atol, aim.max_steps, aim.events, aim.sharp
    control = options.control
    stops, stop_is_corner = point_stops.times, point_stops.is_corner
    stop_is_turning, n_stops = point_stops.is_turning, point_stops.count
    t = 0.0
    u = u0
    n = runtime_int(0)
    f0, J0, P0, Pu0 = start_values(code, params, 0.0, 0.0 + 1e-300, u, phys)
    phi0, om0 = angle_and_rate(code, params, 0.0, 1e-300)
    S0 = math.sin(phi0)
    h = h_first
    h_old = 0.0
    ratio_old = 0.0
    next_stop = 1
    k_model = runtime_int(0)
    have_previous = False
    prev_h = 0.0
    prev_u = 0.0
    prev_U1 = prev_U2 = prev_U3 = 0.0
    cuts = 0
    status = CONVERGED
    event_cut = False  # h was just cut to a state event: no stretching to a stop
    attempts = 0
    stretch = True  # the proposal may be stretched to a stop (not after a rejection)
    evaluations = 1
    event_options = options.events
    step_options = options.steps
    min_step, accept_step = step_options.min_step, step_options.accept_step
    band = event_options.band * phys.dtau
    reach = stop_reach_at(code, params, phys, t, u, f0, band)
    memo = new_exit_memo()
    # Newton's quadratic constant, carried from step to step (``radau5_step``), in the loose
    # passes only (``sharp`` False): it does not bound the stage error (a reviewer measured
    # stages accepted up to 3.7e5 atol off: the constant goes stale over one-correction steps
    # and grows with h kappa), which the loose passes tolerate (they give u(0) and the node
    # weights; the target pass and the frozen Newton solve every stage afresh) but the
    # target pass does not (its stages become final where the loose u(0) needs no frozen
    # Newton pass).  Not in ``frozen_pass`` either (its shooting failed on 1-4 % of the
    # bench with it)
    rate = math.inf
    while t < 1.0:
        if n >= max_steps:
            return PeriodPass(W, n, STEP_BUDGET_EXCEEDED, h, evaluations)
        t_stop = stops[next_stop] if next_stop < n_stops else 1.0
        lam, mu, ceiling, k_model = _model_at(model, t, k_model)
        h = min(h, _ceiling_over(model, t, h, k_model))
        room = t_stop - t
        end_kind = ORDINARY
        at_stop = False
        reach_clip = False
        if event_cut:
            event_cut = False
        elif h >= room / (step_options.stretch if stretch else 1.0):
            h = room
            at_stop = True
            end_kind = KINEMATIC_STOP
            if next_stop < n_stops and stop_is_corner[next_stop]:
                end_kind = CORNER_STOP
        elif 2.0 * h > room:
            h = 0.5 * room
        # a step next to a turning point of phi must not let the friction there stop the body
        turning, j = step_turning(stops, stop_is_turning, n_stops,
                                  next_stop if at_stop else -1,
                                  next_stop - 1 if next_stop >= 1 and t == stops[next_stop - 1]
                                  else -1)
        if turning >= 0.0:
            cap = trap_limit(code, params, phys, turning, j, stop_is_corner, stop_is_turning,
                             t + 0.5 * h, u, options.traps)
            capped = trap_clip(h, cap, accept_step)
            if capped < h:
                h = capped
                at_stop = False
                end_kind = ORDINARY
        if 64.0 * min_step < reach < h and not event_cut:
            # the slipping body reaches the band within the step: end the step there before
            # solving it (the stage Newton across a stop took up to 356 evaluations of the
            # stages, measured at delta 1e-10; ending at the stop, a few)
            h = reach
            reach_clip = True
            at_stop = False
            end_kind = ORDINARY
        attempts += 1
        if not h >= min_step or attempts > step_options.max_attempts_per_step * (n + 16):
            return PeriodPass(W, n, TOLERANCE_NOT_REACHED, h, evaluations)
        kin = stage_kinematics(code, params, t, h)
        if have_previous:  # the last step's collocation polynomial, extrapolated
            r = h / prev_h
            g1 = dense_value(1.0 + C1 * r, prev_u, prev_U1, prev_U2, prev_U3)
            g2 = dense_value(1.0 + C2 * r, prev_u, prev_U1, prev_U2, prev_U3)
            g3 = dense_value(1.0 + r, prev_u, prev_U1, prev_U2, prev_U3)
        else:
            g1 = g2 = g3 = u
        sol, its = solve_step(u, g1, g2, g3, h, kin, phys, atol, options.stage,
                              math.inf if sharp else rate, J0 / phys.kappa)
        if sol.rate == sol.rate:
            rate = sol.rate
        evaluations += 3 * its
        if not sol.ok:
            h *= 0.5
            cuts = 0
            stretch = False
            continue
        # events first: a step whose stages straddle a corner of F has a large error, and
        # shrinking it by the controller would only approach the corner step by step
        if events and cuts < event_options.max_cuts:
            theta = find_event(code, params, phys, SolvedStep(t, h, u, sol, kin, S0, om0, f0),
                               atol, cuts == 0, memo, event_options)
            if theta > 0.0:
                at_start = have_previous and theta * h <= event_options.start_share * prev_h
                if (theta < 1.0 - event_options.end_share and theta * h >= min_step
                        and not at_start):
                    h *= theta
                    cuts += 1
                    event_cut = True
                    continue
                if not at_start and not at_stop:
                    end_kind = STATE_EVENT
        if sharp:
            err, fits = defect_error(u, f0, J0, P0, Pu0, sol, h,
                                     sample_kinematics(code, params, t, h), phys,
                                     options.defect)
            evaluations += 2
        else:
            err = embedded_error(u, f0, J0, P0, Pu0, sol, h)
            fits = True
        lam_end, mu_end, _, k_model = _model_at(model, t + h, k_model)
        ratio = weighted_error(err, lam_end, mu_end, scale_u, scale_p,
                               estimate_floor(u, sol, atol, options.defect), h,
                               max(abs(sol.Pu1), abs(sol.Pu2), abs(sol.Pu3))) / (target * h)
        if not fits:  # the defect's model does not fit: its error is not trusted as it is
            ratio *= step_options.fit_distrust
        if not ratio <= 1.0 and not (h <= accept_step and math.isfinite(ratio)):
            h *= max(control.min_factor, predict_factor(h, h_old, ratio, ratio_old, control)) \
                if math.isfinite(ratio) else control.min_factor
            cuts = 0
            stretch = False
            continue
        if not at_stop and t_stop - (t + h) <= 4.0 * min_step:
            at_stop = True  # (a cut to an event that close to the stop leaves no room after it)
            h = t_stop - t
            if next_stop < n_stops and stop_is_corner[next_stop]:
                end_kind = CORNER_STOP
            elif end_kind == ORDINARY:
                end_kind = KINEMATIC_STOP
        W = grown(W, n)
        record_step(W, n, t, h, u, sol, err, kin, end_kind)
        cuts = 0
        stretch = True
        # (never below ACCEPT_STEP: a step accepted there whatever its error would shrink on)
        h_next = max(h * predict_factor(h, h_old, ratio, ratio_old, control), accept_step)
        h_old = h
        ratio_old = ratio
        t_new = t + h
        if at_stop:
            t_new = t_stop
            next_stop += 1
        have_previous = end_kind != CORNER_STOP
        prev_h, prev_u = h, u
        prev_U1, prev_U2, prev_U3 = sol.U1, sol.U2, sol.U3
        t = t_new
        u = sol.U3
        n += 1
        if end_kind == CORNER_STOP:
            evaluations += 1
            clear_exit_memo(memo)
            f0, J0, P0, Pu0 = start_values(code, params, t, t + 1e-9, u, phys)
            phi0, om0 = angle_and_rate(code, params, t, t + 1e-9)
            S0 = math.sin(phi0)
            reach = stop_reach_at(code, params, phys, t, u, f0, band)
        else:
            f0, J0, P0, Pu0 = phys.kappa * sol.F3, phys.kappa * sol.d3, sol.P3, sol.Pu3
            S0, om0 = kin.S3, kin.om3
            # (not right after a step ended at the reach or at a state event: the body is
            # at the band's edge, and a reach of the residue cut steps of 1e-8 that the
            # controller then grew back by MAX_FACTOR over 5-7 steps; the stop is the next
            # step's event, ``find_event``)
            reach = -1.0 if reach_clip or end_kind == STATE_EVENT else stop_reach(
                phys, u, f0, band, kin.S3, kin.C3, kin.om3,
                (END_D1 * kin.om1 + END_D2 * kin.om2 + END_D3 * kin.om3) / h)
        h = h_next
    close_period(W, n)
    return PeriodPass(W, n, status, h, evaluations)


@njit(cache=True, error_model="numpy")
def frozen_pass(code, params, phys, u0, atol, W, N, stage):
    """Solve the N recorded steps of ``W`` again from u(0) = u0, in place (the stages start
    at their previous values moved along their sensitivities; the step kinematics are
    reused; ``stage``: the ``StageOptions``).  The error estimates are left as they were
    (``estimate_pass`` makes them).

    Returns (status, evaluations of F)."""
    u = u0
    iterations = 0
    for n in range(N):
        t0, h = step_span(W, n)
        kin = recorded_kinematics(W, n)
        g1, g2, g3 = predicted_stages(W, n, u)
        sol, its = solve_step(u, g1, g2, g3, h, kin, phys, atol, stage, math.inf, math.nan)
        iterations += 3 * its
        if not sol.ok:
            return (STAGE_SOLVE_FAILED if math.isfinite(sol.U3) else NON_FINITE), iterations
        record_step(W, n, t0, h, u, sol, recorded_error(W, n), kin, end_kind(W, n))
        u = sol.U3
    return CONVERGED, iterations
