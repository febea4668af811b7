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


import numpy as np
from numba import njit

from .radau import step_integrals, step_weights
from .steps import stage_kinematics


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
