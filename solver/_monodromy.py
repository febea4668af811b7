"""Small shared kernels of the period map: the monodromy M = prod m_n of a period (its
log and sign, without cancellation at M ~ 1), the node weights of int u (the discrete
adjoint of the shooting) and the output arrays of a batched solve.

Shared by the engine's shooting (``_radau5_solve``), its adjoint (``_gradient``) and the
explicit march (``_march``), which thus do not depend on each other.
"""
from __future__ import annotations

import math

import numpy as np
from numba import njit


@njit(cache=True, error_model="numpy")
def monodromy_factor(log_m, sign_m, m_minus_1):
    """(log |M|, sign M) of the monodromy M = prod m_n with one more step factor m_n, given
    as m_n - 1 (formed without cancellation; log1p keeps it near m_n = 1)."""
    if m_minus_1 <= -1.0:  # a step that reverses perturbations: track the sign of M
        return log_m + (math.log(-1.0 - m_minus_1) if m_minus_1 < -1.0 else -math.inf), -sign_m
    return log_m + math.log1p(m_minus_1), sign_m


@njit(cache=True, error_model="numpy")
def one_minus_monodromy(log_m, sign_m):
    """1 - M from ``monodromy_factor``'s (log |M|, sign M), without cancellation at M ~ 1."""
    return -math.expm1(log_m) if sign_m > 0.0 else 1.0 + math.exp(log_m)


@njit(cache=True, error_model="numpy")
def node_weights(weights, step_m, one_minus_M):
    """The sensitivity lambda_n of int_0^1 u dtau of the discrete periodic solution to a
    jump of u at node n (the discrete adjoint of the shooting, for the error functional int u).

    A jump d at node n is carried on as m_n d, m_{n+1} m_n d, ... and, the solution being
    periodic, returns as M d after one period, so it adds d / (1 - M) in total there:
    lambda_n = sum_k q_{n+k} m_n ... m_{n+k-1} / (1 - M) over one period, q_k the derivative
    of step k's integral of u by u_k.  Backwards: lambda_n = q_n + m_n lambda_{n+1}, started
    from lambda_0 summed directly.  ``weights`` holds q on entry and lambda on return.
    """
    N = weights.size
    total = 0.0
    carried = 1.0
    for k in range(N):
        total += weights[k] * carried
        carried *= step_m[k]
    following = total / one_minus_M
    for n in range(N - 1, -1, -1):
        following = weights[n] + step_m[n] * following
        weights[n] = following


@njit(cache=True, error_model="numpy")
def batch_outputs(n, m):
    """Output arrays of a batched solve of n rows of grids with up to m - 1 steps:
    (int_u, int_pi, u0, status, iterations, stage_iterations, step_u, step_pi, step_m, nodes)."""
    return (np.empty(n), np.empty(n), np.empty(n), np.empty(n, np.int8), np.empty(n, np.int64),
            np.empty(n, np.int64), np.full((n, m - 1), np.nan), np.full((n, m - 1), np.nan),
            np.full((n, m - 1), np.nan), np.full((n, m - 1), np.nan))
