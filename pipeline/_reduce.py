"""Reductions: grid maxima over chosen axes with their arg-max parameters, and the starts of
their polish.

``grid_reduction`` and ``polish_starts`` are pure functions of in-memory arrays; the polish
itself (``pipeline.polish.polish_cells``) runs inside dask tasks.
"""

from __future__ import annotations

import numpy as np

from ._grid_scene import Reduction, Scene

__all__ = ["grid_reduction", "polish_starts", "objective"]


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
# Polishing (pipeline.polish): the starts of every cell
# ---------------------------------------------------------------------------


def polish_starts(scene: Scene, r: Reduction, data: dict[str, np.ndarray]) -> list[dict]:
    """The cells a polish of ``r`` runs: per kept grid position (and subset) with a valid point,
    ``{"pos": index into the reduction's shape, "subset": int | None, "group": the kept position
    (one per grid cell, shared by its subsets), "starts": [params, ...]}``,
    the starts the best ``r.polish_starts`` distinct grid basins inside the subset
    (``pipeline.polish.distinct_starts``), the best point of each face of the box not within
    one grid step of those (``pipeline.polish.face_starts``), then the best basin of every
    other subset that lies
    inside this one (nested windows: the wider one starts from the narrower one's best too),
    each with every parameter of its point."""
    from .polish import distinct_starts, face_starts

    dims = scene.dims
    over_pos = [dims.index(a) for a in r.over]
    kept_pos = [i for i in range(len(dims)) if i not in over_pos]
    kept = [scene.axes[i] for i in kept_pos]
    kept_shape = tuple(scene.shape[i] for i in kept_pos)
    over_shape = tuple(scene.shape[i] for i in over_pos)
    o = objective(r.statistic, np.transpose(data[r.quantity], kept_pos + over_pos))
    masks = _subset_masks(scene, r)
    continuous = tuple(scene.axis(a).continuous for a in r.over)
    cells = []
    for kpos in np.ndindex(*kept_shape):
        blocks = [np.where(mask, o[kpos], -np.inf) for mask in masks]
        found = [distinct_starts(b, continuous, r.polish_starts) for b in blocks]
        for j, mask in enumerate(masks):
            flat = list(found[j])
            flat += face_starts(blocks[j], continuous, flat)
            # The best basin of another subset that lies inside this one starts here too: a wider
            # window's best basin may be a grid neighbour of its edge and not a local maximum of
            # the wider block, and its maximum must not fall below the narrower one's.
            for other in found:
                if other and other[0] not in flat and mask.reshape(-1)[other[0]]:
                    flat.append(other[0])
            starts = []
            for k in flat:
                params = dict(scene.fixed)
                for a, i in zip(kept, kpos):
                    params[a.name] = float(a.values[i])
                for a, i in zip(r.over, np.unravel_index(k, over_shape)):
                    params[a] = float(scene.axis(a).values[i])
                starts.append(params)
            if starts:
                subset = j if r.subsets is not None else None
                cells.append({"pos": kpos + ((j,) if r.subsets is not None else ()), "subset": subset,
                              "group": kpos, "starts": starts})
    return cells
