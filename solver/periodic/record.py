"""The step record: what a pass over the period keeps of every step, and the one module
that knows its layout.

A pass records step n in column n of one float64 array ``W`` of shape (N_FIELDS,
capacity + 1) (``new_workspace``, ``grown``), fields by the row constants below; node
fields (T, U, LAMBDA, MU) have a column N for tau = 1.  The shooting, the node weights, the
estimators and the adjoint read it.  It is one array rather than a NamedTuple of arrays
because numba grows, copies and passes the pass's state as one contiguous block, and frozen
passes rewrite its columns in place.
"""
from __future__ import annotations

import math

import numpy as np
from numba import njit

from .radau import StageKinematics, StepError, StepSolution, step_integrals, step_weights
from .steps import stage_kinematics


# ---------------------------------------------------------------- workspace fields
# (rows of one float64 array, not a NamedTuple of arrays: numba grows, copies and passes the
# pass's state as one contiguous block, and frozen passes rewrite its columns in place)
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
FLOOR = 38       # the floor of the step's estimate of u's error (``periodic.defect.estimate_floor``)
N_FIELDS = 39
ORDINARY = 0.0
KINEMATIC_STOP = 1.0
CORNER_STOP = 2.0
STATE_EVENT = 3.0


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


# (one explicit signature: called with a constant row each, it had 18 compilations)
@njit("void(float64[:, ::1], int64, int64, float64, float64, float64)", cache=True,
      error_model="numpy")
def _put3(W, row, n, a, b, c):
    """Rows row .. row + 2 of column n: the three stages' values a, b, c."""
    W[row, n] = a
    W[row + 1, n] = b
    W[row + 2, n] = c


@njit(cache=True, error_model="numpy")
def record_step(W, n, t0, h, u_n, sol, err, kin, end_kind):
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
def stage_kinematics_into(code, params, W, n):
    kin = stage_kinematics(code, params, W[T, n], W[T, n + 1] - W[T, n])
    _put3(W, SIN, n, kin.S1, kin.S2, kin.S3)
    _put3(W, COS, n, kin.C1, kin.C2, kin.C3)
    _put3(W, OMEGA, n, kin.om1, kin.om2, kin.om3)


# ---------------------------------------------------------------- reading and writing a step
# (the only code that indexes the rows: every other module reads and writes the record
# through these; no measurable cost per solve, docs/validation.md "The engine's anatomy")
@njit(cache=True, error_model="numpy")
def node_time(W, n):
    """tau_n."""
    return W[T, n]


@njit(cache=True, error_model="numpy")
def step_span(W, n):
    """(tau_n, h_n) of step n."""
    t0 = W[T, n]
    return t0, W[T, n + 1] - t0


@njit(cache=True, error_model="numpy")
def node_value(W, n):
    """u at node n (n = N: the pass's end value)."""
    return W[U, n]


@njit(cache=True, error_model="numpy")
def end_kind(W, n):
    """What ends step n: ORDINARY, KINEMATIC_STOP, CORNER_STOP or STATE_EVENT."""
    return W[END_KIND, n]


@njit(cache=True, error_model="numpy")
def stage_values(W, n):
    """(U_1, U_2, U_3) of step n."""
    return W[STAGE, n], W[STAGE + 1, n], W[STAGE + 2, n]


@njit(cache=True, error_model="numpy")
def predicted_stages(W, n, u):
    """The stages of step n moved to the start value ``u`` along their sensitivities dU_i/du_n
    (a frozen pass's first guess)."""
    du = u - W[U, n]
    return (W[STAGE, n] + W[SENS, n] * du, W[STAGE + 1, n] + W[SENS + 1, n] * du,
            W[STAGE + 2, n] + W[SENS + 2, n] * du)


@njit(cache=True, error_model="numpy")
def recorded_kinematics(W, n):
    """The ``StageKinematics`` step n was solved with."""
    return StageKinematics(W[SIN, n], W[SIN + 1, n], W[SIN + 2, n], W[COS, n], W[COS + 1, n],
                           W[COS + 2, n], W[OMEGA, n], W[OMEGA + 1, n], W[OMEGA + 2, n])


@njit(cache=True, error_model="numpy")
def end_kinematics(W, n):
    """(sin phi, dphi/dtau) at the end of step n (its last stage)."""
    return W[SIN + 2, n], W[OMEGA + 2, n]


@njit(cache=True, error_model="numpy")
def recorded_solution(W, n):
    """The ``StepSolution`` of step n as recorded (F at the stages other than the last, the
    Newton counts and rate are not kept: 0, True, NaN)."""
    return StepSolution(W[STAGE, n], W[STAGE + 1, n], W[STAGE + 2, n], W[POWER, n],
                        W[POWER + 1, n], W[POWER + 2, n], W[SENS, n], W[SENS + 1, n],
                        W[SENS + 2, n], W[M_MINUS_1, n], W[PU_STAGE, n], W[PU_STAGE + 1, n],
                        W[PU_STAGE + 2, n], W[F_END, n], W[SLOPE, n], W[SLOPE + 1, n],
                        W[SLOPE + 2, n], 0, True, math.nan)


@njit(cache=True, error_model="numpy")
def recorded_stages(W, n):
    """A ``StepSolution`` with step n's stage values only (the rest 0): what the event
    search reads."""
    return StepSolution(W[STAGE, n], W[STAGE + 1, n], W[STAGE + 2, n], 0.0, 0.0, 0.0, 0.0,
                        0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0, True, math.nan)


@njit(cache=True, error_model="numpy")
def recorded_error(W, n):
    """The ``StepError`` estimate of step n."""
    return StepError(W[ERR, n], W[ERR + 1, n], W[ERR + 2, n])


@njit(cache=True, error_model="numpy")
def set_error(W, n, err):
    """Record the ``StepError`` estimate ``err`` of step n."""
    W[ERR, n] = err.u
    W[ERR + 1, n] = err.int_u
    W[ERR + 2, n] = err.int_pi


@njit(cache=True, error_model="numpy")
def error_floor(W, n):
    return W[FLOOR, n]


@njit(cache=True, error_model="numpy")
def set_error_floor(W, n, floor):
    W[FLOOR, n] = floor


@njit(cache=True, error_model="numpy")
def largest_power_slope(W, n):
    """max |dPi/du| over the stages of step n."""
    return max(abs(W[PU_STAGE, n]), abs(W[PU_STAGE + 1, n]), abs(W[PU_STAGE + 2, n]))


@njit(cache=True, error_model="numpy")
def recorded_integrals(W, n):
    """(int u, int Pi) over step n."""
    return W[INT_U, n], W[INT_P, n]


@njit(cache=True, error_model="numpy")
def monodromy_minus_1(W, n):
    """du_{n+1}/du_n - 1 of step n."""
    return W[M_MINUS_1, n]


@njit(cache=True, error_model="numpy")
def integral_sensitivity(W, n, which):
    """d(int_step u)/du_n (``which`` 0) or d(int_step Pi)/du_n (1) of step n."""
    return W[Q_U + which, n]


@njit(cache=True, error_model="numpy")
def node_weight(W, n):
    """(lambda, mu) at node n (``periodic.global_error.node_weights``)."""
    return W[LAMBDA, n], W[MU, n]


@njit(cache=True, error_model="numpy")
def set_node_weight(W, n, which, value):
    """Record lambda (``which`` 0) or mu (1) at node n."""
    W[LAMBDA + which, n] = value


@njit(cache=True, error_model="numpy")
def node_columns(W, N):
    """Copies of the node times, lambda and mu at nodes 0 .. N."""
    return W[T, :N + 1].copy(), W[LAMBDA, :N + 1].copy(), W[MU, :N + 1].copy()


@njit(cache=True, error_model="numpy")
def node_series(W, N):
    """Views of the node times and u at nodes 0 .. N - 1 (the series output)."""
    return W[T, :N], W[U, :N]


@njit(cache=True, error_model="numpy")
def close_period(W, N):
    """Set the last node's time to exactly 1."""
    W[T, N] = 1.0


@njit(cache=True, error_model="numpy")
def shift_step(W, n, shift):
    """Move step n, which starts ``shift`` short of where it should, to first order along
    its sensitivities (u_n, stages, integrals); returns the shift carried to its end."""
    W[U, n] += shift
    for i in range(3):
        W[STAGE + i, n] += W[SENS + i, n] * shift
    W[INT_U, n] += W[Q_U, n] * shift
    W[INT_P, n] += W[Q_P, n] * shift
    return shift * (1.0 + W[M_MINUS_1, n])


@njit(cache=True, error_model="numpy")
def shift_node_value(W, n, shift):
    W[U, n] += shift


@njit(cache=True, error_model="numpy")
def set_step_span(W, n, t0, t1):
    """Step n from t0 to t1 (a given grid's)."""
    W[T, n] = t0
    W[T, n + 1] = t1


@njit(cache=True, error_model="numpy")
def set_step_start(W, n, u, stage, sensitivity):
    """u_n = ``u``, every stage of step n ``stage`` and its dU_i/du_n ``sensitivity`` (the
    first frozen pass's guess on a given grid is stage + sensitivity (u - u_n))."""
    W[U, n] = u
    for i in range(3):
        W[STAGE + i, n] = stage
        W[SENS + i, n] = sensitivity


@njit(cache=True, error_model="numpy")
def set_grid_step(W, n, t0, t1, S, C, om, u, stage, sensitivity):
    """Step n of a given grid before its first frozen pass (``periodic.shooting.frozen_orbit``):
    from t0 to t1, with sin phi ``S``, cos phi ``C`` and dphi/dtau ``om`` at its stages (each
    (3,)), u_n = ``u``, its stages and their sensitivities as ``set_step_start``, no error
    estimate, an ORDINARY end."""
    set_step_span(W, n, t0, t1)
    _put3(W, SIN, n, S[0], S[1], S[2])
    _put3(W, COS, n, C[0], C[1], C[2])
    _put3(W, OMEGA, n, om[0], om[1], om[2])
    set_step_start(W, n, u, stage, sensitivity)
    _put3(W, ERR, n, 0.0, 0.0, 0.0)
    W[END_KIND, n] = ORDINARY


@njit(cache=True, error_model="numpy")
def stage_columns(W, N):
    """View of the stage values of steps 0 .. N - 1, shape (3, N)."""
    return W[STAGE:STAGE + 3, :N]
