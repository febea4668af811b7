"""Starts of a polish: the best few distinct basins of the grid (not only its best point).

A basin is a local maximum of the grid objective over the continuous ``over`` axes (each
combination of the discrete axes apart); two local maxima within one grid step of each other
(a plateau) are one basin.
"""

from __future__ import annotations

import numpy as np

__all__ = ["distinct_starts"]


def distinct_starts(objective: np.ndarray, continuous: tuple[bool, ...], n: int) -> list[int]:
    """Flat indices of the best ``n`` distinct local maxima of ``objective``, best first.

    Parameters
    ----------
    objective : ndarray, shape (over axes...)
        The grid objective of one cell; -inf where a point failed or lies outside the subset.
    continuous : tuple of bool, one per axis
        Axes along which neighbours are compared (the others are categorical).
    n : number of starts wanted (fewer when the grid has fewer basins).

    Returns
    -------
    list of int
        Flat indices; the grid's best point first (a local maximum by definition), each later
        one more than one grid step (Chebyshev, in index) from every earlier one that shares its
        discrete values. Empty when no point is finite.
    """
    from scipy.ndimage import maximum_filter

    o = np.asarray(objective, dtype=np.float64)
    finite = np.isfinite(o)
    if not finite.any():
        return []
    size = tuple(3 if c else 1 for c in continuous)
    filled = np.where(finite, o, -np.inf)
    peak = finite & (filled >= maximum_filter(filled, size=size, mode="constant", cval=-np.inf))
    cand = np.flatnonzero(peak.reshape(-1))
    cand = cand[np.argsort(-filled.reshape(-1)[cand], kind="stable")]
    cont = np.array(continuous, dtype=bool)
    chosen: list[int] = []
    picked_idx: list[np.ndarray] = []
    for k in cand:
        idx = np.array(np.unravel_index(int(k), o.shape))
        if any(np.all(idx[~cont] == p[~cont]) and np.max(np.abs(idx[cont] - p[cont]), initial=0) <= 1
               for p in picked_idx):
            continue
        chosen.append(int(k))
        picked_idx.append(idx)
        if len(chosen) >= n:
            break
    return chosen
