"""Physical parameters and the scalings of the paper (sections "Model" and "Other power laws")."""
from __future__ import annotations

from dataclasses import dataclass
from typing import NamedTuple

import numpy as np

from .kinematics import as_points


@dataclass(frozen=True)
class Physics:
    """Period, resistance coefficients and force law, one entry per parameter point.

    Parameters
    ----------
    period : array_like, shape (n_points,)
        T > 0, in units of sqrt(L/g).
    mu_n, mu_s : array_like, shape (n_points,)
        Normal and tangential coefficients, > 0 (eq. frictiondelta / frictionp).
    p : array_like, shape (n_points,)
        Resistive force exponent, 0 <= p < 2 (eq. vp); p = 0 is Coulomb friction.
    delta : array_like, shape (n_points,)
        Regularisation delta >= 0 (eq. delta); must be > 0 when p = 0.
    """

    period: np.ndarray
    mu_n: np.ndarray
    mu_s: np.ndarray
    p: np.ndarray = 0.0
    delta: np.ndarray = 1e-5

    def __post_init__(self):
        arrs = {k: as_points(k, getattr(self, k)) for k in ("period", "mu_n", "mu_s", "p", "delta")}
        n = max(a.shape[0] for a in arrs.values())
        for k, a in arrs.items():
            if a.shape[0] not in (1, n):
                raise ValueError(f"{k}: length {a.shape[0]} does not match length {n}")
            arrs[k] = np.broadcast_to(a, (n,)).copy()
        if np.any(arrs["period"] <= 0):
            raise ValueError("period: T must be > 0")
        for k in ("mu_n", "mu_s"):
            if np.any(arrs[k] <= 0):
                raise ValueError(f"{k}: friction coefficient must be > 0")
        if np.any((arrs["p"] < 0) | (arrs["p"] >= 2)):
            raise ValueError("p: force-law exponent must lie in [0, 2)")
        if np.any(arrs["delta"] < 0):
            raise ValueError("delta: regularisation must be >= 0")
        if np.any((arrs["delta"] == 0) & (arrs["p"] == 0)):
            raise ValueError("delta: must be > 0 when p = 0 (unregularised Coulomb friction)")
        for k, a in arrs.items():
            object.__setattr__(self, k, a)

    def __len__(self):
        return self.period.shape[0]

    @classmethod
    def from_scaled(cls, anisotropy_ratio, scaled_period, p=0.0, delta=1e-5, friction_scale=1.0):
        """Physics with mu_n / mu_s = ``anisotropy_ratio`` and (mu_n mu_s)^(1/(4-2p)) T = ``scaled_period``.

        ``friction_scale`` is sqrt(mu_n mu_s); scaled outputs do not depend on it.
        """
        T, mu_n, mu_s = physical_from_scaled(anisotropy_ratio, scaled_period, p, friction_scale)
        return cls(period=T, mu_n=mu_n, mu_s=mu_s, p=p, delta=delta)

    @property
    def inertia_factor(self):
        """kappa = T^(2-p), the factor in u' = kappa F (eq. Newtonu)."""
        return self.period ** (2.0 - self.p)

    @property
    def delta_tau(self):
        """delta_tau = T delta (eq. tau)."""
        return self.period * self.delta

    @property
    def anisotropy_ratio(self):
        return self.mu_n / self.mu_s

    @property
    def scaled_period(self):
        return scaled_from_physical(self.period, self.mu_n, self.mu_s, self.p)[1]

    def with_period(self, period):
        """These physics with every point's period replaced by ``period`` (scalar or
        (n_points,)); only the new period is checked (the rest was, at construction): an
        optimiser's line search makes one per trial point."""
        T = np.asarray(period, dtype=float)
        if T.ndim > 1 or T.size not in (1, len(self)):
            raise ValueError(f"period: expected a scalar or {len(self)} values, got shape "
                             f"{T.shape}")
        T = np.broadcast_to(T.reshape(-1), self.period.shape).copy()
        if not np.all(np.isfinite(T) & (T > 0)):
            raise ValueError("period: T must be finite and > 0")
        new = object.__new__(type(self))
        for name in ("mu_n", "mu_s", "p", "delta"):
            object.__setattr__(new, name, getattr(self, name).copy())
        object.__setattr__(new, "period", T)
        return new

    def take(self, index):
        return Physics(self.period[index], self.mu_n[index], self.mu_s[index], self.p[index],
                       self.delta[index])


def scaled_from_physical(period, mu_n, mu_s, p=0.0):
    """(T, mu_n, mu_s) -> (anisotropy ratio mu_n/mu_s, scaled period (mu_n mu_s)^(1/(4-2p)) T)."""
    period, mu_n, mu_s, p = (np.asarray(x, dtype=float) for x in (period, mu_n, mu_s, p))
    return mu_n / mu_s, (mu_n * mu_s) ** (1.0 / (4.0 - 2.0 * p)) * period


def physical_from_scaled(anisotropy_ratio, scaled_period, p=0.0, friction_scale=1.0):
    """(ratio, scaled period) -> (T, mu_n, mu_s) with sqrt(mu_n mu_s) = ``friction_scale``."""
    r, Ts, p, g = (np.asarray(x, dtype=float) for x in (anisotropy_ratio, scaled_period, p, friction_scale))
    mu_n = g * np.sqrt(r)
    mu_s = g / np.sqrt(r)
    T = Ts / g ** (1.0 / (2.0 - p))
    return T, mu_n, mu_s


class PointPhysics(NamedTuple):
    """The physics of one parameter point as the kernels see it (eq. Newtonu, eq. tau):
    what the engine's and the march's compiled kernels take per point."""

    kappa: float   # T^(2-p), the inertia factor in u' = kappa F
    mu_n: float    # normal resistance coefficient
    mu_s: float    # tangential resistance coefficient
    p: float       # force-law exponent, 0 <= p < 2
    dtau: float    # delta_tau = T delta
