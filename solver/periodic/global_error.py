"""The global error of the engine's period integrals: one estimate behind one rule.

Every estimator takes a converged periodic solution (the ``periodic.record`` step record) and returns
its errors of int u and int Pi (absolute) and, per step, the share of the tolerance it
finds there; ``combine`` is the one rule that adds them up: the estimators' errors add (they
count different errors: no cancellation is assumed between them), and the estimate is the
larger of U's and P's relative errors in the solver's norm (``solve`` docstring: U relative
to max(|int u|, 1e-3 V), P relative).  A step whose share is above its length times the
tolerance asks for refinement: its ceiling for the next adaptive pass is its length times
share^(-1/ERROR_ORDER) (``refinement_ceiling``).

The node weights are the discrete adjoint of the shooting: for
int u, lambda_n, the change of int u of the periodic solution when u jumps by 1 at node n,
is q_n + m_n lambda_{n+1} with q_n = d(int_step n u)/du_n and m_n = du_{n+1}/du_n, closed
around the period by 1 / (1 - M); for int Pi the same with q_n = d(int_step n Pi)/du_n.
A local error e made in step n is a jump at node n + 1: it changes int u by
lambda_{n+1} e, to first order.

Estimators here:

- ``local_error_estimate``: each step's local error from its defect (``periodic.defect.defect_error``,
  or the split re-solve of ``periodic.estimators.event_split_errors``) weighted by the node weights, plus
  its own quadrature errors.
"""
from __future__ import annotations

import math

from numba import njit

from .estimators import floored_errors
from .radau import ERROR_ORDER
from .record import (error_floor, integral_sensitivity, largest_power_slope, monodromy_minus_1,
                     node_weight, recorded_error, set_node_weight, step_span)


@njit(cache=True, error_model="numpy")
def node_weights(W, N, one_minus_M):
    """lambda (int u) and mu (int Pi) at the N nodes into W[LAMBDA], W[MU] (node N is node
    0), by the backward recursion lambda_n = q_n + m_n lambda_{n+1}, started from lambda_0
    summed over the period and divided by 1 - M."""
    for which in range(2):  # lambda from d(int_step u)/du_n, mu from d(int_step Pi)/du_n
        total = 0.0
        carried = 1.0
        for k in range(N):
            total += integral_sensitivity(W, k, which) * carried
            carried *= 1.0 + monodromy_minus_1(W, k)
        following = total / one_minus_M
        set_node_weight(W, N, which, following)
        for n in range(N - 1, -1, -1):
            following = (integral_sensitivity(W, n, which)
                         + (1.0 + monodromy_minus_1(W, n)) * following)
            set_node_weight(W, n, which, following)


@njit(cache=True, error_model="numpy")
def local_error_estimate(W, N, shares, scale_u, scale_p):
    """The steps' local errors (``periodic.estimators.estimate_pass``) carried to the period integrals:
    returns (error of int u, error of int Pi) and adds each step's weighted error (in the
    norm: the larger of U's and P's relative shares) to ``shares``.  Each step's errors are
    counted above their rounding floor (``periodic.estimators.floored_errors``, rows FLOOR)."""
    e_u = 0.0
    e_p = 0.0
    for n in range(N):
        h = step_span(W, n)[1]
        lam, mu = node_weight(W, n + 1)
        lam = abs(lam)
        mu = abs(mu)
        pi_u = largest_power_slope(W, n)
        eu, ev, ew = floored_errors(recorded_error(W, n), error_floor(W, n), h, pi_u)
        du = lam * eu + ev
        dp = mu * eu + ew
        e_u += du
        e_p += dp
        shares[n] += max(du / scale_u, dp / scale_p)
    return e_u, e_p


@njit(cache=True, error_model="numpy")
def combine(error_u, error_p, scale_u, scale_p):
    """The estimate from the estimators' summed errors of int u and int Pi."""
    return max(error_u / scale_u, error_p / scale_p)


@njit(cache=True, error_model="numpy")
def refinement_ceiling(W, N, shares, target, ceilings, steps):
    """Per step, the largest step the next adaptive pass may take inside it: inf where the
    step's share is within ``target`` times its length, else its length times
    (target h / share)^(1 / ERROR_ORDER) but at least 1 / ``steps.max_refinement``, and at
    least ``steps.accept_step`` (``periodic.options.StepOptions``).  Returns how many steps
    ask for refinement."""
    asked = 0
    for n in range(N):
        h = step_span(W, n)[1]
        ratio = shares[n] / (target * h)
        if ratio > 1.0:
            shrink = ratio ** (-1.0 / ERROR_ORDER) if math.isfinite(ratio) else 0.0
            ceilings[n] = h * max(shrink, 1.0 / steps.max_refinement)
            # (not below ACCEPT_STEP, which the pass takes whatever its error: a step of 1e-13
            # cut to a state event asked for 1.2e-13, below MIN_STEP, and the pass failed)
            ceilings[n] = max(ceilings[n], steps.accept_step)
            asked += 1
        else:
            ceilings[n] = math.inf
    return asked
