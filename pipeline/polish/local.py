"""The local method of a polish: a bounded maximiser that stops on a relative value tolerance.

``maximise`` runs one start. It counts solver calls (each distinct point once), stops at the
cap (a result that says so, never "converged"), and keeps the value after every iteration,
whose last relative change is the run's own convergence estimate. The methods were chosen by
measurement (docs/validation.md, "Polish method"): Powell (default), Nelder-Mead, compass.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

__all__ = ["LocalResult", "maximise", "METHODS"]

METHODS = ("Powell", "Nelder-Mead", "compass")


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
    last_change : float  relative change of the value over the last iteration (NaN if none)
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
             method: str = "Powell") -> LocalResult:
    """Maximise ``fun`` from ``x0`` inside ``bounds``.

    Parameters
    ----------
    fun : callable x -> (value, record)
        value -inf where the solve failed; ``record`` is kept for the best point.
    x0 : ndarray, shape (n_free,)
    bounds : ndarray, shape (n_free, 2)
    step : ndarray, shape (n_free,)  the scale of a move (one grid spacing)
    tolerance : relative value tolerance: the run has converged when one iteration changes
        the value by less than ``tolerance`` times its size (Powell's ``ftol``; Nelder-Mead's
        simplex spread; compass: a poll at 1/64 of a grid step that gains less).
    max_evaluations : cap on solver calls (``capped`` when reached).
    """
    from scipy.optimize import minimize

    bounds = np.asarray(bounds, dtype=np.float64).reshape(-1, 2)
    x0 = np.clip(np.asarray(x0, dtype=np.float64), bounds[:, 0], bounds[:, 1])
    step = np.asarray(step, dtype=np.float64)
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
            def neg(x):
                v = f(x)
                return -v if np.isfinite(v) else 1e300

            def callback(*args):
                history.append(f.best[0])

            if method == "Powell":
                opts = {"ftol": tolerance, "xtol": 1e-2, "maxfev": 10 ** 9, "direc": np.diag(step)}
            elif method == "Nelder-Mead":
                simplex = [x0]
                for j in range(len(x0)):
                    e = x0.copy()
                    e[j] = x0[j] + (step[j] if x0[j] + step[j] <= bounds[j, 1] else -step[j])
                    simplex.append(e)
                opts = {"maxfev": 10 ** 9, "initial_simplex": np.array(simplex),
                        "xatol": 1e-3 * float(step.min()), "fatol": tolerance * max(abs(v0), 1e-300)}
            else:
                raise ValueError(f"unknown polish method {method!r} (one of {', '.join(METHODS)})")
            try:
                res = minimize(neg, x0, method=method, bounds=[tuple(b) for b in bounds], options=opts,
                               callback=callback)
                converged = bool(res.success)
            except (ValueError, FloatingPointError):  # a failed optimiser run keeps its best point
                converged = False
    except _Capped:
        capped, converged = True, False
    value, x, record = f.best
    if x is None:
        x = x0
    if not history or history[-1] != value:
        history.append(value)
    return LocalResult(x=np.asarray(x), value=float(value), record=record, evaluations=len(f.cache),
                       converged=converged and np.isfinite(value), capped=capped,
                       last_change=_relative_change(history))


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
