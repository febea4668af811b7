"""Reductions: grid maxima over chosen axes with their arg-max parameters, and polishing.

``grid_reduction`` is a pure function of in-memory arrays; ``polish_cells`` runs inside dask
tasks and calls the solver one point at a time from the best grid point.
"""

from __future__ import annotations

import math

import numpy as np

from ._grid import solve_points
from ._scene import Reduction, Scene

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


def polish_cells(scene: Scene, r: Reduction, cells: list[dict]) -> list[dict]:
    """Refine the best grid points of ``cells`` with a bounded local optimiser.

    Each cell is ``{"params": {name: float}, "subset": int | None, "value": grid objective}`` with
    every parameter of the point. The continuous axes of ``r.over`` move (in log2 for axes
    given on a log2 grid), bounded to the axis range (and to the subset's window); the discrete
    ones stay at their grid values. Returns, per cell, the best point found, never worse than
    the grid point.
    """
    from scipy.optimize import minimize

    rtol = r.polish_rtol if r.polish_rtol is not None else scene.rtol
    report = tuple(n for n in r.report if n != r.quantity)
    outputs = (r.quantity,) + report
    free = [a for a in r.over if scene.axis(a).continuous]
    results = []
    for cell in cells:
        base = dict(cell["params"])
        logs = [scene.axis(a).spacing == "log2" for a in free]
        tf = [(math.log2 if lg else float) for lg in logs]
        bounds = []
        for a, lg, sub in zip(free, logs, [cell["subset"]] * len(free)):
            lo, hi = _bounds(scene, r, a, sub)
            bounds.append((math.log2(lo), math.log2(hi)) if lg else (lo, hi))
        x0 = np.array([f(base[a]) for f, a in zip(tf, free)])
        n_eval = 0
        cache: dict[tuple, tuple[float, dict]] = {}

        def evaluate(x):
            nonlocal n_eval
            x = np.clip(x, [b[0] for b in bounds], [b[1] for b in bounds])
            key = tuple(np.round(x, 14))
            if key in cache:
                return cache[key]
            p = dict(base)
            for a, lg, xi in zip(free, logs, x):
                p[a] = float(2.0 ** xi) if lg else float(xi)
            arrays = {k: np.array([v], dtype=np.float64) for k, v in p.items()}
            vals = solve_points(scene.family, arrays, outputs, method=scene.method, rtol=rtol)
            n_eval += 1
            o = float(objective(r.statistic, vals[r.quantity])[0])
            rec = {"params": p, "status": int(vals["status"][0]),
                   "values": {k: float(vals[k][0]) for k in outputs}}
            cache[key] = (o, rec)
            return o, rec

        best_o, best = -np.inf, None
        if free:
            # One grid spacing per free axis as the initial simplex / scale.
            steps = []
            for a, lg, (lo, hi) in zip(free, logs, bounds):
                v = scene.axis(a).array()
                g = np.log2(v) if lg else v
                steps.append(float(np.min(np.diff(g))) if g.size > 1 else 0.1 * (hi - lo or 1.0))
            steps = np.array(steps)

            def fun(x):
                o, _ = evaluate(np.asarray(x))
                return -o if np.isfinite(o) else 1e300

            opts = {"maxfev": r.polish_max_evaluations} if r.polish_method in ("Nelder-Mead", "Powell") \
                else {"maxfun": r.polish_max_evaluations}
            if r.polish_method == "Nelder-Mead":
                simplex = [x0]
                for j in range(len(free)):
                    e = x0.copy()
                    e[j] = x0[j] + steps[j] if x0[j] + steps[j] <= bounds[j][1] else x0[j] - steps[j]
                    simplex.append(e)
                opts.update(initial_simplex=np.array(simplex), xatol=1e-3 * float(steps.min()),
                            fatol=rtol * max(abs(cell["value"]), 1e-300))
            elif r.polish_method == "L-BFGS-B":
                opts.update(eps=1e-3 * steps, ftol=rtol)
            try:
                minimize(fun, x0, method=r.polish_method, bounds=bounds, options=opts)
            except Exception:  # a failed optimiser run keeps the grid point
                pass
            for o, rec in cache.values():
                if o > best_o:
                    best_o, best = o, rec
        if best is None or best_o < cell["value"]:
            # Never report worse than the grid: re-evaluate the grid point if the optimiser lost it.
            o, rec = evaluate(x0) if free else evaluate(np.zeros(0))
            if best is None or o > best_o:
                best_o, best = o, rec
        results.append({"objective": best_o, "evaluations": n_eval, **best})
    return results
