"""The polishing coordinates of one reduction: the bounded box of its continuous ``over`` axes.

An axis given on a log2 grid moves in log2 (so a step means the same factor everywhere); the
others move linearly. A subset window (``Subsets`` kind "window") narrows its axis's bounds.
"""

from __future__ import annotations

import numpy as np

__all__ = ["PolishSpace", "EDGE_FRACTION"]

#: an arg-max closer to a bound than this fraction of one grid step lies on that edge
EDGE_FRACTION = 1e-3


class PolishSpace:
    """The free axes of reduction ``r`` of ``scene`` and their box.

    Attributes
    ----------
    free : list of str
        The continuous ``over`` axes (the discrete power-law shapes stay at their grid values).
    log : ndarray of bool, shape (n_free,)
        Axis moves in log2.
    step : ndarray, shape (n_free,)
        One grid spacing per free axis, in its coordinate (the natural scale of a move).
    """

    def __init__(self, scene, r):
        self.scene, self.r = scene, r
        self.free = [a for a in r.over if scene.axis(a).continuous]
        self.log = np.array([scene.axis(a).spacing == "log2" for a in self.free], dtype=bool)
        steps = []
        for a, lg in zip(self.free, self.log):
            v = scene.axis(a).array()
            g = np.log2(v) if lg else v
            steps.append(float(np.min(np.diff(g))))
        self.step = np.array(steps, dtype=np.float64)

    def to_x(self, params: dict) -> np.ndarray:
        """The free coordinates of a point (dict of every parameter)."""
        v = np.array([params[a] for a in self.free], dtype=np.float64)
        return np.where(self.log, np.log2(np.where(self.log, v, 1.0)), v)

    def params(self, base: dict, x: np.ndarray) -> dict:
        """``base`` with the free axes at ``x``."""
        p = dict(base)
        for a, lg, xi in zip(self.free, self.log, x):
            p[a] = float(2.0 ** xi) if lg else float(xi)
        return p

    def axis_bounds(self, name: str, subset: int | None) -> tuple[float, float]:
        """(lo, hi) of axis ``name`` in its values: the grid's ends, narrowed by a subset window."""
        v = self.scene.axis(name).array()
        lo, hi = float(v.min()), float(v.max())
        s = self.r.subsets
        if s is not None and s.kind == "window" and name in s.axes and subset is not None:
            h = s.labels[subset]
            lo, hi = max(lo, s.center - h), min(hi, s.center + h)
        return lo, hi

    def bounds(self, subset: int | None) -> np.ndarray:
        """shape (n_free, 2): the box in x coordinates."""
        b = np.array([self.axis_bounds(a, subset) for a in self.free], dtype=np.float64).reshape(-1, 2)
        return np.where(self.log[:, None], np.log2(np.where(self.log[:, None], b, 1.0)), b)

    def inside(self, params: dict, subset: int | None) -> bool:
        """``params`` lies in the polish domain of ``subset``: the free axes inside the box, the
        discrete ones in an exponent-set subset's set."""
        b = self.bounds(subset)
        x = self.to_x(params)
        if np.any(x < b[:, 0] - 1e-12) or np.any(x > b[:, 1] + 1e-12):
            return False
        s = self.r.subsets
        if s is not None and s.kind == "exponent_sets" and subset is not None:
            return all(abs(params[a]) in s.sets[subset] for a in s.axes)
        return True

    def edges(self, params: dict, subset: int | None) -> dict[str, int]:
        """Per ``over`` axis: -1 where ``params`` lies on the box's lower end, +1 on its upper
        end, 0 inside (within ``EDGE_FRACTION`` of a grid step; discrete axes: 0)."""
        out = {a: 0 for a in self.r.over}
        if not self.free:
            return out
        x, b = self.to_x(params), self.bounds(subset)
        tol = EDGE_FRACTION * self.step
        for j, a in enumerate(self.free):
            if b[j, 1] - b[j, 0] <= tol[j]:
                continue  # a window of one value: no room to move, no edge to report
            if x[j] <= b[j, 0] + tol[j]:
                out[a] = -1
            elif x[j] >= b[j, 1] - tol[j]:
                out[a] = 1
        return out
