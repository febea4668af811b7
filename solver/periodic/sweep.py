"""One period of the engine: an adaptive sweep and a frozen-grid sweep.

A sweep integrates eq. (Newtonu) over one period from u(0) with the Radau IIA step of
``periodic.radau`` and records every step in a ``Workspace`` row set (one float64 array of shape
(N_FIELDS, capacity + 1), fields by the index constants below), which is what the
shooting, the adjoint weights and the error estimators read.

- ``adaptive_sweep`` chooses the steps (diffrax's loop: the step kernel proposes, the
  controller ``periodic.control.predict_factor`` decides).  The error of a step is its
  embedded estimate weighted by the sensitivities of int u and int Pi of the periodic
  solution to it, lambda and mu (the node weights of the previous sweep, ``WeightModel``),
  per unit length and relative to the norm of U and P: a step is accepted when

      max((|lambda err_u| + |err_int_u|) / scale_U, (|mu err_u| + |err_int_pi|) / scale_P)
          <= target h,

  so the accepted steps' weighted errors sum to at most ``target`` over the period.  Steps
  end at every kinematic stop (``periodic.switching.kinematic_stops``: corners of phi, zeros of
  sin phi, cos phi, omega) and at every state event (``periodic.switching.locate_state_event``),
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

from ..model.force import force_slope_power_sc
from ..model.kinematics import angle_and_rate
from .radau import (C1, C2, StepError, runtime_bool, runtime_int, THETA_LATE, THETA_MID, SampleKinematics, StageKinematics,
                      StepSolution, defect_error, dense_value, embedded_error, estimate_floor, radau5_step, step_integrals,
                      step_weights)
from ..status import CONVERGED, NON_FINITE, STAGE_SOLVE_FAILED, STEP_BUDGET_EXCEEDED, \
    TOLERANCE_NOT_REACHED
from .control import MIN_FACTOR, predict_factor
from .switching import (N_STATE_FUNCTIONS, SIMPLE_TURNING, STOP, TANGENTIAL, Bracket,
                         SolvedStep, exit_functions, locate_exit, locate_state_event, rate_slope,
                         state_function)

# ---------------------------------------------------------------- workspace fields
# (rows of one float64 array, not a NamedTuple of arrays: numba grows, copies and passes the
# sweep's state as one contiguous block, and frozen sweeps rewrite its columns in place)
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
LAMBDA = 28      # node weight of int u (``periodic.global_error.node_weights``)
MU = 29          # node weight of int Pi
END_KIND = 30    # what ends step n: ORDINARY, KINEMATIC_STOP, CORNER_STOP, STATE_EVENT
PU_STAGE = 31    # dPi/du at the stages: rows PU_STAGE .. PU_STAGE + 2
SLOPE = 34       # dF/du at the stages: rows SLOPE .. SLOPE + 2
F_END = 37       # F at the step's end (its last stage)
FLOOR = 38       # the floor of the step's estimate of u's error (``periodic.radau.estimate_floor``)
N_FIELDS = 39

ORDINARY = 0.0
KINEMATIC_STOP = 1.0
CORNER_STOP = 2.0
STATE_EVENT = 3.0

#: the smallest step (in tau, period 1): below it a sweep fails (TOLERANCE_NOT_REACHED)
MIN_STEP = 2.0 ** -40
#: a step this short is accepted whatever its error (which the estimate counts): next to a
#: power law's corner omega ~ z^(gamma - 1), and for gamma near 1 (1.035 measured) the error
#: per unit length does not fall as steps shrink, so no step size meets it: the steps
#: approached the corner geometrically down to MIN_STEP and the sweep failed
ACCEPT_STEP = 2.0 ** -36
#: next to a turning point of phi a step may change u by friction at most this share of u
#: (``trap_ceiling``)
TRAP_SHARE = 0.1
#: ... but at a simple turning point (``periodic.switching.SIMPLE_TURNING``: a simple zero of omega,
#: no corner) never below this step: where the body comes to rest at the turning point with
#: the links (u -> 0 there) the cap shrinks with u and the steps approached the turning point
#: geometrically (45 % of the bench's steps at rtol 1e-4).  An empirical floor, not a bound:
#: measured honest on the harness's sets (also at 1e-2: worst 2.3 rtol) and a reviewer's
#: short- and long-period harmonic sets; at every turning point it was 6.4 rtol off (estimate
#: 0.6) on a sin^3 Fourier motion whose flat inflections are near-tangencies
#: (``test_a_flat_inflection_keeps_the_trap_cap``), which keep the cap
TRAP_FLOOR = 1e-3
#: a step whose defect model does not fit (``periodic.radau.defect_error``) is judged by this many
#: times its error estimate (measured: the fallback estimates were up to 12x too small next
#: to turning points at scaled period 0.01)
FIT_DISTRUST = 16.0
#: a step is stretched to a stop within this factor of it, and split evenly up to twice it
STRETCH = 1.25
#: a state event closer than this share of its step to the step's end is taken to be on it
EVENT_END_SHARE = 1e-6
#: ... and one closer than this share of the previous step to the step's start is not cut:
#: mostly it is the one that step ended at (located on its polynomial, then missed by the
#: re-solved step by a residue; cut there, steps of 1e-7 .. 1e-8 followed, grown back by
#: MAX_FACTOR over 5-7 steps: bench, rtol 1e-4, median n_tau 116 -> 105 with this share
#: instead of 1e-6), but after a kinematic stop it can be another event (a reviewer: 196 of
#: ~17.8k skipped), which then stays inside its step, judged by the error estimate (no
#: solve's error changed against the share 1e-6 on 7 sets x 150 points x 4 rtols)
EVENT_START_SHARE = 1e-3
#: state switching functions within this share of their terms' size have no sign
SIGN_ROUNDING = 64.0 * 2.0 ** -52
#: a switching function's value has a sign beyond this many stage tolerances
EVENT_NOISE = 8.0
#: ... and a sign change is an event where its sides differ by more than this many delta_tau
CROSSING_BAND = 4.0
#: the friction's band: the body is at rest where |g| is within this many delta_tau (stops)
EVENT_BAND = 10.0
#: a sweep gives up after this many attempted steps per accepted one (plus 16)
MAX_ATTEMPTS_PER_STEP = 32
#: a state event within this share of a recorded step's end counts as on it (rounding)
SPLIT_SHARE = 1e-9
#: an event is cut at most this many times in a row (the located root moves as the step
#: shrinks; past this it is accepted where the last cut put it)
MAX_EVENT_CUTS = 4


class Stops(NamedTuple):
    """A point's kinematic step ends, which every sweep keeps (``periodic.switching``):
    ``times`` (count,) sorted in [0, 1), times[0] = 0; ``is_corner`` (count,) whether phi has
    a corner there (the next step's start values are re-evaluated on its side);
    ``is_turning`` (count,) whether the links (nearly) stop rotating there (``trap_ceiling``;
    ``switching.turning_stops``' codes); ``count``."""

    times: np.ndarray
    is_corner: np.ndarray
    is_turning: np.ndarray
    count: int


class Sweep(NamedTuple):
    """What ``adaptive_sweep`` returns: the workspace ``W`` (possibly grown, its first ``N``
    steps the sweep's), ``status`` (CONVERGED when the sweep reached tau = 1), ``h_next``
    (the controller's last proposal) and the ``evaluations`` of F made."""

    W: np.ndarray
    N: int
    status: int
    h_next: float
    evaluations: int


class SweepAim(NamedTuple):
    """What an ``adaptive_sweep`` aims at: accepted steps keep their weighted error
    (``weighted_error``, in the norm ``scale_u``, ``scale_p``, weighted by ``model``, a
    ``WeightModel``) <= ``target`` h; stages solved to ``atol``; at most ``max_steps`` steps;
    ``events``: cut steps at the state events (``_first_crossing``); ``sharp``: judge steps
    by the defect estimate and solve every stage afresh (the target sweep), else by the
    embedded estimate with a carried Newton constant (the loose sweeps).  (Flags in a bundle
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
    """What an adaptive sweep knows from the previous one: node times ``t`` (N + 1,), the
    node weights ``lam`` and ``mu`` there (int u's and int Pi's sensitivity to a jump of u),
    and ``max_step`` (N,), the ceiling the estimators put on the steps inside each of its
    steps (inf: none).  ``N`` = 0: no previous sweep (unit weights, no ceilings)."""

    t: np.ndarray
    lam: np.ndarray
    mu: np.ndarray
    max_step: np.ndarray
    N: int


@njit(cache=True, error_model="numpy")
def new_workspace(capacity):
    return np.empty((N_FIELDS, capacity + 1))


@njit(cache=True, error_model="numpy")
def grown(W, n):
    """``W`` with room for step n (doubled, contents kept), or W itself."""
    if n + 1 < W.shape[1]:
        return W
    bigger = np.empty((N_FIELDS, 2 * W.shape[1]))
    bigger[:, :W.shape[1]] = W
    return bigger


@njit(cache=True, error_model="numpy")
def stage_kinematics(code, params, t0, h):
    """sin phi, cos phi, dphi/dtau at the stages tau_0 + c_i h (inside the step at corners)."""
    side = t0 + 0.5 * h
    phi1, om1 = angle_and_rate(code, params, t0 + C1 * h, side)
    phi2, om2 = angle_and_rate(code, params, t0 + C2 * h, side)
    phi3, om3 = angle_and_rate(code, params, t0 + h, side)
    return StageKinematics(math.sin(phi1), math.sin(phi2), math.sin(phi3),
                           math.cos(phi1), math.cos(phi2), math.cos(phi3), om1, om2, om3)


@njit(cache=True, error_model="numpy")
def sample_kinematics(code, params, t0, h):
    """sin phi, cos phi, dphi/dtau at the defect estimate's samples (``periodic.radau``)."""
    side = t0 + 0.5 * h
    phi_m, om_m = angle_and_rate(code, params, t0 + THETA_MID * h, side)
    phi_l, om_l = angle_and_rate(code, params, t0 + THETA_LATE * h, side)
    return SampleKinematics(math.sin(phi_m), math.cos(phi_m), om_m, math.sin(phi_l),
                            math.cos(phi_l), om_l)


@njit(cache=True, error_model="numpy")
def start_values(code, params, t, side, u, phys):
    """(kappa F, kappa dF/du, Pi, dPi/du) at (t, u) on the side ``side`` of t."""
    phi, om = angle_and_rate(code, params, t, side)
    F, d, P, Pu = force_slope_power_sc(u, math.sin(phi), math.cos(phi), om, phys.mu_n,
                                       phys.mu_s, phys.p, phys.dtau)
    return phys.kappa * F, phys.kappa * d, P, Pu


@njit(cache=True, error_model="numpy")
def solve_step(u_n, U1, U2, U3, h, kin, phys, atol, rate=math.inf, slope=math.nan):
    """``radau5_step`` from the predicted stages (with the carried Newton ``rate`` and
    ``slope``); where its Newton fails, again from u_n, then from rest (a step into a stop
    can defeat a prediction: the former engine measured it at a burst-and-coast corner).  Returns
    (StepSolution, iterations summed)."""
    sol = radau5_step(u_n, U1, U2, U3, h, kin, phys, atol, rate, slope)
    its = sol.iterations
    if not sol.ok:
        sol = radau5_step(u_n, u_n, u_n, u_n, h, kin, phys, atol, math.inf, math.nan)
        its += sol.iterations
    if not sol.ok and u_n != 0.0:
        sol = radau5_step(u_n, 0.0, 0.0, 0.0, h, kin, phys, atol, math.inf, math.nan)
        its += sol.iterations
    return sol, its


@njit(cache=True, error_model="numpy")
def weighted_error(err, lam, mu, scale_u, scale_p, floor=0.0, h=0.0, pi_u=0.0):
    """A step's error in the norm of U and P: its local error in u carried to the period
    integrals by the node weights lam, mu, plus its own quadrature errors (absolute values:
    no cancellation is counted on).  ``floor`` (``periodic.radau.estimate_floor``) is taken off u's
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


# (one explicit signature: called with a constant row each, it had 18 compilations)
@njit("void(float64[:, ::1], int64, int64, float64, float64, float64)", cache=True,
      error_model="numpy")
def _put3(W, row, n, a, b, c):
    """Rows row .. row + 2 of column n: the three stages' values a, b, c."""
    W[row, n] = a
    W[row + 1, n] = b
    W[row + 2, n] = c


@njit(cache=True, error_model="numpy")
def _record(W, n, t0, h, u_n, sol, err, kin, end_kind):
    W[T, n] = t0
    W[T, n + 1] = t0 + h
    W[U, n] = u_n
    W[U, n + 1] = sol.U3
    _put3(W, STAGE, n, sol.U1, sol.U2, sol.U3)
    _put3(W, POWER, n, sol.P1, sol.P2, sol.P3)
    _put3(W, SENS, n, sol.s1, sol.s2, sol.s3)
    _put3(W, PU_STAGE, n, sol.Pu1, sol.Pu2, sol.Pu3)
    _put3(W, SLOPE, n, sol.d1, sol.d2, sol.d3)
    _put3(W, SIN, n, kin.S1, kin.S2, kin.S3)
    _put3(W, COS, n, kin.C1, kin.C2, kin.C3)
    _put3(W, OMEGA, n, kin.om1, kin.om2, kin.om3)
    _put3(W, ERR, n, err.u, err.int_u, err.int_pi)
    W[M_MINUS_1, n] = sol.m_minus_1
    W[Q_U, n], W[Q_P, n] = step_weights(h, sol)
    W[INT_U, n], W[INT_P, n] = step_integrals(h, sol)
    W[END_KIND, n] = end_kind
    W[F_END, n] = sol.F3


@njit(cache=True, error_model="numpy")
def _first_crossing(step, atol, dtau):
    """The earliest sign change of a state switching function across the step, sampled at
    its start, its stages and its end along the solution: (k, theta_a, theta_b, f_a, f_b),
    or k = -1 where there is none.

    A value has a sign only beyond the noise of the stage values (EVENT_NOISE times the
    stage tolerance ``atol``, and rounding: a body at rest at tau = 0 has g = +-1e-17), and a
    sign change is a crossing only where one side lies beyond EVENT_BAND delta_tau: inside
    the friction's band F is smooth (a stuck g whose sign changes with the force it must
    hold is no corner; cut there, a sweep at delta 1e-10 took 1e5 steps of 1e-11).  Not
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
    noise = EVENT_NOISE * atol
    sharp = CROSSING_BAND * dtau
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
        signed = abs(f_prev) > max(noise, SIGN_ROUNDING * (abs(u_n) + abs(om0)))
        for i in range(3):
            if i == 0:
                th, u, om, f = C1, sol.U1, kin.om1, f1
            elif i == 1:
                th, u, om, f = C2, sol.U2, kin.om2, f2
            else:
                th, u, om, f = 1.0, sol.U3, kin.om3, f3
            if abs(f) <= max(noise, SIGN_ROUNDING * (abs(u) + abs(om))):
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
def trap_ceiling(code, params, phys, t_z, side, u):
    """The longest step next to a turning point t_z of phi: TRAP_SHARE |u| / (kappa |F(u, t_z)|).
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
    # steps of ACCEPT_STEP from the sweep)
    return TRAP_SHARE * abs(u) / abs(kF)


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
def trap_limit(code, params, phys, turning, i, stop_is_corner, stop_is_turning, side, u):
    """``trap_ceiling`` at the turning point of stop i, floored at TRAP_FLOOR where it is
    simple (``periodic.switching.SIMPLE_TURNING``: a simple zero of omega, no corner of phi)."""
    cap = trap_ceiling(code, params, phys, turning, side, u)
    if stop_is_turning[i] == SIMPLE_TURNING and not stop_is_corner[i]:
        cap = max(cap, TRAP_FLOOR)
    return cap


@njit(cache=True, error_model="numpy")
def trap_clip(h, cap):
    """The proposed step h clipped to a turning point's trap ceiling ``cap``: at least
    ACCEPT_STEP, but never longer than h.  (Clipped to max(cap, ACCEPT_STEP) instead, a step
    4e-12 short of a power law's corner was taken 1.5e-11 long, across the corner, with its
    stages on the other side's formula; and steps below ACCEPT_STEP were lengthened.)"""
    return min(h, max(cap, ACCEPT_STEP))


#: at the converged solution a step next to a turning point may exceed its ``trap_ceiling``
#: by this factor before the round is rejected (the shooting's last shift moves u a little)
TRAP_SLACK = 2.0
#: ... and its ceiling, which the next sweep keeps over the whole recorded step
#: (``WeightModel.max_step``), splits the step into at most this many: the step next to the
#: turning point gets the cap from that sweep's own ``trap_limit`` (from the converged u(0),
#: where its u is the converged one).  The cap itself as the ceiling split a step of 0.014
#: next to a flat turning point into steps of 4.5e-9 (u there 9e-8, in the friction's band):
#: STEP_BUDGET_EXCEEDED after 4,000
#: (``tests/test_engine.py::test_a_trapped_step_is_split_into_at_most_trap_span_steps``)
TRAP_SPAN = 64.0


@njit(cache=True, error_model="numpy")
def trapped_steps(code, params, phys, point_stops, W, N, ceilings):
    """The ``trap_ceiling`` of ``adaptive_sweep`` checked again on the converged solution of
    ``W``: the sweep judged the steps next to a turning point by its own u, and the frozen
    Newton can move u there into the friction's band, where the ceiling is far smaller.  A
    step ending on such a node with its last stage in the band is damped as if the body
    stuck over the stage's share of the step (kappa dF/du ~ kappa mu / delta_tau): the step's
    value stays accurate, but its du_{n+1}/du_n is not (measured 0.29 .. 0.72 for a step
    into tau = 0 of a sin^3 motion, the period's true monodromy 0.99), so the discrete period
    map gains a fixed point in the band that the node weights (by 1 / (1 - M) of the
    discrete M) do not see as ill-conditioned: estimates of 0.1 .. 0.9 rtol for errors up to
    10 rtol.  Each step over TRAP_SLACK times its ceiling gets it in ``ceilings`` (min with
    what is there), but at least the step over TRAP_SPAN.  Not at a corner of phi (a power
    law's turning point), where a body at rest in the band has a ceiling of ACCEPT_STEP:
    judged there too, the stress power laws' steps doubled (mean n_tau 222 -> 434 at rtol
    1e-3) and 22 solves exceeded the step budget (2 without), where no solve had been off.  Returns (how many, evaluations of F)."""
    stops, stop_is_corner = point_stops.times, point_stops.is_corner
    stop_is_turning, n_stops = point_stops.is_turning, point_stops.count
    count = 0
    evaluations = 0
    j = 0  # the stop at or after W[T, n]
    for n in range(N):
        t = W[T, n]
        h = W[T, n + 1] - t
        while j < n_stops and stops[j] < t:
            j += 1
        starts = j < n_stops and stops[j] == t
        k = j + 1 if starts else j  # the next stop after t (n_stops: tau = 1)
        ends = W[T, n + 1] == (stops[k] if k < n_stops else 1.0)
        turning, i = step_turning(stops, stop_is_turning, n_stops, k if ends else -1,
                                  j if starts else -1)
        if turning < 0.0 or stop_is_corner[i]:
            continue
        cap = max(trap_limit(code, params, phys, turning, i, stop_is_corner, stop_is_turning,
                             t + 0.5 * h, W[U, n]), ACCEPT_STEP)
        evaluations += 1
        if h > TRAP_SLACK * cap:
            ceilings[n] = min(ceilings[n], max(cap, h / TRAP_SPAN))
            count += 1
    return count, evaluations


@njit(cache=True, error_model="numpy")
def _stop_reach(phys, u, f0, band, S, C, om, om_slope):
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
def _stop_reach_at(code, params, phys, t, u, f0, band):
    """``_stop_reach`` from (t, u) with the kinematics on the right of t evaluated afresh
    (at tau = 0 and after a corner of phi)."""
    if phys.p != 0.0 or band <= 0.0:
        return -1.0
    phi, om = angle_and_rate(code, params, t, t + 1e-9)
    return _stop_reach(phys, u, f0, band, math.sin(phi), math.cos(phi), om,
                       rate_slope(code, params, t, t + 1e-9))


#: d/dtheta at theta = 1 of the quadratic through a step's stages (c1, c2, 1): omega's slope
#: at the step's end from its stage values (``_stop_reach`` after an ordinary step)
_D1 = (1.0 - C2) / ((C1 - C2) * (C1 - 1.0))
_D2 = (1.0 - C1) / ((C2 - C1) * (C2 - 1.0))
_D3 = 1.0 / (1.0 - C1) + 1.0 / (1.0 - C2)


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
def find_event(code, params, phys, step, atol, first_cut, memo):
    """theta in (0, 1] of the earliest event in a solved step (a ``SolvedStep``), or -1 where
    it holds none:

    - a sign change of g or of the outer end's velocity (``_first_crossing``), located on
      the collocation polynomial;
    - for p = 0, a stop: g enters the friction's band (|g| <= EVENT_BAND delta_tau) from
      outside and stays in it (no sign change need occur: the body stops and sticks), located
      where |g| reaches the band's edge.  A stage can stick early on a spurious root of the
      stage equations where h kappa mu > |u_n| (the polynomial then stops too early: 2.3
      steps early measured at mu_n/mu_s 3,020), so on a step's first cut (``first_cut``) the
      stop is not put before the line of g from the step's start, whose slope kappa F(u_n)
      + (omega S / 4)' is the slipping body's;
    - for p = 0, an exit: a step that starts in the band, where one of the exit functions
      (``periodic.switching.exit_functions``) turns positive; their values at the step's ends come
      from ``memo`` (``held_exits``) where it has them.
    """
    t0, h, u_n, sol, kin, S0, om0, f0 = step
    theta = 2.0
    k, a, b, fa, fb = _first_crossing(step, atol, phys.dtau)
    if k >= 0:
        theta = locate_state_event(k, code, params, step, Bracket(a, b, fa, fb), 0.0)
    band = EVENT_BAND * phys.dtau
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
                stop = locate_state_event(runtime_int(STOP), code, params, step,
                                          Bracket(th_a, th_b, f_a, f_b), band)
                if first_cut:
                    phi, om = angle_and_rate(code, params, t0, t0 + 0.5 * h)
                    reach = _stop_reach(phys, u_n, f0, band, math.sin(phi), math.cos(phi), om,
                                        rate_slope(code, params, t0, t0 + 0.5 * h))
                    if reach > 0.0:
                        stop = max(stop, min(reach / h, 1.0))
                theta = min(theta, stop)
        else:  # held in the band: does it leave within the step?
            side = t0 + 0.5 * h
            up0, down0 = held_exits(code, params, t0, side, phys, band, memo)
            up1, down1 = held_exits(code, params, t0 + h, side, phys, band, memo)
            if up0 <= 0.0 < up1:
                theta = min(theta, (locate_exit(runtime_int(0), code, params,
                                                Bracket(t0, t0 + h, up0, up1), side, phys,
                                                band) - t0) / h)
            if down0 <= 0.0 < down1:
                theta = min(theta, (locate_exit(runtime_int(1), code, params,
                                                Bracket(t0, t0 + h, down0, down1), side, phys,
                                                band) - t0) / h)
    return theta if theta <= 1.0 else -1.0


@njit(cache=True, error_model="numpy")
def adaptive_sweep(code, params, phys, point_stops, u0, h_first, aim, W):
    """Integrate one period from u(0) = u0 with step-size control; see the module docstring.

    Parameters
    ----------
    code, params : the kinematics' kernel encoding, one row; phys : PointPhysics
    point_stops : Stops
    h_first : float
        The first step's size (the controller's proposal carried from an earlier sweep).
    aim : SweepAim
        What the steps are judged by (target, norm, weight model, stage tolerance, step
        budget, events, sharp).
    W : workspace, grown as needed

    Returns
    -------
    Sweep
    """
    target, scale_u, scale_p, model = aim.target, aim.scale_u, aim.scale_p, aim.model
    atol, max_steps, events, sharp = aim.atol, aim.max_steps, aim.events, aim.sharp
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
    band = EVENT_BAND * phys.dtau
    stop_reach = _stop_reach_at(code, params, phys, t, u, f0, band)
    memo = new_exit_memo()
    # Newton's quadratic constant, carried from step to step (``radau5_step``), in the loose
    # sweeps only (``sharp`` False): it does not bound the stage error (a reviewer measured
    # stages accepted up to 3.7e5 atol off: the constant goes stale over one-correction steps
    # and grows with h kappa), which the loose sweeps tolerate (they give u(0) and the node
    # weights; the target sweep and the frozen Newton solve every stage afresh) but the
    # target sweep does not (its stages become final where the loose u(0) needs no frozen
    # Newton sweep).  Not in ``frozen_sweep`` either (its shooting failed on 1-4 % of the
    # bench with it)
    rate = math.inf
    while t < 1.0:
        if n >= max_steps:
            return Sweep(W, n, STEP_BUDGET_EXCEEDED, h, evaluations)
        t_stop = stops[next_stop] if next_stop < n_stops else 1.0
        lam, mu, ceiling, k_model = _model_at(model, t, k_model)
        h = min(h, _ceiling_over(model, t, h, k_model))
        room = t_stop - t
        end_kind = ORDINARY
        at_stop = False
        reach_clip = False
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
        # a step next to a turning point of phi must not let the friction there stop the body
        turning, j = step_turning(stops, stop_is_turning, n_stops,
                                  next_stop if at_stop else -1,
                                  next_stop - 1 if next_stop >= 1 and t == stops[next_stop - 1]
                                  else -1)
        if turning >= 0.0:
            cap = trap_limit(code, params, phys, turning, j, stop_is_corner, stop_is_turning,
                             t + 0.5 * h, u)
            capped = trap_clip(h, cap)
            if capped < h:
                h = capped
                at_stop = False
                end_kind = ORDINARY
        if 64.0 * MIN_STEP < stop_reach < h and not event_cut:
            # the slipping body reaches the band within the step: end the step there before
            # solving it (the stage Newton across a stop took up to 356 evaluations of the
            # stages, measured at delta 1e-10; ending at the stop, a few)
            h = stop_reach
            reach_clip = True
            at_stop = False
            end_kind = ORDINARY
        attempts += 1
        if not h >= MIN_STEP or attempts > MAX_ATTEMPTS_PER_STEP * (n + 16):
            return Sweep(W, n, TOLERANCE_NOT_REACHED, h, evaluations)
        kin = stage_kinematics(code, params, t, h)
        if have_previous:  # the last step's collocation polynomial, extrapolated
            r = h / prev_h
            g1 = dense_value(1.0 + C1 * r, prev_u, prev_U1, prev_U2, prev_U3)
            g2 = dense_value(1.0 + C2 * r, prev_u, prev_U1, prev_U2, prev_U3)
            g3 = dense_value(1.0 + r, prev_u, prev_U1, prev_U2, prev_U3)
        else:
            g1 = g2 = g3 = u
        sol, its = solve_step(u, g1, g2, g3, h, kin, phys, atol,
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
        if events and cuts < MAX_EVENT_CUTS:
            theta = find_event(code, params, phys, SolvedStep(t, h, u, sol, kin, S0, om0, f0),
                               atol, cuts == 0, memo)
            if theta > 0.0:
                at_start = have_previous and theta * h <= EVENT_START_SHARE * prev_h
                if theta < 1.0 - EVENT_END_SHARE and theta * h >= MIN_STEP and not at_start:
                    h *= theta
                    cuts += 1
                    event_cut = True
                    continue
                if not at_start and not at_stop:
                    end_kind = STATE_EVENT
        if sharp:
            err, fits = defect_error(u, f0, J0, P0, Pu0, sol, h,
                                     sample_kinematics(code, params, t, h), phys)
            evaluations += 2
        else:
            err = embedded_error(u, f0, J0, P0, Pu0, sol, h)
            fits = True
        lam_end, mu_end, _, k_model = _model_at(model, t + h, k_model)
        ratio = weighted_error(err, lam_end, mu_end, scale_u, scale_p,
                               estimate_floor(u, sol, atol), h,
                               max(abs(sol.Pu1), abs(sol.Pu2), abs(sol.Pu3))) / (target * h)
        if not fits:  # the defect's model does not fit: its error is not trusted as it is
            ratio *= FIT_DISTRUST
        if not ratio <= 1.0 and not (h <= ACCEPT_STEP and math.isfinite(ratio)):
            h *= max(MIN_FACTOR, predict_factor(h, h_old, ratio, ratio_old)) \
                if math.isfinite(ratio) else MIN_FACTOR
            cuts = 0
            stretch = False
            continue
        if not at_stop and t_stop - (t + h) <= 4.0 * MIN_STEP:
            at_stop = True  # (a cut to an event that close to the stop leaves no room after it)
            h = t_stop - t
            if next_stop < n_stops and stop_is_corner[next_stop]:
                end_kind = CORNER_STOP
            elif end_kind == ORDINARY:
                end_kind = KINEMATIC_STOP
        W = grown(W, n)
        _record(W, n, t, h, u, sol, err, kin, end_kind)
        cuts = 0
        stretch = True
        # (never below ACCEPT_STEP: a step accepted there whatever its error would shrink on)
        h_next = max(h * predict_factor(h, h_old, ratio, ratio_old), ACCEPT_STEP)
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
            stop_reach = _stop_reach_at(code, params, phys, t, u, f0, band)
        else:
            f0, J0, P0, Pu0 = phys.kappa * sol.F3, phys.kappa * sol.d3, sol.P3, sol.Pu3
            S0, om0 = kin.S3, kin.om3
            # (not right after a step ended at the reach or at a state event: the body is
            # at the band's edge, and a reach of the residue cut steps of 1e-8 that the
            # controller then grew back by MAX_FACTOR over 5-7 steps; the stop is the next
            # step's event, ``find_event``)
            stop_reach = -1.0 if reach_clip or end_kind == STATE_EVENT else _stop_reach(
                phys, u, f0, band, kin.S3, kin.C3, kin.om3,
                (_D1 * kin.om1 + _D2 * kin.om2 + _D3 * kin.om3) / h)
        h = h_next
    W[T, n] = 1.0
    return Sweep(W, n, status, h, evaluations)


@njit(cache=True, error_model="numpy")
def frozen_sweep(code, params, phys, u0, atol, W, N):
    """Solve the N recorded steps of ``W`` again from u(0) = u0, in place (the stages start
    at their previous values moved along their sensitivities; the step kinematics are
    reused).  The error estimates are left as they were (``estimate_sweep`` makes them).

    Returns (status, evaluations of F)."""
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
                              W[STAGE + 2, n] + W[SENS + 2, n] * du, h, kin, phys, atol,
                              math.inf, math.nan)
        iterations += 3 * its
        if not sol.ok:
            return (STAGE_SOLVE_FAILED if math.isfinite(sol.U3) else NON_FINITE), iterations
        zero = StepError(W[ERR, n], W[ERR + 1, n], W[ERR + 2, n])
        _record(W, n, t0, h, u, sol, zero, kin, W[END_KIND, n])
        u = sol.U3
    return CONVERGED, iterations


@njit(cache=True, error_model="numpy")
def estimate_sweep(code, params, phys, corner_nodes, atol, W, N):
    """The defect estimate (``periodic.radau.defect_error``) of every recorded step of ``W``, in
    place (rows ERR), from its stored stages: two evaluations of F per step, and the start
    values where phi has a corner (``corner_nodes``, (N,)) or at tau = 0; and the estimate's
    floor (rows FLOOR) for rounding alone (the stage tolerance ``atol`` is set so that the
    stages' Newton error stays a small share of rtol; subtracting a floor of the tolerance
    here hid true errors of 5 rtol where the node weights reach 4e3).  Returns how many steps fell back to
    the embedded estimate."""
    kappa = phys.kappa
    fallbacks = 0
    evaluations = 2 * N
    f0 = J0 = P0 = Pu0 = 0.0
    for n in range(N):
        t0 = W[T, n]
        h = W[T, n + 1] - t0
        u = W[U, n]
        if n == 0 or corner_nodes[n]:
            f0, J0, P0, Pu0 = start_values(code, params, t0, t0 + 0.5 * h, u, phys)
            evaluations += 1
        step = StepSolution(W[STAGE, n], W[STAGE + 1, n], W[STAGE + 2, n], W[POWER, n],
                            W[POWER + 1, n], W[POWER + 2, n], W[SENS, n], W[SENS + 1, n],
                            W[SENS + 2, n], W[M_MINUS_1, n], W[PU_STAGE, n],
                            W[PU_STAGE + 1, n], W[PU_STAGE + 2, n], W[F_END, n], W[SLOPE, n],
                            W[SLOPE + 1, n], W[SLOPE + 2, n], 0, True, math.nan)
        err, used = defect_error(u, f0, J0, P0, Pu0, step, h,
                                 sample_kinematics(code, params, t0, h), phys)
        fallbacks += not used
        W[ERR, n] = err.u
        W[ERR + 1, n] = err.int_u
        W[ERR + 2, n] = err.int_pi
        W[FLOOR, n] = estimate_floor(u, step, 0.0)
        f0, J0, P0, Pu0 = kappa * step.F3, kappa * step.d3, step.P3, step.Pu3
    return fallbacks, evaluations


@njit(cache=True, error_model="numpy")
def stage_kinematics_into(code, params, W, n):
    kin = stage_kinematics(code, params, W[T, n], W[T, n + 1] - W[T, n])
    _put3(W, SIN, n, kin.S1, kin.S2, kin.S3)
    _put3(W, COS, n, kin.C1, kin.C2, kin.C3)
    _put3(W, OMEGA, n, kin.om1, kin.om2, kin.om3)


@njit(cache=True, error_model="numpy")
def _interior_event(code, params, phys, atol, W, N, n, memo):
    """theta of the first event (``find_event``) strictly inside recorded step n, or -1
    (``memo``: the exit functions' ``held_exits`` memo, steps visited in order)."""
    t0 = W[T, n]
    h = W[T, n + 1] - t0
    if n == 0 or W[END_KIND, n - 1] == CORNER_STOP:  # (the step's side of a corner)
        phi0, om0 = angle_and_rate(code, params, t0, t0 + 0.5 * h)
        S0 = math.sin(phi0)
        clear_exit_memo(memo)
    else:
        S0, om0 = W[SIN + 2, n - 1], W[OMEGA + 2, n - 1]
    sol = StepSolution(W[STAGE, n], W[STAGE + 1, n], W[STAGE + 2, n], 0.0, 0.0, 0.0, 0.0,
                       0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0, True, math.nan)
    kin = StageKinematics(W[SIN, n], W[SIN + 1, n], W[SIN + 2, n], W[COS, n], W[COS + 1, n],
                          W[COS + 2, n], W[OMEGA, n], W[OMEGA + 1, n], W[OMEGA + 2, n])
    theta = find_event(code, params, phys, SolvedStep(t0, h, W[U, n], sol, kin, S0, om0, 0.0),
                       atol, runtime_bool(False), memo)
    return theta if SPLIT_SHARE < theta < 1.0 - SPLIT_SHARE else -1.0


@njit(cache=True, error_model="numpy")
def event_split_errors(code, params, phys, atol, W, N, split):
    """The error of the recorded steps that hold a state event off their ends (the shooting
    moved it after the adaptive sweep had put it on a node): each such step is solved again
    as two steps split at the event, and the change of its end value and integrals replaces
    its estimate where larger (the defect's samples need not see a corner between them).
    ``split`` (N,) is set for those steps.  Returns (their count, evaluations of F)."""
    count = 0
    evaluations = 0
    memo = new_exit_memo()
    for n in range(N):
        split[n] = False
        theta = _interior_event(code, params, phys, atol, W, N, n, memo)
        if theta < 0.0:
            continue
        t0 = W[T, n]
        h = W[T, n + 1] - t0
        u_n = W[U, n]
        U1, U2, U3 = W[STAGE, n], W[STAGE + 1, n], W[STAGE + 2, n]
        h1 = theta * h
        h2 = h - h1
        first, its1 = solve_step(u_n, dense_value(C1 * theta, u_n, U1, U2, U3),
                              dense_value(C2 * theta, u_n, U1, U2, U3),
                              dense_value(theta, u_n, U1, U2, U3), h1,
                              stage_kinematics(code, params, t0, h1), phys, atol, math.inf,
                              math.nan)
        r = 1.0 - theta
        second, its2 = solve_step(first.U3, dense_value(theta + C1 * r, u_n, U1, U2, U3),
                               dense_value(theta + C2 * r, u_n, U1, U2, U3), U3, h2,
                               stage_kinematics(code, params, t0 + h1, h2), phys, atol,
                               math.inf, math.nan)
        evaluations += 3 * (its1 + its2)
        if not (first.ok and second.ok):
            continue
        iu1, ip1 = step_integrals(h1, first)
        iu2, ip2 = step_integrals(h2, second)
        W[ERR, n] = max(abs(W[ERR, n]), abs(second.U3 - U3))
        W[ERR + 1, n] = max(abs(W[ERR + 1, n]), abs(iu1 + iu2 - W[INT_U, n]))
        W[ERR + 2, n] = max(abs(W[ERR + 2, n]), abs(ip1 + ip2 - W[INT_P, n]))
        split[n] = True
        count += 1
    return count, evaluations
