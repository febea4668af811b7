"""The monodromy M = prod_n du_{n+1}/du_n of a sweep, accumulated without cancellation.

Copies of ``_periodic.monodromy_factor`` and ``_periodic.one_minus_monodromy`` (which the
order-3 engine's removal takes with it), for the adjoint of ``_gradient``.
"""
from __future__ import annotations

import math

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
