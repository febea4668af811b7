"""One period of the ``radau5`` engine: an adaptive sweep and a frozen-grid sweep.

A sweep integrates eq. (Newtonu) over one period from u(0) with the Radau IIA step of
``_radau5`` and records every step in a ``Workspace`` row set (one float64 array of shape
(N_FIELDS, capacity + 1), fields by the index constants below), which is what the
shooting, the adjoint weights and the error estimators read.

- ``adaptive_sweep`` chooses the steps (diffrax's loop: the step kernel proposes, the
  controller ``_step_control.predict_factor`` decides).  The error of a step is its
  embedded estimate weighted by the sensitivities of int u and int Pi of the periodic
  solution to it, lambda and mu (the node weights of the previous sweep, ``WeightModel``),
  per unit length and relative to the norm of U and P: a step is accepted when

      max((|lambda err_u| + |err_int_u|) / scale_U, (|mu err_u| + |err_int_pi|) / scale_P)
          <= target h,

  so the accepted steps' weighted errors sum to at most ``target`` over the period.  Steps
  end at every kinematic stop (``_switching.kinematic_stops``: corners of phi, zeros of
  sin phi, cos phi, omega) and at every state event (``_switching.locate_state_event``),
  and never exceed the previous estimators' ceilings (``WeightModel.max_step``).
- ``frozen_sweep`` solves the same steps again from another u(0) (the shooting's Newton
  iterations: on a fixed step sequence the period map is smooth and its derivative, the
  monodromy, is exact), starting each stage at the previous sweep's value moved along its
  sensitivity, and records the embedded estimates of the new solution.
"""
from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np
from numba import njit

from ._force import force_slope_power_sc
from ._kinematics import angle_and_rate
from ._radau5 import (C1, C2, StepError, THETA_LATE, THETA_MID, SampleKinematics, StageKinematics,
                      StepSolution, defect_error, dense_value, estimate_floor, radau5_step, step_integrals,
                      step_weights)
from ._status import CONVERGED, NON_FINITE, STAGE_SOLVE_FAILED, STEP_BUDGET_EXCEEDED, \
    TOLERANCE_NOT_REACHED
from ._step_control import MIN_FACTOR, predict_factor
from ._switching import N_STATE_FUNCTIONS, locate_state_event, state_function

# ---------------------------------------------------------------- workspace fields
T = 0            # node times tau_n, n = 0 .. N (tau_N = 1)
U = 1            # u at the nodes
STAGE = 2        # stage values U_1..U_3 of step n: rows STAGE .. STAGE + 2
POWER = 5        # Pi at the stages: rows POWER .. POWER + 2
SENS = 8         # dU_i/du_n: rows SENS .. SENS + 2
M_MINUS_1 = 11   # du_{n+1}/du_n - 1
Q_U = 12         # d(int_step u)/du_n
Q_P = 13         # d(int_step Pi)/du_n
INT_U = 14       # int_step u
INT_P = 15       # int_step Pi
ERR = 16         # embedded estimate (u, int u, int Pi): rows ERR .. ERR + 2
SIN = 19         # sin phi at the stages: rows SIN .. SIN + 2
COS = 22         # cos phi at the stages
OMEGA = 25       # dphi/dtau at the stages
LAMBDA = 28      # node weight of int u (``_global_error.node_weights``)
MU = 29          # node weight of int Pi
END_KIND = 30    # what ends step n: ORDINARY, KINEMATIC_STOP, CORNER_STOP, STATE_EVENT
PU_STAGE = 31    # dPi/du at the stages: rows PU_STAGE .. PU_STAGE + 2
SLOPE = 34       # dF/du at the stages: rows SLOPE .. SLOPE + 2
F_END = 37       # F at the step's end (its last stage)
FLOOR = 38       # the floor of the step's estimate of u's error (``_radau5.estimate_floor``)
N_FIELDS = 39

ORDINARY = 0.0
KINEMATIC_STOP = 1.0
CORNER_STOP = 2.0
STATE_EVENT = 3.0

#: the smallest step (in tau, period 1): below it a sweep fails (TOLERANCE_NOT_REACHED)
MIN_STEP = 2.0 ** -40
#: a step is stretched to a stop within this factor of it, and split evenly up to twice it
STRETCH = 1.25
#: a state event closer than this share of its step to the step's end is taken to be on it
EVENT_END_SHARE = 1e-6
#: state switching functions within this share of their terms' size have no sign
SIGN_ROUNDING = 64.0 * 2.0 ** -52
#: a sweep gives up after this many attempted steps per accepted one (plus 16)
MAX_ATTEMPTS_PER_STEP = 8
DEBUG = False
#: an event is cut at most this many times in a row (the located root moves as the step
#: shrinks; past this it is accepted where the last cut put it)
MAX_EVENT_CUTS = 4


class WeightModel(NamedTuple):
    """What an adaptive sweep knows from the previous one: node times ``t`` (N + 1,), the
    node weights ``lam`` and ``mu`` there (int u's and int Pi's sensitivity to a jump of u),
    and ``max_step`` (N,), the ceiling the estimators put on the steps inside each of its
    steps (inf: none).  ``N`` = 0: no previous sweep (unit weights, no ceilings)."""

    t: np.ndarray
    lam: np.ndarray
    mu: np.ndarray
    max_step: np.ndarray
    N: int


@njit(cache=True)
def new_workspace(capacity):
    return np.empty((N_FIELDS, capacity + 1))


@njit(cache=True)
def grown(W, n):
    """``W`` with room for step n (doubled, contents kept), or W itself."""
    if n + 1 < W.shape[1]:
        return W
    bigger = np.empty((N_FIELDS, 2 * W.shape[1]))
    bigger[:, :W.shape[1]] = W
    return bigger


@njit(cache=True)
def stage_kinematics(code, params, t0, h):
    """sin phi, cos phi, dphi/dtau at the stages tau_0 + c_i h (inside the step at corners)."""
    side = t0 + 0.5 * h
    phi1, om1 = angle_and_rate(code, params, t0 + C1 * h, side)
    phi2, om2 = angle_and_rate(code, params, t0 + C2 * h, side)
    phi3, om3 = angle_and_rate(code, params, t0 + h, side)
    return StageKinematics(math.sin(phi1), math.sin(phi2), math.sin(phi3),
                           math.cos(phi1), math.cos(phi2), math.cos(phi3), om1, om2, om3)


@njit(cache=True)
def sample_kinematics(code, params, t0, h):
    """sin phi, cos phi, dphi/dtau at the defect estimate's samples (``_radau5``)."""
    side = t0 + 0.5 * h
    phi_m, om_m = angle_and_rate(code, params, t0 + THETA_MID * h, side)
    phi_l, om_l = angle_and_rate(code, params, t0 + THETA_LATE * h, side)
    return SampleKinematics(math.sin(phi_m), math.cos(phi_m), om_m, math.sin(phi_l),
                            math.cos(phi_l), om_l)


@njit(cache=True)
def start_values(code, params, t, side, u, phys):
    """(kappa F, kappa dF/du, Pi, dPi/du) at (t, u) on the side ``side`` of t."""
    phi, om = angle_and_rate(code, params, t, side)
    F, d, P, Pu = force_slope_power_sc(u, math.sin(phi), math.cos(phi), om, phys.mu_n,
                                       phys.mu_s, phys.p, phys.dtau)
    return phys.kappa * F, phys.kappa * d, P, Pu


@njit(cache=True)
def solve_step(u_n, U1, U2, U3, h, kin, phys, atol):
    """``radau5_step`` from the predicted stages; where its Newton fails, again from u_n, then
    from rest (a step into a stop can defeat a prediction; see
    ``_periodic._radau_step_retrying``).  Returns (StepSolution, iterations summed)."""
    sol = radau5_step(u_n, U1, U2, U3, h, kin, phys, atol)
    its = sol.iterations
    if not sol.ok:
        sol = radau5_step(u_n, u_n, u_n, u_n, h, kin, phys, atol)
        its += sol.iterations
    if not sol.ok and u_n != 0.0:
        sol = radau5_step(u_n, 0.0, 0.0, 0.0, h, kin, phys, atol)
        its += sol.iterations
    return sol, its


@njit(cache=True)
def weighted_error(err, lam, mu, scale_u, scale_p, floor=0.0, h=0.0):
    """A step's error in the norm of U and P: its local error in u carried to the period
    integrals by the node weights lam, mu, plus its own quadrature errors (absolute values:
    no cancellation is counted on).  ``floor`` (``_radau5.estimate_floor``) is taken off u's
    error and h floor off the quadratures': the step-size control must not chase the stage
    values' own error, which no smaller step reduces."""
    e_u = max(abs(err.u) - floor, 0.0)
    e_v = max(abs(err.int_u) - h * floor, 0.0)
    e_w = max(abs(err.int_pi) - h * floor * abs(err.int_pi) / max(abs(err.int_u), 1e-300),
              0.0)
    return max((abs(lam) * e_u + e_v) / scale_u, (abs(mu) * e_u + e_w) / scale_p)


@njit(cache=True)
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


@njit(cache=True)
def _record(W, n, t0, h, u_n, sol, err, kin, end_kind):
    W[T, n] = t0
    W[T, n + 1] = t0 + h
    W[U, n] = u_n
    W[U, n + 1] = sol.U3
    W[STAGE, n] = sol.U1
    W[STAGE + 1, n] = sol.U2
    W[STAGE + 2, n] = sol.U3
    W[POWER, n] = sol.P1
    W[POWER + 1, n] = sol.P2
    W[POWER + 2, n] = sol.P3
    W[SENS, n] = sol.s1
    W[SENS + 1, n] = sol.s2
    W[SENS + 2, n] = sol.s3
    W[PU_STAGE, n] = sol.Pu1
    W[PU_STAGE + 1, n] = sol.Pu2
    W[PU_STAGE + 2, n] = sol.Pu3
    W[M_MINUS_1, n] = sol.m_minus_1
    q_u, q_p = step_weights(h, sol)
    W[Q_U, n] = q_u
    W[Q_P, n] = q_p
    i_u, i_p = step_integrals(h, sol)
    W[INT_U, n] = i_u
    W[INT_P, n] = i_p
    W[ERR, n] = err.u
    W[ERR + 1, n] = err.int_u
    W[ERR + 2, n] = err.int_pi
    W[SIN, n] = kin.S1
    W[SIN + 1, n] = kin.S2
    W[SIN + 2, n] = kin.S3
    W[COS, n] = kin.C1
    W[COS + 1, n] = kin.C2
    W[COS + 2, n] = kin.C3
    W[OMEGA, n] = kin.om1
    W[OMEGA + 1, n] = kin.om2
    W[OMEGA + 2, n] = kin.om3
    W[END_KIND, n] = end_kind
    W[SLOPE, n] = sol.d1
    W[SLOPE + 1, n] = sol.d2
    W[SLOPE + 2, n] = sol.d3
    W[F_END, n] = sol.F3


@njit(cache=True)
def _first_crossing(code, params, t0, h, u_n, sol, kin, S0, om0, band):
    """The earliest sign change of a state switching function across the step, sampled at
    its start, its stages and its end along the solution: (k, theta_a, theta_b, f_a, f_b),
    or k = -1 where there is none.  Only values beyond ``band`` times their terms' size have
    a sign: rounding (a body at rest at tau = 0 has g = +-1e-17).  Not the friction's band
    of width ~delta_tau: a step that ends just past a corner of F, as a cut to an event
    located on a longer step's polynomial can, has its end inside it (measured: the cut
    steps then kept the corner 3 % of the step inside and were rejected, 1e3 rtol over, down
    to steps of 1e-6)."""
    best_k = -1
    best_a = 2.0
    best_b = 2.0
    best_fa = 0.0
    best_fb = 0.0
    for k in range(N_STATE_FUNCTIONS):
        f_prev = state_function(k, u_n, S0, om0)
        th_prev = 0.0
        signed = abs(f_prev) > band * (abs(u_n) + abs(om0))
        for i in range(3):
            if i == 0:
                th, u, S, om = C1, sol.U1, kin.S1, kin.om1
            elif i == 1:
                th, u, S, om = C2, sol.U2, kin.S2, kin.om2
            else:
                th, u, S, om = 1.0, sol.U3, kin.S3, kin.om3
            f = state_function(k, u, S, om)
            if abs(f) <= band * (abs(u) + abs(om)):
                continue
            if signed and f_prev * f < 0.0:
                if th_prev < best_a:
                    best_k, best_a, best_b, best_fa, best_fb = k, th_prev, th, f_prev, f
                break
            f_prev = f
            th_prev = th
            signed = True
    return best_k, best_a, best_b, best_fa, best_fb


@njit(cache=True)
def adaptive_sweep(code, params, phys, stops, stop_is_corner, n_stops, u0, h_first, target,
                   scale_u, scale_p, model, atol, W, max_steps, events):
    """Integrate one period from u(0) = u0 with step-size control; see the module docstring.

    Parameters
    ----------
    stops : (n_stops,) sorted step ends in [0, 1), stops[0] = 0; stop_is_corner : whether
        phi has a corner there (the next step's start values are re-evaluated on its side).
    h_first : float
        The first step's size (the controller's proposal carried from an earlier sweep).
    target : float
        Accepted steps keep their weighted error (``weighted_error``) <= target h.
    model : WeightModel
    events : bool
        Cut steps at the state events (``_first_crossing``).

    Returns
    -------
    (W, N, status, h_next): the workspace (possibly grown), the number of steps, a status
    code (CONVERGED when the sweep reached tau = 1), the controller's last proposal.
    """
    t = 0.0
    u = u0
    n = 0
    f0, J0, P0, Pu0 = start_values(code, params, 0.0, 0.0 + 1e-300, u, phys)
    phi0, om0 = angle_and_rate(code, params, 0.0, 1e-300)
    S0 = math.sin(phi0)
    h = h_first
    h_old = 0.0
    ratio_old = 0.0
    next_stop = 1
    k_model = 0
    band = SIGN_ROUNDING
    have_previous = False
    prev_h = 0.0
    prev_u = 0.0
    prev_U1 = prev_U2 = prev_U3 = 0.0
    cuts = 0
    status = CONVERGED
    event_cut = False  # h was just cut to a state event: no stretching to a stop
    attempts = 0
    stretch = True  # the proposal may be stretched to a stop (not after a rejection)
    while t < 1.0:
        if n >= max_steps:
            return W, n, STEP_BUDGET_EXCEEDED, h
        t_stop = stops[next_stop] if next_stop < n_stops else 1.0
        lam, mu, ceiling, k_model = _model_at(model, t, k_model)
        h = min(h, ceiling)
        room = t_stop - t
        end_kind = ORDINARY
        at_stop = False
        if event_cut:
            event_cut = False
        elif h >= room / (STRETCH if stretch else 1.0):
            h = room
            at_stop = True
            end_kind = KINEMATIC_STOP
            if next_stop < n_stops and stop_is_corner[next_stop]:
                end_kind = CORNER_STOP
        elif 2.0 * h > room:
            h = 0.5 * room
        attempts += 1
        if not h >= MIN_STEP or attempts > MAX_ATTEMPTS_PER_STEP * (n + 16):
            return W, n, TOLERANCE_NOT_REACHED, h
        kin = stage_kinematics(code, params, t, h)
        if have_previous:  # the last step's collocation polynomial, extrapolated
            r = h / prev_h
            g1 = dense_value(1.0 + C1 * r, prev_u, prev_U1, prev_U2, prev_U3)
            g2 = dense_value(1.0 + C2 * r, prev_u, prev_U1, prev_U2, prev_U3)
            g3 = dense_value(1.0 + r, prev_u, prev_U1, prev_U2, prev_U3)
        else:
            g1 = g2 = g3 = u
        sol, its = solve_step(u, g1, g2, g3, h, kin, phys, atol)
        if not sol.ok:
            h *= 0.5
            cuts = 0
            stretch = False
            continue
        # events first: a step whose stages straddle a corner of F has a large error, and
        # shrinking it by the controller would only approach the corner step by step
        if events and cuts < MAX_EVENT_CUTS:
            k, a, b, fa, fb = _first_crossing(code, params, t, h, u, sol, kin, S0, om0, band)
            if k >= 0:
                theta = locate_state_event(k, code, params, t, h, u, sol.U1, sol.U2, sol.U3,
                                           fa, fb, a, b)
                at_start = have_previous and theta * h <= EVENT_END_SHARE * prev_h
                if DEBUG:
                    print("event", t, h, k, a, b, theta, at_start)
                if theta < 1.0 - EVENT_END_SHARE and theta * h >= MIN_STEP and not at_start:
                    h *= theta
                    cuts += 1
                    event_cut = True
                    continue
                if not at_start and not at_stop:
                    end_kind = STATE_EVENT
        err, _ = defect_error(u, f0, J0, P0, Pu0, sol, h,
                              sample_kinematics(code, params, t, h), phys)
        lam_end, mu_end, _, k_model = _model_at(model, t + h, k_model)
        ratio = weighted_error(err, lam_end, mu_end, scale_u, scale_p,
                               estimate_floor(u, sol, atol), h) / (target * h)
        if DEBUG:
            print("step", t, h, ratio, sol.iterations, end_kind)
        if not ratio <= 1.0:
            h *= max(MIN_FACTOR, predict_factor(h, h_old, ratio, ratio_old)) \
                if math.isfinite(ratio) else MIN_FACTOR
            cuts = 0
            stretch = False
            continue
        W = grown(W, n)
        _record(W, n, t, h, u, sol, err, kin, end_kind)
        cuts = 0
        stretch = True
        h_next = h * predict_factor(h, h_old, ratio, ratio_old)
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
            f0, J0, P0, Pu0 = start_values(code, params, t, t + 1e-9, u, phys)
            phi0, om0 = angle_and_rate(code, params, t, t + 1e-9)
            S0 = math.sin(phi0)
        else:
            f0, J0, P0, Pu0 = phys.kappa * sol.F3, phys.kappa * sol.d3, sol.P3, sol.Pu3
            S0, om0 = kin.S3, kin.om3
        h = h_next
    W[T, n] = 1.0
    return W, n, status, h


@njit(cache=True)
def frozen_sweep(code, params, phys, u0, atol, W, N):
    """Solve the N recorded steps of ``W`` again from u(0) = u0, in place (the stages start
    at their previous values moved along their sensitivities; the step kinematics are
    reused).  The error estimates are left as they were (``estimate_sweep`` makes them).

    Returns (status, stage iterations)."""
    u = u0
    iterations = 0
    for n in range(N):
        t0 = W[T, n]
        h = W[T, n + 1] - t0
        kin = StageKinematics(W[SIN, n], W[SIN + 1, n], W[SIN + 2, n], W[COS, n],
                              W[COS + 1, n], W[COS + 2, n], W[OMEGA, n], W[OMEGA + 1, n],
                              W[OMEGA + 2, n])
        du = u - W[U, n]
        sol, its = solve_step(u, W[STAGE, n] + W[SENS, n] * du,
                              W[STAGE + 1, n] + W[SENS + 1, n] * du,
                              W[STAGE + 2, n] + W[SENS + 2, n] * du, h, kin, phys, atol)
        iterations += its
        if not sol.ok:
            return (STAGE_SOLVE_FAILED if math.isfinite(sol.U3) else NON_FINITE), iterations
        zero = StepError(W[ERR, n], W[ERR + 1, n], W[ERR + 2, n])
        _record(W, n, t0, h, u, sol, zero, kin, W[END_KIND, n])
        u = sol.U3
    return CONVERGED, iterations


@njit(cache=True)
def estimate_sweep(code, params, phys, corner_nodes, atol, W, N):
    """The defect estimate (``_radau5.defect_error``) of every recorded step of ``W``, in
    place (rows ERR), from its stored stages: two evaluations of F per step, and the start
    values where phi has a corner (``corner_nodes``, (N,)) or at tau = 0; and the estimate's
    floor (rows FLOOR) for the stage tolerance ``atol``.  Returns how many steps fell back to
    the embedded estimate."""
    kappa = phys.kappa
    fallbacks = 0
    f0 = J0 = P0 = Pu0 = 0.0
    for n in range(N):
        t0 = W[T, n]
        h = W[T, n + 1] - t0
        u = W[U, n]
        if n == 0 or corner_nodes[n]:
            f0, J0, P0, Pu0 = start_values(code, params, t0, t0 + 0.5 * h, u, phys)
        step = StepSolution(W[STAGE, n], W[STAGE + 1, n], W[STAGE + 2, n], W[POWER, n],
                            W[POWER + 1, n], W[POWER + 2, n], W[SENS, n], W[SENS + 1, n],
                            W[SENS + 2, n], W[M_MINUS_1, n], W[PU_STAGE, n],
                            W[PU_STAGE + 1, n], W[PU_STAGE + 2, n], W[F_END, n], W[SLOPE, n],
                            W[SLOPE + 1, n], W[SLOPE + 2, n], 0, True)
        err, used = defect_error(u, f0, J0, P0, Pu0, step, h,
                                 sample_kinematics(code, params, t0, h), phys)
        fallbacks += not used
        W[ERR, n] = err.u
        W[ERR + 1, n] = err.int_u
        W[ERR + 2, n] = err.int_pi
        W[FLOOR, n] = estimate_floor(u, step, atol)
        f0, J0, P0, Pu0 = kappa * step.F3, kappa * step.d3, step.P3, step.Pu3
    return fallbacks


@njit(cache=True)
def _stage_kinematics_into(code, params, W, n):
    kin = stage_kinematics(code, params, W[T, n], W[T, n + 1] - W[T, n])
    W[SIN, n], W[SIN + 1, n], W[SIN + 2, n] = kin.S1, kin.S2, kin.S3
    W[COS, n], W[COS + 1, n], W[COS + 2, n] = kin.C1, kin.C2, kin.C3
    W[OMEGA, n], W[OMEGA + 1, n], W[OMEGA + 2, n] = kin.om1, kin.om2, kin.om3


@njit(cache=True)
def snap_events(code, params, W, N):
    """Move nodes onto the state events that lie inside the recorded steps of ``W`` (the
    events an adaptive sweep put on nodes move when the shooting then moves u(0)): the event
    in step n is located on its collocation polynomial (``_switching.locate_state_event``)
    and the nearer of the step's two nodes moves onto it, unless that node is a kinematic
    stop (or tau = 0, 1), in which case the other one does, unless it is one too.  The
    moved steps' stage kinematics are recomputed; their stages are left for the next
    ``frozen_sweep`` to correct.  Returns how many nodes moved."""
    moved = 0
    for n in range(N):
        t0 = W[T, n]
        h = W[T, n + 1] - t0
        if n == 0:
            phi0, om0 = angle_and_rate(code, params, t0, t0 + 0.5 * h)
            S0 = math.sin(phi0)
        else:
            S0, om0 = W[SIN + 2, n - 1], W[OMEGA + 2, n - 1]
        sol = StepSolution(W[STAGE, n], W[STAGE + 1, n], W[STAGE + 2, n], 0.0, 0.0, 0.0, 0.0,
                           0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0, True)
        kin = StageKinematics(W[SIN, n], W[SIN + 1, n], W[SIN + 2, n], W[COS, n],
                              W[COS + 1, n], W[COS + 2, n], W[OMEGA, n], W[OMEGA + 1, n],
                              W[OMEGA + 2, n])
        k, a, b, fa, fb = _first_crossing(code, params, t0, h, W[U, n], sol, kin, S0, om0,
                                          SIGN_ROUNDING)
        if k < 0:
            continue
        theta = locate_state_event(k, code, params, t0, h, W[U, n], sol.U1, sol.U2, sol.U3,
                                   fa, fb, a, b)
        if theta <= EVENT_END_SHARE or theta >= 1.0 - EVENT_END_SHARE:
            continue
        right_free = n + 1 < N and W[END_KIND, n] != KINEMATIC_STOP \
            and W[END_KIND, n] != CORNER_STOP
        left_free = n > 0 and W[END_KIND, n - 1] != KINEMATIC_STOP \
            and W[END_KIND, n - 1] != CORNER_STOP
        if right_free and (theta >= 0.5 or not left_free):
            W[T, n + 1] = t0 + theta * h
            W[END_KIND, n] = STATE_EVENT
        elif left_free:
            W[T, n] = t0 + theta * h
            W[END_KIND, n - 1] = STATE_EVENT
            _stage_kinematics_into(code, params, W, n - 1)
        else:
            continue
        _stage_kinematics_into(code, params, W, n)
        if n + 1 < N:
            _stage_kinematics_into(code, params, W, n + 1)
        moved += 1
    return moved
