"""Starts of a polish: the best few distinct basins of the grid (not only its best point).

A basin is a local maximum of the grid objective over the continuous ``over`` axes (each
combination of the discrete axes apart); two local maxima within one grid step of each other
(a plateau) are one basin.
"""

from __future__ import annotations

import numpy as np

__all__ = ["distinct_starts", "face_starts"]


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


def face_starts(objective: np.ndarray, continuous: tuple[bool, ...], taken: list[int]) -> list[int]:
    """Flat indices of the best grid point on each face of the box (each end of each continuous
    axis), best first, leaving out any within one grid step of ``taken`` or of each other.

    A maximum on the domain's edge between grid points need not be a local maximum of the grid
    (a narrow ridge along the face: power_law at 2^-4, 2^1, window 0.49 peaks at 0.913 at
    A1/A0 = 0.02, A0 = 1.40 between the grid's 1.18 and 1.57, where no grid point is a local
    maximum); the best point of its face starts a climb along it.
    """
    o = np.asarray(objective, dtype=np.float64)
    cont = np.array(continuous, dtype=bool)
    cand = []
    for ax in np.flatnonzero(cont):
        for end in (0, o.shape[ax] - 1):
            face = np.take(o, [end], axis=ax)
            k = int(np.argmax(face))
            if not np.isfinite(face.flat[k]):
                continue
            idx = list(np.unravel_index(k, face.shape))
            idx[ax] = end
            cand.append((float(face.flat[k]), int(np.ravel_multi_index(idx, o.shape))))
    chosen: list[int] = []
    near = [np.array(np.unravel_index(t, o.shape)) for t in taken]
    for _, k in sorted(cand, key=lambda t: -t[0]):
        idx = np.array(np.unravel_index(k, o.shape))
        if any(np.all(idx[~cont] == p[~cont]) and np.max(np.abs(idx[cont] - p[cont]), initial=0) <= 1 for p in near):
            continue
        chosen.append(k)
        near.append(idx)
    return chosen
