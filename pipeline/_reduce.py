"""Reductions: grid maxima over chosen axes with their arg-max parameters, and polishing.

``grid_reduction`` is a pure function of in-memory arrays. ``polish_cells`` runs inside dask
tasks and refines best grid points with a bounded local optimiser: a compass search batched
over cells (each round one solver call), or scipy.optimize.minimize per cell.
"""

from __future__ import annotations

import numpy as np

from ._grid import solve_points
from ._grid_scene import Reduction, Scene

__all__ = ["grid_reduction", "polish_cells", "objective"]


def objective(statistic: str, q: np.ndarray) -> np.ndarray:
    """The quantity maximised: q (max), -q (min) or |q| (absmax); NaN (failed points) -> -inf."""
    o = {"max": q, "min": -q, "absmax": np.abs(q)}[statistic]
    return np.where(np.isnan(o), -np.inf, o)


def _subset_masks(scene: Scene, r: Reduction) -> list[np.ndarray]:
    """Boolean masks over the ``over`` block (shape of the over axes), one per subset."""
    over_shape = tuple(scene.axis(a).size for a in r.over)
    if r.subsets is None:
        return [np.ones(over_shape, dtype=bool)]
    out = []
    for per_axis in r.subsets.masks(scene):
        m = np.ones(over_shape, dtype=bool)
        for j, a in enumerate(r.over):
            if a in per_axis:
                shape = [1] * len(r.over)
                shape[j] = -1
                m = m & per_axis[a].reshape(shape)
        out.append(m)
    return out


def grid_reduction(scene: Scene, r: Reduction, data: dict[str, np.ndarray]) -> tuple[dict[str, np.ndarray], np.ndarray]:
    """Best grid point of ``r.quantity`` over ``r.over`` for every kept cell (and subset).

    Parameters
    ----------
    data : dict of ndarray, each shape ``scene.shape``
        ``r.quantity`` and every name in ``r.report``.

    Returns
    -------
    arrays : dict of ndarray, shape (kept axes..., [n_subsets])
        The statistic, the signed value (absmax), the arg-max axis values and the reported
        quantities there, named as in :func:`pipeline._store.reduction_arrays`.
    flat_index : ndarray of int, same shape
        Flat index of the best point inside the ``over`` block (-1 where every point failed).
    """
    dims = scene.dims
    over_pos = [dims.index(a) for a in r.over]
    kept_pos = [i for i in range(len(dims)) if i not in over_pos]
    kept_shape = tuple(scene.shape[i] for i in kept_pos)
    over_shape = tuple(scene.shape[i] for i in over_pos)
    m = int(np.prod(over_shape, dtype=np.int64))

    def block(x):
        return np.transpose(x, kept_pos + over_pos).reshape(kept_shape + (m,))

    q = block(data[r.quantity])
    o = objective(r.statistic, q)
    masks = _subset_masks(scene, r)
    best_idx = []
    for mask in masks:
        om = np.where(mask.reshape(-1), o, -np.inf)
        idx = np.argmax(om, axis=-1)
        ok = np.take_along_axis(om, idx[..., None], axis=-1)[..., 0] > -np.inf
        best_idx.append(np.where(ok, idx, -1))
    flat = np.stack(best_idx, axis=-1) if r.subsets is not None else best_idx[0]
    valid = flat >= 0
    safe = np.where(valid, flat, 0)

    def at(x):
        """x (shape kept+(m,)) at the best index, NaN where no valid point."""
        if r.subsets is not None:
            vals = np.take_along_axis(x, safe.reshape(kept_shape + (-1,)), axis=-1)
        else:
            vals = np.take_along_axis(x, safe[..., None], axis=-1)[..., 0]
        return np.where(valid, vals, np.nan)

    out: dict[str, np.ndarray] = {}
    signed = at(q)
    out[r.name] = np.abs(signed) if r.statistic == "absmax" else signed
    if r.statistic == "absmax":
        out[f"{r.name}_signed"] = signed
    unr = np.unravel_index(safe, over_shape)
    for j, a in enumerate(r.over):
        out[f"{r.name}_{a}"] = np.where(valid, scene.axis(a).array()[unr[j]], np.nan)
    for name in r.report:
        if name != r.quantity:
            out[f"{r.name}_{name}"] = at(block(data[name]))
    return out, flat


# ---------------------------------------------------------------------------
# Polishing
# ---------------------------------------------------------------------------


def _bounds(scene: Scene, r: Reduction, name: str, subset: int | None) -> tuple[float, float]:
    v = scene.axis(name).array()
    lo, hi = float(v.min()), float(v.max())
    if r.subsets is not None and r.subsets.kind == "window" and name in r.subsets.axes and subset is not None:
        h = r.subsets.labels[subset]
        lo, hi = max(lo, r.subsets.center - h), min(hi, r.subsets.center + h)
    return lo, hi


class _Space:
    """The polishing coordinates of one reduction: the free (continuous) axes of ``over``,
    in log2 for axes given on a log2 grid, with one grid spacing as the natural step."""

    def __init__(self, scene: Scene, r: Reduction):
        self.scene, self.r = scene, r
        self.free = [a for a in r.over if scene.axis(a).continuous]
        self.log = np.array([scene.axis(a).spacing == "log2" for a in self.free], dtype=bool)
        steps = []
        for a, lg in zip(self.free, self.log):
            v = scene.axis(a).array()
            g = np.log2(v) if lg else v
            steps.append(float(np.min(np.diff(g))))
        self.step = np.array(steps)

    def to_x(self, params: dict) -> np.ndarray:
        v = np.array([params[a] for a in self.free], dtype=np.float64)
        return np.where(self.log, np.log2(np.where(self.log, v, 1.0)), v)

    def bounds(self, subset) -> np.ndarray:
        """shape (n_free, 2) in x coordinates."""
        b = np.array([_bounds(self.scene, self.r, a, subset) for a in self.free], dtype=np.float64).reshape(-1, 2)
        return np.where(self.log[:, None], np.log2(np.where(self.log[:, None], b, 1.0)), b)

    def params(self, base: dict, x: np.ndarray) -> dict:
        p = dict(base)
        for a, lg, xi in zip(self.free, self.log, x):
            p[a] = float(2.0 ** xi) if lg else float(xi)
        return p


def _solve_many(scene: Scene, r: Reduction, points: list[dict], rtol: float) -> list[tuple[float, dict]]:
    """Objective and record at each point (dict of every parameter), in one batched solver call."""
    if not points:
        return []
    outputs = (r.quantity,) + tuple(n for n in r.report if n != r.quantity)
    arrays = {k: np.array([p[k] for p in points], dtype=np.float64) for k in points[0]}
    vals = solve_points(scene.family, arrays, outputs, method=scene.method, rtol=rtol)
    obj = objective(r.statistic, vals[r.quantity])
    return [(float(obj[i]), {"params": points[i], "status": int(vals["status"][i]),
                             "values": {k: float(vals[k][i]) for k in outputs}}) for i in range(len(points))]


def _compass(space: _Space, cells: list[dict], rtol: float, budget: int) -> list[dict]:
    """Bounded compass search, batched over cells: every round evaluates x +- step along each
    free axis for every active cell in one solver call; a cell moves to its best improving
    neighbour, or halves its step. Starts at half a grid spacing (the grid optimum is within
    one spacing of the true one) and stops at 1/64 of a spacing or after ``budget`` solves."""
    n_free = len(space.free)
    state = []
    first = _solve_many(space.scene, space.r, [c["params"] for c in cells], rtol)
    for c, (o, rec) in zip(cells, first):
        state.append({"x": space.to_x(c["params"]), "o": o, "rec": rec, "step": 0.5 * space.step.copy(),
                      "bounds": space.bounds(c["subset"]), "base": c["params"], "evals": 1})
    while True:
        batch, owner = [], []
        for k, st in enumerate(state):
            if n_free == 0 or np.all(st["step"] < space.step / 64) or st["evals"] + 2 * n_free > budget:
                continue
            for j in range(n_free):
                for sgn in (-1.0, 1.0):
                    x = st["x"].copy()
                    x[j] = np.clip(x[j] + sgn * st["step"][j], *st["bounds"][j])
                    if x[j] != st["x"][j]:
                        batch.append(space.params(st["base"], x))
                        owner.append((k, x))
        if not batch:
            break
        results = _solve_many(space.scene, space.r, batch, rtol)
        best: dict[int, tuple] = {}
        for (k, x), (o, rec) in zip(owner, results):
            state[k]["evals"] += 1
            if o > best.get(k, (-np.inf,))[0]:
                best[k] = (o, rec, x)
        for k, st in enumerate(state):
            if k not in best:
                if n_free and not np.all(st["step"] < space.step / 64) and st["evals"] + 2 * n_free <= budget:
                    st["step"] = st["step"] * 0.5  # every neighbour was outside the bounds
                continue
            o, rec, x = best[k]
            # Move only on a gain above the solver's own accuracy, so noise cannot drive the walk.
            if o > st["o"] + rtol * abs(st["o"]):
                st.update(o=o, rec=rec, x=x)
            else:
                st["step"] = st["step"] * 0.5
    return [{"objective": st["o"], "evaluations": st["evals"], **st["rec"]} for st in state]


def _scipy(space: _Space, cells: list[dict], rtol: float, budget: int, method: str) -> list[dict]:
    """One scipy.optimize.minimize run per cell (solver called one point at a time)."""
    from scipy.optimize import minimize

    out = []
    for cell in cells:
        x0 = space.to_x(cell["params"])
        bounds = space.bounds(cell["subset"])
        cache: dict[tuple, tuple[float, dict]] = {}

        def evaluate(x):
            x = np.clip(np.asarray(x, dtype=np.float64), bounds[:, 0], bounds[:, 1])
            key = tuple(np.round(x, 14))
            if key not in cache:
                cache[key] = _solve_many(space.scene, space.r, [space.params(cell["params"], x)], rtol)[0]
            return cache[key]

        o0, rec0 = evaluate(x0)
        if space.free:
            def fun(x):
                o, _ = evaluate(x)
                return -o if np.isfinite(o) else 1e300

            if method == "Nelder-Mead":
                simplex = [x0]
                for j in range(len(space.free)):
                    e = x0.copy()
                    up = x0[j] + space.step[j] <= bounds[j, 1]
                    e[j] = x0[j] + (space.step[j] if up else -space.step[j])
                    simplex.append(e)
                opts = {"maxfev": budget, "initial_simplex": np.array(simplex),
                        "xatol": float(space.step.min()) / 64, "fatol": rtol * max(abs(o0), 1e-300)}
            elif method == "L-BFGS-B":
                opts = {"maxfun": budget, "eps": 1e-3 * space.step, "ftol": rtol}
            else:
                opts = {"maxfev": budget}
            try:
                minimize(fun, x0, method=method, bounds=[tuple(b) for b in bounds], options=opts)
            except (ValueError, FloatingPointError):  # a failed optimiser run keeps the grid point
                pass
        o, rec = max(cache.values(), key=lambda t: t[0])
        out.append({"objective": o, "evaluations": len(cache), **rec})
    return out


def polish_cells(scene: Scene, r: Reduction, cells: list[dict]) -> list[dict]:
    """Refine the best grid points of ``cells`` with a bounded local optimiser.

    Each cell is ``{"params": {name: float}, "subset": int | None, "value": grid objective}`` with
    every parameter of the point. The continuous axes of ``r.over`` move (in log2 for axes
    given on a log2 grid), bounded to the axis range (and to the subset's window); the discrete
    ones stay at their grid values. Returns per cell the best point evaluated, which includes
    the grid point itself, so polishing never reports less than the grid optimum (up to the
    solver's tolerance when ``polish_rtol`` differs from the grid's rtol).
    """
    rtol = r.polish_rtol if r.polish_rtol is not None else scene.rtol
    space = _Space(scene, r)
    if r.polish_method == "compass":
        return _compass(space, cells, rtol, r.polish_max_evaluations)
    return _scipy(space, cells, rtol, r.polish_max_evaluations, r.polish_method)
