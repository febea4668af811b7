"""Kinematic families: the prescribed half opening angle phi(tau), periodic with period 1.

A family is a frozen dataclass of parameter arrays, one entry per parameter
point.  Every family lowers itself to one of two kernel encodings (methods as
data): a truncated Fourier series (harmonic motions are its K = 1 case) or a
two-phase power law.  The numba functions here evaluate phi and dphi/dtau from
that encoding; the grids of the solvers put nodes at the corners returned by
``corners``.

Clapping convention (section "Optimal motions"): phi may leave [0, pi].  The
force integral only sees sin(phi), cos(phi) and dphi/dtau of the prescribed
function, which is exactly the paper's statement that eqs. (Newton) and
(power) stay valid when the two halves meet at phi = n pi and reverse.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numba import njit, prange

from .._threads import serial_when_single

FOURIER = 0
POWER_LAW = 1


def as_points(name, value):
    """``value`` as a finite 1-D float array over parameter points; errors name the argument."""
    arr = np.atleast_1d(np.asarray(value, dtype=float))
    if arr.ndim != 1:
        raise ValueError(f"{name}: expected a scalar or a 1-D array, got shape {arr.shape}")
    if not np.all(np.isfinite(arr)):
        raise ValueError(f"{name}: must be finite (got NaN or inf)")
    return arr


def _broadcast(**arrays):
    shapes = {k: v.shape[0] for k, v in arrays.items()}
    n = max(shapes.values())
    for k, m in shapes.items():
        if m not in (1, n):
            raise ValueError(f"{k}: length {m} does not match the other parameters' length {n}")
    return {k: np.broadcast_to(v, (n,) + v.shape[1:]).copy() for k, v in arrays.items()}, n


class _Family:
    """Common evaluation methods; subclasses define ``kernel_encoding`` and ``corners``."""

    def angle(self, tau):
        """phi(tau) [rad], shape (n_points, n_tau) for tau of shape (n_tau,)."""
        return self._evaluate(tau)[0]

    def angle_rate(self, tau):
        """dphi/dtau [rad per period], shape (n_points, n_tau); at a corner the left limit."""
        return self._evaluate(tau)[1]

    def _evaluate(self, tau):
        code, params = self.kernel_encoding()
        tau = np.asarray(tau, dtype=float)
        tau_grid = np.broadcast_to(tau, (params.shape[0],) + tau.shape[-1:]).copy()
        with serial_when_single(params.shape[0]):
            return evaluate_grid(code, params, tau_grid, tau_grid)

    def __len__(self):
        return self.kernel_encoding()[1].shape[0]

    def take(self, index):
        """The family restricted to the points ``index`` (an index array or mask)."""
        raise NotImplementedError


@dataclass(frozen=True)
class Harmonic(_Family):
    """phi = A0 + A1 cos(2 pi tau)  (section "Harmonic motions").

    Parameters
    ----------
    A0, A1 : array_like, shape (n_points,)  [rad]
        Mean angle and amplitude, A1 >= 0.
    """

    A0: np.ndarray
    A1: np.ndarray

    def __post_init__(self):
        arrs, _ = _broadcast(A0=as_points("A0", self.A0), A1=as_points("A1", self.A1))
        if np.any(arrs["A1"] < 0):
            raise ValueError("A1: amplitude must be >= 0")
        object.__setattr__(self, "A0", arrs["A0"])
        object.__setattr__(self, "A1", arrs["A1"])

    def kernel_encoding(self):
        n = self.A0.shape[0]
        params = np.zeros((n, 2 + 2 * 1))
        params[:, 0] = 1  # K
        params[:, 1] = self.A0
        params[:, 2] = self.A1
        return FOURIER, params

    def corners(self):
        return np.zeros((self.A0.shape[0], 0))

    def take(self, index):
        return Harmonic(self.A0[index], self.A1[index])


@dataclass(frozen=True)
class Fourier(_Family):
    """phi = A0 + sum_k A_k cos(2 pi k tau) + B_k sin(2 pi k tau)  (eq. Fourier).

    Parameters
    ----------
    A : array_like, shape (n_points, K + 1)  [rad]
        A0 ... AK.
    B : array_like, shape (n_points, K)  [rad]
        B1 ... BK.
    """

    A: np.ndarray
    B: np.ndarray

    def __post_init__(self):
        A = np.atleast_2d(np.asarray(self.A, dtype=float))
        B = np.asarray(self.B, dtype=float)
        B = B.reshape(A.shape[0], -1) if B.ndim < 2 else B
        if A.shape[1] < 1:
            raise ValueError("A: needs at least A0")
        if B.shape != (A.shape[0], A.shape[1] - 1):
            raise ValueError(f"B: expected {A.shape[1] - 1} sine coefficients per point "
                             f"(one fewer than A), got shape {B.shape}")
        if not (np.all(np.isfinite(A)) and np.all(np.isfinite(B))):
            raise ValueError("A, B: must be finite (got NaN or inf)")
        object.__setattr__(self, "A", A)
        object.__setattr__(self, "B", B)

    @property
    def max_wavenumber(self):
        return self.A.shape[1] - 1

    def kernel_encoding(self):
        n, K1 = self.A.shape
        K = K1 - 1
        params = np.zeros((n, 2 + 2 * max(K, 1)))
        params[:, 0] = K
        params[:, 1:K + 2] = self.A
        params[:, K + 2:2 * K + 2] = self.B
        return FOURIER, params

    def corners(self):
        return np.zeros((self.A.shape[0], 0))

    def take(self, index):
        return Fourier(self.A[index], self.B[index])


@dataclass(frozen=True)
class PowerLaw(_Family):
    """Two-phase power-law motion (eqs. rapidendc, rapidbegc, rapidbego, rapidendo).

    Closing on 0 <= tau <= tau0 from A0 + A1 to A0 - A1, opening on
    tau0 <= tau <= 1 back to A0 + A1.

    Parameters
    ----------
    A0, A1 : array_like, shape (n_points,)  [rad]
        Mean angle and half the angle range, A1 >= 0.
    duty_cycle : array_like, shape (n_points,)
        tau0 in (0, 1), the closing phase's share of the period.
    closing_exponent, opening_exponent : array_like, shape (n_points,)
        gamma_c, gamma_o >= 1 (1 is linear).
    closing_concave_up, opening_concave_up : array_like of bool, shape (n_points,)
        False: concave down (gamma_{c,d}, eq. rapidendc; gamma_{o,d}, eq. rapidbego);
        True: concave up (gamma_{c,u}, eq. rapidbegc; gamma_{o,u}, eq. rapidendo).
    """

    A0: np.ndarray
    A1: np.ndarray
    duty_cycle: np.ndarray
    closing_exponent: np.ndarray
    closing_concave_up: np.ndarray
    opening_exponent: np.ndarray
    opening_concave_up: np.ndarray

    def __post_init__(self):
        names = ("A0", "A1", "duty_cycle", "closing_exponent", "closing_concave_up",
                 "opening_exponent", "opening_concave_up")
        arrs, _ = _broadcast(**{k: as_points(k, getattr(self, k)) for k in names})
        if np.any(arrs["A1"] < 0):
            raise ValueError("A1: amplitude must be >= 0")
        if np.any((arrs["duty_cycle"] <= 0) | (arrs["duty_cycle"] >= 1)):
            raise ValueError("duty_cycle: tau0 must lie in (0, 1)")
        for k in ("closing_exponent", "opening_exponent"):
            if np.any(arrs[k] < 1):
                raise ValueError(f"{k}: power-law exponent must be >= 1")
        for k in names:
            value = arrs[k].astype(bool) if k.endswith("concave_up") else arrs[k]
            object.__setattr__(self, k, value)

    def kernel_encoding(self):
        params = np.stack([self.A0, self.A1, self.duty_cycle, self.closing_exponent,
                           self.closing_concave_up.astype(float), self.opening_exponent,
                           self.opening_concave_up.astype(float)], axis=1)
        return POWER_LAW, params

    def corners(self):
        return np.stack([np.zeros_like(self.duty_cycle), self.duty_cycle], axis=1)

    def take(self, index):
        return PowerLaw(*(getattr(self, k)[index] for k in (
            "A0", "A1", "duty_cycle", "closing_exponent", "closing_concave_up",
            "opening_exponent", "opening_concave_up")))


@njit(cache=True, error_model="numpy")
def _fourier(params, tau):
    K = int(params[0])
    phi = params[1]
    rate = 0.0
    c1 = math.cos(2.0 * math.pi * tau)
    s1 = math.sin(2.0 * math.pi * tau)
    ca, sa = 1.0, 0.0
    for k in range(1, K + 1):  # cos, sin of 2 pi k tau by angle addition (error ~k eps)
        ca, sa = ca * c1 - sa * s1, sa * c1 + ca * s1
        Ak = params[1 + k]
        Bk = params[K + 1 + k]
        phi += Ak * ca + Bk * sa
        rate += 2.0 * math.pi * k * (Bk * ca - Ak * sa)
    return phi, rate


@njit(cache=True, error_model="numpy")
def _fourier_rate_slope(params, tau):
    """d^2 phi / d tau^2 of eq. (Fourier): -(2 pi)^2 sum_k k^2 (A_k cos + B_k sin)(2 pi k tau)."""
    K = int(params[0])
    c1 = math.cos(2.0 * math.pi * tau)
    s1 = math.sin(2.0 * math.pi * tau)
    ca, sa = 1.0, 0.0
    slope = 0.0
    for k in range(1, K + 1):
        ca, sa = ca * c1 - sa * s1, sa * c1 + ca * s1
        slope -= (2.0 * math.pi * k) ** 2 * (params[1 + k] * ca + params[K + 1 + k] * sa)
    return slope


@njit(cache=True, error_model="numpy")
def _power_law(params, tau, tau_phase):
    """phi and dphi/dtau; ``tau_phase`` (a point inside the step) picks the phase at corners."""
    A0, A1, tau0, gc, cup, go, oup = params[0], params[1], params[2], params[3], params[4], params[5], params[6]
    t = tau - math.floor(tau_phase)
    tp = tau_phase - math.floor(tau_phase)
    if tp <= tau0:
        x = min(max(t / tau0, 0.0), 1.0)
        if cup > 0.5:  # eq. rapidbegc
            y = 1.0 - x
            return A0 + A1 - 2.0 * A1 * (1.0 - y ** gc), -2.0 * A1 * gc * y ** (gc - 1.0) / tau0
        return A0 + A1 - 2.0 * A1 * x ** gc, -2.0 * A1 * gc * x ** (gc - 1.0) / tau0  # eq. rapidendc
    x = min(max((t - tau0) / (1.0 - tau0), 0.0), 1.0)
    if oup > 0.5:  # eq. rapidendo
        return A0 - A1 + 2.0 * A1 * x ** go, 2.0 * A1 * go * x ** (go - 1.0) / (1.0 - tau0)
    y = 1.0 - x  # eq. rapidbego
    return A0 - A1 + 2.0 * A1 * (1.0 - y ** go), 2.0 * A1 * go * y ** (go - 1.0) / (1.0 - tau0)


@njit(cache=True, error_model="numpy")
def angle_and_rate(code, params, tau, tau_phase):
    """phi(tau), dphi/dtau(tau) for one point; ``tau_phase`` selects the side of a corner."""
    if code == FOURIER:
        return _fourier(params, tau)
    return _power_law(params, tau, tau_phase)


#: the step of the central difference of omega that gives a power law's d omega / d tau
RATE_SLOPE_STEP = 1e-7


@njit(cache=True, error_model="numpy")
def rate_slope(code, params, tau, tau_phase):
    """d omega / d tau (phi'') at tau on the side ``tau_phase``: analytic for Fourier motions
    (and harmonic ones); for a power law a central difference of the analytic omega, which
    stays finite at a corner where omega ~ z^(gamma - 1) has an infinite slope (the analytic
    one is +-inf there, or 0 * inf at gamma = 1)."""
    if code == FOURIER:
        return _fourier_rate_slope(params, tau)
    e = RATE_SLOPE_STEP
    return (_power_law(params, tau + e, tau_phase)[1]
            - _power_law(params, tau - e, tau_phase)[1]) / (2.0 * e)


@njit(cache=True, parallel=True, error_model="numpy")
def evaluate_grid(code, params, tau, tau_phase):
    n, m = tau.shape
    phi = np.empty((n, m))
    rate = np.empty((n, m))
    for i in prange(n):
        for j in range(m):
            phi[i, j], rate[i, j] = angle_and_rate(code, params[i], tau[i, j], tau_phase[i, j])
    return phi, rate


def period_grid(kinematics, n_steps):
    """Step boundaries tau_0 = 0 < ... < tau_N = 1 with nodes at every corner.

    Each phase between corners gets a share of ``n_steps`` proportional to its
    length (at least 2 steps), uniform inside; doubling ``n_steps`` nests the grids
    when it doubles every share, which ``phase_steps`` guarantees.

    Returns
    -------
    ndarray, shape (n_points, N + 1)
    """
    corners = kinematics.corners()
    n = corners.shape[0]
    if corners.shape[1] == 0:
        return np.broadcast_to(np.linspace(0.0, 1.0, n_steps + 1), (n, n_steps + 1)).copy()
    # two phases: [0, tau0] and [tau0, 1]
    tau0 = corners[:, 1]
    n_close = phase_steps(tau0, n_steps)
    n_open = n_steps - n_close
    frac = np.arange(n_steps + 1)[None, :]
    closing = frac / n_close[:, None] * tau0[:, None]
    opening = tau0[:, None] + (frac - n_close[:, None]) / n_open[:, None] * (1.0 - tau0[:, None])
    return np.where(frac <= n_close[:, None], closing, opening)


def phase_steps(tau0, n_steps):
    """Steps in the closing phase: proportional to tau0, >= 2 and <= n_steps - 2, and exactly
    doubling with n_steps (computed at the base level 8 and scaled) so grids nest."""
    base = 8
    scale = max(n_steps // base, 1)
    if n_steps % base:
        raise ValueError("n_steps must be a multiple of 8")
    n_base = np.clip(np.rint(tau0 * base).astype(int), 2, base - 2)
    return n_base * scale
