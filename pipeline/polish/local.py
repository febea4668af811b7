"""The local method of a polish: a bounded maximiser that stops on a relative value tolerance.

``maximise`` runs one start. It counts solver calls (each distinct point once), stops at the
cap (a result that says so, never "converged"), and restarts the method from its best point
until a whole run gains less than the tolerance; that last gain is the start's own
convergence estimate. The methods were chosen by
measurement (docs/validation.md, "Polish method"): L-BFGS-B (default: forward-difference
gradients), Powell, Nelder-Mead, compass.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

__all__ = ["LocalResult", "maximise", "METHODS"]

METHODS = ("L-BFGS-B", "Powell", "Nelder-Mead", "compass")
#: L-BFGS-B's own per-iteration test at this fraction of the tolerance: on an ill-conditioned
#: ridge one iteration gains far less than what is left (duty_cycle at 2^-3, 2^-1, tau0 = 0.5:
#: stopped 3.3e-4 short with ftol = the tolerance); the restart test keeps the tolerance.
INNER = 1e-2


@dataclass(frozen=True)
class LocalResult:
    """One start's run.

    Attributes
    ----------
    x : ndarray, shape (n_free,)  the best point evaluated
    value : float  the objective there (-inf where every evaluation failed)
    record : object  what ``fun`` returned beside the value at ``x``
    evaluations : int  distinct points evaluated (solver calls)
    converged : bool  the method's value tolerance was met before the cap
    capped : bool  the cap stopped the run
    last_change : float  relative change of the value over the last run (the restart that
        confirmed convergence; compass: its last accepted move), NaN if none
    """

    x: np.ndarray
    value: float
    record: object
    evaluations: int
    converged: bool
    capped: bool
    last_change: float


class _Capped(Exception):
    pass


class _Counted:
    """``fun`` clipped to the box, cached by point, counted, stopping at the cap."""

    def __init__(self, fun, bounds, cap):
        self.fun, self.bounds, self.cap = fun, bounds, cap
        self.cache: dict[tuple, tuple[float, object]] = {}
        self.best: tuple[float, np.ndarray, object] = (-np.inf, None, None)

    def __call__(self, x) -> float:
        x = np.clip(np.asarray(x, dtype=np.float64), self.bounds[:, 0], self.bounds[:, 1])
        key = tuple(np.round(x, 13))
        if key not in self.cache:
            if len(self.cache) >= self.cap:
                raise _Capped
            self.cache[key] = self.fun(x)
            v = self.cache[key][0]
            if v > self.best[0] or self.best[1] is None:
                self.best = (v, x, self.cache[key][1])
        return self.cache[key][0]


def _relative_change(history: list[float]) -> float:
    if len(history) < 2 or not np.isfinite(history[-1]) or not np.isfinite(history[-2]):
        return np.nan
    return abs(history[-1] - history[-2]) / max(abs(history[-1]), 1e-300)


def maximise(fun, x0, bounds, step, *, tolerance: float, max_evaluations: int,
             method: str = "L-BFGS-B") -> LocalResult:
    """Maximise ``fun`` from ``x0`` inside ``bounds``.

    Parameters
    ----------
    fun : callable x -> (value, record)
        value -inf where the solve failed; ``record`` is kept for the best point.
    x0 : ndarray, shape (n_free,)
    bounds : ndarray, shape (n_free, 2)
    step : ndarray, shape (n_free,)  the scale of a move (one grid spacing)
    tolerance : relative value tolerance: the run has converged when the method, restarted
        from its best point, gains less than ``tolerance`` times the value in a whole run (each
        run stops on the method's own test at that tolerance: Powell's and L-BFGS-B's ``ftol``,
        Nelder-Mead's simplex spread); compass: a poll at 1/64 of a grid step that gains less.
    max_evaluations : cap on solver calls (``capped`` when reached).
    """
    from scipy.optimize import minimize

    step = np.asarray(step, dtype=np.float64)
    # Every method works in units of one grid step (z = x / step): a first move, a difference
    # quotient and a simplex then have the grid's scale on every axis (L-BFGS-B's first line
    # search otherwise jumps a whole unit of x, across basins, to a corner of the box).
    unit = np.where(step > 0, step, 1.0)
    bounds = np.asarray(bounds, dtype=np.float64).reshape(-1, 2) / unit[:, None]
    x0 = np.clip(np.asarray(x0, dtype=np.float64) / unit, bounds[:, 0], bounds[:, 1])
    user_fun = fun

    def fun(z):
        return user_fun(z * unit)

    step = np.ones_like(unit)
    f = _Counted(fun, bounds, max_evaluations)
    history: list[float] = []
    converged = capped = False
    try:
        v0 = f(x0)
        history.append(v0)
        if len(x0) == 0 or not np.isfinite(v0):
            converged = len(x0) == 0 and np.isfinite(v0)
        elif method == "compass":
            converged = _compass(f, x0, v0, bounds, step, tolerance, history)
        else:
            scale = max(abs(v0), 1e-300)  # the value in units of the start's: tolerances are relative

            def neg(x):
                v = f(x)
                return -v / scale if np.isfinite(v) else 1e300

            if method == "Powell":
                opts = {"ftol": tolerance, "xtol": 1e-2, "maxfev": 10 ** 9, "direc": np.diag(step)}
            elif method == "Nelder-Mead":
                opts = {"maxfev": 10 ** 9, "initial_simplex": _simplex(x0, bounds, step),
                        "xatol": 1e-3 * float(step.min()), "fatol": tolerance}
            elif method == "L-BFGS-B":
                # gradients by forward differences of 1e-3 grid step (solver noise ~ rtol is far below)
                opts = {"maxfun": 10 ** 9, "ftol": INNER * tolerance, "gtol": 0.0, "eps": 1e-3}
            else:
                raise ValueError(f"unknown polish method {method!r} (one of {', '.join(METHODS)})")
            # Converged when a whole run restarted from the best point so far (fresh directions,
            # simplex or Hessian) gains less than the tolerance: a run's own test stops too
            # early on a curved ridge (Powell's line searches along stale directions gain little
            # per iteration; L-BFGS-B's line search gives up on solver noise).
            x = x0
            while True:
                before = f.best[0]
                try:
                    minimize(neg, x, method=method, bounds=[tuple(b) for b in bounds], options=opts)
                except (ValueError, FloatingPointError):  # a failed optimiser run keeps its best point
                    converged = False
                    break
                x = np.asarray(f.best[1], dtype=np.float64)
                gain = (f.best[0] - before) / max(abs(f.best[0]), 1e-300)
                history.append(f.best[0])
                if before > -np.inf and not gain > tolerance:
                    converged = True
                    break
                if method == "Nelder-Mead":
                    opts["initial_simplex"] = _simplex(x, bounds, step)
    except _Capped:
        capped, converged = True, False
    value, x, record = f.best
    if x is None:
        x = x0
    if not history or history[-1] != value:
        history.append(value)
    return LocalResult(x=np.asarray(x) * unit, value=float(value), record=record, evaluations=len(f.cache),
                       converged=converged and np.isfinite(value), capped=capped,
                       last_change=_relative_change(history))


def _simplex(x0, bounds, step) -> np.ndarray:
    """Nelder-Mead's first simplex: ``x0`` and one grid step along each axis (inwards at a bound)."""
    simplex = [x0]
    for j in range(len(x0)):
        e = x0.copy()
        e[j] = x0[j] + (step[j] if x0[j] + step[j] <= bounds[j, 1] else -step[j])
        simplex.append(e)
    return np.array(simplex)


def _compass(f, x, v, bounds, step, tolerance, history) -> bool:
    """Compass search from half a grid step; converged when the step is below 1/64 of a grid step."""
    h = 0.5 * step.copy()
    while np.any(h >= step / 64):
        best = (v, x)
        for j in range(len(x)):
            for sgn in (-1.0, 1.0):
                y = x.copy()
                y[j] = np.clip(y[j] + sgn * h[j], *bounds[j])
                if y[j] != x[j]:
                    vy = f(y)
                    if vy > best[0]:
                        best = (vy, y)
        if best[0] > v + tolerance * abs(v):
            v, x = best
            history.append(v)
        else:
            h = h * 0.5
    return True
