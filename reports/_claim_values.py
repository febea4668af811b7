"""Our value of a claim of the paper, read from the stores: the reductions named in
``claims.toml`` (``compute = "<name>"``).

Every reduction is a named function ``f(stores, **args) -> Measurement`` in :data:`COMPUTE`.
They are built from a few small steps over labelled arrays (``xarray.DataArray``):

``source``
    the array of one role of a reduction of a grid store (the polished optimum where the scene
    polishes, else the grid one: ``value``, ``signed``, an arg-max axis, a reported quantity),
    a stored quantity (``quantity = "scaled_power"``), or a role of the optima of an optima
    store (``relative_efficiency``, ``scaled_period``, ``phi_max``, ``phi_min``, ``distinct``);
``select``
    ``at`` (one value per dimension; "min"/"max" for the axis' ends), ``cells`` (a list of such
    points, stacked along ``cell``), ``ranges`` (inclusive [lo, hi] per dimension), ``exclude``;
``grid``
    true: the grid optimum even where a polished one is stored;
``tau0_window``
    the half-width of the τ0 window |τ0 − 0.5| ≤ h of a reduction repeated over τ0 windows
    (``duty_cycle_halfwidth``): 0.45 is the paper's domain τ0 ∈ [0.05, 0.95] (issue 44); a store
    without that window raises NotComputed (never read on another domain);
``peak_over``
    the maximum over dimensions (the paper's "peak" over periods);
``location_along``
    the coordinate of the maximum along one dimension, per remaining cell;
``statistic``
    ``only`` (one cell), ``max``, ``min``, ``median``, ``range`` ((min, max)), ``fraction``
    (share of cells passing ``test``), optionally ``location`` (the coordinate of the max/min
    instead of the value).

A selection the store does not hold raises :class:`NotComputed` (the claim is "not run").

The polish record (issue 44): where a polished reduction stores ``{r}_polished_status``,
``{r}_polished_uncertainty`` and ``{r}_polished_{axis}_edge``, a selected cell whose status is
not 0 makes the measurement ``cannot_judge``, the error estimate of a polished value is its
uncertainty (relative) times |value|, and an arg-max on an edge of the polish domain is named.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

__all__ = ["Measurement", "NotComputed", "COMPUTE", "grid_role_array", "is_optima", "optima_role_array", "scene_store"]


class NotComputed(LookupError):
    """The stores do not hold what a claim needs (a missing scene, cell or array)."""


@dataclass
class Measurement:
    """Our value of a claim and what the data say about its accuracy.

    value : float, or (lo, hi) for a range
    where : the cell(s) the value comes from, in words
    resolution : the grid (or ensemble) the value was found on
    error : our error estimate, in words
    error_value : the error estimate in the value's units (NaN when not known)
    edges : arg-max axes at an end of their scanned range, e.g. ("A1/A0 at its lower end 0.059",)
    coarse, coarse_value : for an extremum over a sampled axis, the sampling in words and how
        much the value changes to the neighbouring samples (what the grid can hide)
    coarse_side : "below" (a maximum: finer sampling can only raise it) or "above" (a minimum);
        the sampling explains a miss only on that side
    neighbours : for a located coordinate, the coordinates one grid step either side
    failed : (cells without a valid value, cells selected)
    cannot_judge : why the data cannot decide the claim (a selected polished optimum that did not
        converge: ``_polished_status`` ≠ 0), "" when they can
    """

    value: object
    where: str = ""
    resolution: str = ""
    error: str = ""
    error_value: float = math.nan
    edges: tuple = ()
    coarse: str = ""
    coarse_value: float = math.nan
    neighbours: list = field(default_factory=list)
    coarse_side: str = ""
    failed: tuple = (0, 0)
    cannot_judge: str = ""


# ---------------------------------------------------------------------------
# Sources
# ---------------------------------------------------------------------------

_AXIS_NAMES = {"anisotropy_ratio": "μn/μs", "scaled_period": "scaled period", "A0": "A0", "A1_ratio": "A1/A0",
               "duty_cycle": "τ0", "T2_mu_n": "T²μn", "T2_mu_s": "T²μs", "max_wavenumber": "Kmax", "p": "p",
               "duty_cycle_halfwidth": "Δτ0", "exponent_set": "exponent set", "closing_shape": "closing law",
               "opening_shape": "opening law"}


def axis_name(dim: str) -> str:
    return _AXIS_NAMES.get(dim, dim)


def value_text(dim: str, v: float) -> str:
    """A coordinate as the paper writes it (powers of two for the friction parameters)."""
    v = float(v)
    if dim in ("anisotropy_ratio", "scaled_period", "T2_mu_n", "T2_mu_s") and v > 0:
        k = math.log2(v)
        if abs(2 * k - round(2 * k)) < 1e-9:
            return f"2^{k:g}" if k else "1"
    return f"{v:.3g}"


def is_optima(sd) -> bool:
    """The store holds an optimiser's ensembles (kept optima), not a grid."""
    return sd.meta.get("kind", "grid") == "optima"


def scene_store(stores, scene):
    """The store of ``scene`` among ``stores`` (by name); NotComputed when absent."""
    if scene not in stores:
        raise NotComputed(f"no store of scene {scene!r}")
    return stores[scene]


def _reduction(sd, name):
    for red in sd.reductions:
        if red["name"] == name:
            return red
    raise NotComputed(f"scene {sd.name} has no reduction {name!r}")


def grid_role_array(sd, reduction: str, role: str = "value"):
    """(DataArray of ``role`` of ``reduction``, its grid counterpart or None, polished?).

    The polished array when stored (the grid one beside it for the resolution error), else
    the grid one. ``role``: value | signed | an axis of ``over`` | a reported quantity |
    ``linear_shapes`` (1 where both power laws of the optimum are linear) | ``phi_min``,
    ``phi_max`` (A0 (1 -+ A1/A0), the span of a harmonic optimum)."""
    _reduction(sd, reduction)
    if role in ("phi_min", "phi_max"):  # a harmonic optimum: phi spans A0 (1 -+ A1/A0)
        (a0, _, polished), (r, _, _) = grid_role_array(sd, reduction, "A0"), grid_role_array(sd, reduction, "A1_ratio")
        return a0 * (1 - r) if role == "phi_min" else a0 * (1 + r), None, polished
    if role == "linear_shapes":
        arrays = [grid_role_array(sd, reduction, r) for r in ("closing_shape", "opening_shape")]
        both = (abs(arrays[0][0]) == 1) & (abs(arrays[1][0]) == 1)
        return both.astype(float).where(arrays[0][0].notnull()), None, arrays[0][2]
    suffix = "" if role == "value" else f"_{role}"
    polished, grid = f"{reduction}_polished{suffix}", f"{reduction}{suffix}"
    if polished in sd.ds:
        return sd.ds[polished], (sd.ds[grid] if grid in sd.ds else None), True
    if grid in sd.ds:
        return sd.ds[grid], None, False
    raise NotComputed(f"store {sd.name} has no array {grid!r}")


def optima_role_array(sd, role: str):
    """A role of the best kept optimum per (anisotropy_ratio, max_wavenumber, p): |λ|/λub
    (``relative_efficiency``), ``scaled_period``, ``phi_max``, ``phi_min``, ``amplitude`` (half of
    max − min of φ) [rad], the number
    of distinct optima kept (``distinct``), or the number of distinct optima among the ten most
    efficient starts counted with repetition (``distinct_in_best_ten``, what the paper's figures
    draw), the share of all starts that reached the best optimum (``share_at_best``), the share
    of the starts that reached any kept optimum that reached the best (``share_of_optima_at_best``), or the
    second (``second_share``), and the second optimum's |λ|/λub (``second_relative_efficiency``)."""
    ds = sd.ds
    if "optimum_relative_efficiency" not in ds:
        raise NotComputed(f"store {sd.name} holds no kept optima")
    if role == "relative_efficiency":
        return abs(ds["optimum_relative_efficiency"].isel(rank=0))
    if role == "scaled_period":
        return ds["optimum_scaled_period"].isel(rank=0)
    if role in ("phi_max", "phi_min"):
        phi = ds["optimum_phi"].isel(rank=0)
        return phi.max("tau", skipna=False) if role == "phi_max" else phi.min("tau", skipna=False)
    if role == "amplitude":  # the stroke amplitude: half of max - min of phi over the period [rad]
        phi = ds["optimum_phi"].isel(rank=0)
        return (phi.max("tau", skipna=False) - phi.min("tau", skipna=False)) / 2
    if role == "distinct":
        kept = (ds["optimum_start"] >= 0).sum("rank")
        return kept.where(kept > 0).astype(float)
    if role in ("share_at_best", "second_share"):
        # the ensemble as the paper states it ("the same across all initializations"): the share
        # of every start of the cell (failed ones included) that reached the best kept optimum,
        # equal within the store's keep tolerances (phi_tolerance rad, period_tolerance relative);
        # or the share that reached the second-best one (its basin)
        n = ds.sizes["start"] if "start" in ds.sizes else None
        if not n:
            raise NotComputed(f"store {sd.name} has no start dimension")
        mult = ds["optimum_multiplicity"].where(ds["optimum_start"] >= 0, 0)
        k = 0 if role == "share_at_best" else 1
        share = mult.isel(rank=k).astype(float) / float(n)
        return share.where((ds["optimum_start"] >= 0).any("rank"))
    if role == "share_of_optima_at_best":
        # the starts that converged to an optimum (a kept, moving optimum: accepted, not at
        # rest), and the share of them at the best one
        mult = ds["optimum_multiplicity"].where(ds["optimum_start"] >= 0, 0)
        total = mult.sum("rank")
        return (mult.isel(rank=0).astype(float) / total.where(total > 0)).where(total > 0)
    if role == "second_relative_efficiency":
        return abs(ds["optimum_relative_efficiency"].isel(rank=1))
    if role == "distinct_in_best_ten":
        # the paper's figures: "the ten most efficient local optima (with repetition)"; the kept
        # optima are ranked by |lambda|, each reached by `multiplicity` accepted starts
        mult = ds["optimum_multiplicity"].where(ds["optimum_start"] >= 0, 0)
        before = mult.cumsum("rank") - mult
        total = mult.sum("rank")
        shown = ((mult > 0) & (before < np.minimum(total, 10))).sum("rank")
        return shown.where(total > 0).astype(float)
    raise NotComputed(f"no optima role {role!r}")


# ---------------------------------------------------------------------------
# Selection
# ---------------------------------------------------------------------------


def _index(da, dim, want):
    if dim not in da.dims:
        raise NotComputed(f"no dimension {dim!r}")
    coord = np.asarray(da[dim].values, dtype=np.float64)
    if want in ("min", "max"):
        return int(np.argmin(coord) if want == "min" else np.argmax(coord))
    hit = np.flatnonzero(np.isclose(coord, float(want), rtol=1e-6, atol=1e-12))
    if not hit.size:
        have = ", ".join(value_text(dim, c) for c in coord[:8]) + (" …" if coord.size > 8 else "")
        raise NotComputed(f"the store has no cell at {axis_name(dim)} = {value_text(dim, float(want))} "
                          f"(it has {have})")
    return int(hit[0])


def _at(da, at: dict):
    return da.isel({d: _index(da, d, v) for d, v in (at or {}).items()})


def select(da, *, at=None, cells=None, ranges=None, exclude=None, exclude_ranges=None):
    """(``da`` at ``at``, stacked over ``cells``, restricted to ``ranges``, with the cells of
    ``exclude`` and the region ``exclude_ranges`` (inclusive [lo, hi] per dimension: the cells
    inside every range, a rectangle) masked as NaN; the number of masked cells)."""
    import xarray as xr

    excluded = 0
    da = _at(da, at)
    if cells:
        da = xr.concat([_at(da, c) for c in cells], dim="cell", coords="all")
    for d, (lo, hi) in (ranges or {}).items():
        if d not in da.dims:
            raise NotComputed(f"no dimension {d!r}")
        keep = np.flatnonzero((da[d].values >= lo) & (da[d].values <= hi))
        if not keep.size:
            raise NotComputed(f"the store has no cell with {axis_name(d)} in [{lo:g}, {hi:g}]")
        da = da.isel({d: keep})
    for c in exclude or []:  # masked (NaN), and not counted as failures (see _failures)
        try:
            hit = _at(da, c)
        except NotComputed:
            continue
        mask = np.ones(da.shape, dtype=bool)
        for d in c:
            shape = [1] * da.ndim
            shape[da.dims.index(d)] = -1
            mask &= (da[d].values == hit[d].values).reshape(shape)
        da = da.where(~mask)
        excluded += int(mask.sum())
    if exclude_ranges:
        mask = np.ones(da.shape, dtype=bool)
        for d, (lo, hi) in exclude_ranges.items():
            if d not in da.dims:
                raise NotComputed(f"no dimension {d!r}")
            shape = [1] * da.ndim
            shape[da.dims.index(d)] = -1
            c = np.asarray(da[d].values, dtype=np.float64)
            mask &= ((c >= lo) & (c <= hi)).reshape(shape)
        da = da.where(~mask)
        excluded += int(mask.sum())
    return da, excluded


def _where(da, index=None) -> str:
    """The coordinates of a cell (``index`` into ``da``'s flattened values) in words."""
    cell = da if index is None else da.isel(dict(zip(da.dims, np.unravel_index(index, da.shape))))
    parts = []
    for name, c in cell.coords.items():
        if c.ndim == 0 and name in _AXIS_NAMES:
            parts.append(f"{axis_name(name)} = {value_text(name, float(c.values))}")
    return ", ".join(parts)


def _collapse(da, statistic: str, test=None, location=None):
    """(value, where, index of the cell or None) of ``statistic`` over every cell of ``da``."""
    v = np.asarray(da.values, dtype=np.float64).ravel()
    ok = np.isfinite(v)
    n = v.size
    if statistic == "only":
        if n != 1:
            raise NotComputed(f"{n} cells selected where the claim needs one")
        return float(v[0]), _where(da, 0), 0
    if not ok.any():
        return math.nan, f"{n} cells, none valid", None
    if statistic in ("max", "min"):
        i = int(np.nanargmax(v) if statistic == "max" else np.nanargmin(v))
        if location:
            cell = da.isel(dict(zip(da.dims, np.unravel_index(i, da.shape))))
            return float(cell[location].values), _where(da, i), i
        return float(v[i]), _where(da, i), i
    if statistic == "median":
        return float(np.median(v[ok])), f"median over {ok.sum()} cells", None
    if statistic == "range":
        return (float(v[ok].min()), float(v[ok].max())), f"over {ok.sum()} cells", None
    if statistic == "spread":
        lo, hi = int(np.nanargmin(v)), int(np.nanargmax(v))
        return (float(v[hi] - v[lo]), f"largest {v[hi]:.3g} ({_where(da, hi)}) minus smallest {v[lo]:.3g} "
                                      f"({_where(da, lo)}), over {ok.sum()} cells", None)
    if statistic == "fraction":
        passed = _test(v[ok], test or {})
        return float(np.mean(passed)), f"{int(passed.sum())} of {ok.sum()} cells", None
    raise NotComputed(f"unknown statistic {statistic!r}")


def _test(v, test: dict) -> np.ndarray:
    """Cells passing every bound of ``test``: min, max, between [a, b], outside [a, b]."""
    passed = np.ones(v.shape, dtype=bool)
    if "min" in test:
        passed &= v >= test["min"]
    if "max" in test:
        passed &= v <= test["max"]
    if "between" in test:
        a, b = test["between"]
        passed &= (v >= a) & (v <= b)
    if "outside" in test:
        a, b = test["outside"]
        passed &= (v < a) | (v > b)
    return passed


def _location_along(da, dim):
    """The coordinate of the maximum along ``dim``, per remaining cell."""
    filled = da.fillna(-np.inf)
    idx = filled.argmax(dim)
    loc = da[dim].isel({dim: idx}).drop_vars(dim, errors="ignore")
    return loc.where(np.isfinite(filled.max(dim)))


# ---------------------------------------------------------------------------
# Resolution, error and edges
# ---------------------------------------------------------------------------


def _grid_text(sd, dims) -> str:
    return " × ".join(f"{axis_name(d)} {sd.ds.sizes[d]}" for d in dims if d in sd.ds.sizes)


def _continuous_argmax_axes(sd, reduction) -> list[str]:
    """The axes ``reduction`` maximises over that are continuous coordinates of the store (the
    shape switches of power-law motions excluded): those whose arg-max can sit at a range end."""
    return [ax for ax in _reduction(sd, reduction).get("over", [])
            if ax in sd.ds.coords and ax not in ("closing_shape", "opening_shape")]


def _edges(sd, reduction, cell_sel) -> tuple:
    """Continuous arg-max axes of ``reduction`` at an end of their scanned range in the cell."""
    out = []
    for ax in _continuous_argmax_axes(sd, reduction):
        flag = f"{reduction}_polished_{ax}_edge"
        if flag in sd.ds:  # the polish record says which end of the polish domain (issue 44)
            try:
                f = float(np.asarray(cell_sel(sd.ds[flag]).values).ravel()[0])
                arg = float(np.asarray(cell_sel(grid_role_array(sd, reduction, ax)[0]).values).ravel()[0])
            except (NotComputed, IndexError, ValueError):
                continue
            if f:
                out.append(f"{axis_name(ax)} at the {'lower' if f < 0 else 'upper'} end of the polish domain "
                           f"({arg:.3g}; {flag})")
            continue
        try:
            arg_da, _, _ = grid_role_array(sd, reduction, ax)
            arg = float(np.asarray(cell_sel(arg_da).values).ravel()[0])
        except (NotComputed, IndexError, ValueError):
            continue
        coord = np.asarray(sd.ds[ax].values, dtype=np.float64)
        span = float(coord.max() - coord.min()) or 1.0
        for end, bound in (("lower", coord.min()), ("upper", coord.max())):
            if abs(arg - bound) <= 1e-6 * span:
                out.append(f"{axis_name(ax)} at the {end} end of its scanned range ({arg:.3g})")
    return tuple(out)


def _edge_shares(sd, reduction, sel) -> tuple:
    """For a statistic over many cells: per continuous arg-max axis, how many of the selected
    cells have their optimum at an end of the scanned range (said in the verdict)."""
    out = []
    for ax in _continuous_argmax_axes(sd, reduction):
        flag = f"{reduction}_polished_{ax}_edge"
        if flag in sd.ds:  # the polish record (issue 44)
            try:
                f = np.asarray(sel(sd.ds[flag]).values, dtype=np.float64).ravel()
            except (NotComputed, IndexError, ValueError, KeyError):
                continue
            f = f[np.isfinite(f)]
            for end, sign in (("lower", -1), ("upper", 1)):
                k = int(np.sum(f == sign))
                if k:
                    out.append(f"{axis_name(ax)} at the {end} end of the polish domain in {k} of {f.size} cells")
            continue
        try:
            arg = np.asarray(sel(grid_role_array(sd, reduction, ax)[0]).values, dtype=np.float64).ravel()
        except (NotComputed, IndexError, ValueError, KeyError):
            continue
        arg = arg[np.isfinite(arg)]
        coord = np.asarray(sd.ds[ax].values, dtype=np.float64)
        span = float(coord.max() - coord.min()) or 1.0
        for end, bound in (("lower", coord.min()), ("upper", coord.max())):
            k = int(np.sum(np.abs(arg - bound) <= 1e-6 * span))
            if k:
                out.append(f"{axis_name(ax)} at the {end} end of its scanned range ({bound:.3g}) in {k} of {arg.size} cells")
    return tuple(out)


def _cell(arr, index):
    """Cell ``index`` (into the flattened values) of ``arr``; ``arr`` itself when it is one cell."""
    if index is None or arr.size <= 1:
        return arr
    return arr.isel(dict(zip(arr.dims, np.unravel_index(index, arr.shape))))


def _polish_change(m: Measurement, selected, grid_selected, index):
    """Our error estimate of a polished optimum: how far polishing moved it from the grid's."""
    p, g = np.asarray(selected.values, float), np.asarray(grid_selected.values, float)
    with np.errstate(invalid="ignore", divide="ignore"):
        change = np.abs(p - g)
        rel = change / np.abs(p)
    if index is not None:
        change, rel = change.ravel()[index], rel.ravel()[index]
    elif np.isfinite(change).any():
        change, rel = np.nanmax(change), np.nanmax(rel)
    else:
        return
    if np.isfinite(change):
        m.error_value = float(change)
        m.error = f"grid→polished change {change:.2g}" + (f" ({100 * rel:.2g} %)" if np.isfinite(rel) else "")


def _neighbour_spread(da, index, dims) -> tuple[float, str]:
    """Largest change of ``da`` from cell ``index`` to its neighbours along the sampled ``dims``
    (how much an extremum can hide between samples), and the sampling in words."""
    ix = np.unravel_index(index, da.shape)
    v0 = float(da.values[ix])
    spread, words = 0.0, []
    for d in dims:
        if d not in da.dims or da.sizes[d] < 2:
            continue
        k = da.dims.index(d)
        for step in (-1, 1):
            j = list(ix)
            j[k] += step
            if 0 <= j[k] < da.shape[k] and np.isfinite(da.values[tuple(j)]):
                spread = max(spread, abs(float(da.values[tuple(j)]) - v0))
        coord = np.asarray(da[d].values, dtype=np.float64)
        log = bool(np.all(coord > 0)) and d in ("anisotropy_ratio", "scaled_period", "T2_mu_n", "T2_mu_s")
        step_v = float(np.min(np.diff(np.log2(coord) if log else coord)))
        words.append(f"{axis_name(d)} sampled in steps of " + (f"2^{step_v:g}" if log else f"{step_v:.3g}"))
    return spread, ", ".join(words)


def _neighbour_coords(da, index, dim) -> list[float]:
    """The coordinates one grid step either side of the located one."""
    if dim not in da.dims:
        return []
    k = da.dims.index(dim)
    i = np.unravel_index(index, da.shape)[k]
    coord = np.asarray(da[dim].values, dtype=np.float64)
    return [float(coord[j]) for j in (i - 1, i + 1) if 0 <= j < coord.size]


def _failures(da, excluded: int = 0) -> tuple:
    """(cells without a valid value, cells selected), the ``excluded`` (masked) cells left out."""
    v = np.asarray(da.values, dtype=np.float64)
    return int(np.count_nonzero(~np.isfinite(v))) - excluded, int(v.size) - excluded


# ---------------------------------------------------------------------------
# The reductions named in claims.toml
# ---------------------------------------------------------------------------


#: ``{r}_polished_status`` (contract of issue 44): -1 not computed, 0 converged, 1 cap reached,
#: 2 no valid solve; the store's own ``flag_values`` / ``flag_meanings`` attributes name them when present
POLISH_STATUS = {-1: "not computed", 0: "converged", 1: "cap reached, not converged", 2: "solve failed or no valid start"}


def _worst_status(a, dims):
    """``a`` (a status array) reduced over ``dims`` to the status of largest magnitude: a peak or a
    location reads every cell of those dimensions, so any cell not converged (-1, 1, 2) shows."""
    for d in dims:
        a = a.reduce(lambda x, axis: np.take_along_axis(
            x, np.expand_dims(np.argmax(np.abs(x), axis=axis), axis), axis).squeeze(axis), dim=d)
    return a


def polish_record(sd, reduction):
    """(status, uncertainty) arrays of a polished reduction's record, each None when the store
    holds none (a store polished before issue 44)."""
    st, un = f"{reduction}_polished_status", f"{reduction}_polished_uncertainty"
    return (sd.ds[st] if st in sd.ds else None), (sd.ds[un] if un in sd.ds else None)


def _status_names(status) -> dict:
    names = dict(POLISH_STATUS)
    values, meanings = status.attrs.get("flag_values"), status.attrs.get("flag_meanings")
    if values is not None and meanings:
        words = meanings.split() if isinstance(meanings, str) else list(meanings)
        if len(words) == len(np.atleast_1d(values)):
            names.update({int(k): str(w).replace("_", " ") for k, w in zip(np.atleast_1d(values), words)})
    return names


def _status_words(status) -> str:
    """Why the data cannot decide, from the selected polish statuses ("" when all are 0)."""
    names = _status_names(status)
    v = np.asarray(status.values).ravel()
    v = v[np.isfinite(v.astype(np.float64))].astype(int)
    bad = v[v != 0]
    if not bad.size:
        return ""
    kinds = ", ".join(f"{int((bad == k).sum())} {names.get(int(k), f'status {int(k)}')}"
                      for k in sorted(set(bad.tolist())))
    return (f"cannot judge: {bad.size} of {v.size} selected polished optima did not converge ({kinds}; "
            "_polished_status ≠ 0)")


@dataclass
class _Source:
    sd: object
    da: object            # the selected array
    sel: object           # the selection, for other arrays of the same store
    grid: object = None   # the selected grid counterpart of a polished array
    polished: bool = False
    excluded: int = 0
    status: object = None       # the selected polish status (the worst over a peak), or None
    uncertainty: object = None  # the selected relative uncertainty of the polished value, or None


def _selected(stores, scene, *, reduction=None, role="value", quantity=None, absolute=False, at=None, cells=None,
              ranges=None, exclude=None, exclude_ranges=None, peak_over=(), location_along=None,
              grid=False, tau0_window=None) -> _Source:
    """The selected array of one claim source (see the module docstring); ``grid``: the grid
    optimum even where a polished one is stored (what the grid alone resolves);
    ``tau0_window``: the τ0 window's half-width (the paper's domain is 0.45)."""
    sd = scene_store(stores, scene)
    if tau0_window is not None:
        dim = "duty_cycle_halfwidth"
        if reduction is None or dim not in sd.ds.dims:
            raise NotComputed(f"store {sd.name} has no τ0 window {tau0_window:g} (dimension {dim}: the scene's "
                              "reductions are not repeated over τ0 windows; issue 44: rerun after the polish merge)")
        at = {**(at or {}), dim: tau0_window}
    grid_da, polished = None, False
    if reduction is not None:
        da, grid_da, polished = grid_role_array(sd, reduction, role)
        if grid and polished:
            if grid_da is None:
                raise NotComputed(f"store {sd.name} has no grid {role!r} of {reduction!r}")
            da, grid_da, polished = grid_da, None, False
    elif quantity is not None:
        if quantity not in sd.ds:
            raise NotComputed(f"store {sd.name} has no quantity {quantity!r}")
        da = sd.ds[quantity]
        if "status" in sd.ds:
            da = da.where(sd.ds["status"] == 0)
    else:
        da = optima_role_array(sd, role)
    if absolute:
        da = abs(da)
        grid_da = abs(grid_da) if grid_da is not None else None

    def sel(arr):
        a, _ = select(arr, at=at, cells=cells, ranges=ranges, exclude=exclude, exclude_ranges=exclude_ranges)
        for d in peak_over:
            a = a.max(d)
        if location_along:
            a = _location_along(a, location_along)
        return a

    def sel_cells(arr, status=False):  # the record of the cells a peak or a location reads: worst / largest
        a, _ = select(arr, at=at, cells=cells, ranges=ranges, exclude=exclude, exclude_ranges=exclude_ranges)
        dims = [*peak_over, *([location_along] if location_along else [])]
        if status:
            return _worst_status(a, dims)
        for d in dims:
            a = a.max(d)
        return a

    excluded = (select(da, at=at, cells=cells, ranges=ranges, exclude=exclude, exclude_ranges=exclude_ranges)[1]
                if exclude or exclude_ranges else 0)
    # a peak or a located coordinate has no grid counterpart of the same meaning
    grid = sel(grid_da) if grid_da is not None and not peak_over and not location_along else None
    status = uncertainty = None
    if polished and reduction is not None:
        st, un = polish_record(sd, reduction)
        status = sel_cells(st, status=True) if st is not None else None
        uncertainty = sel_cells(un) if un is not None else None
    return _Source(sd, sel(da), sel, grid, polished, excluded, status, uncertainty)


def _apply_record(m: Measurement, *sources, index=None) -> None:
    """The polish record of the sources read (issue 44): ``cannot_judge`` when a selected
    polished optimum did not converge; the error estimate from the relative uncertainties (of
    cell ``index`` of a single source, else the largest over the selected cells, summed over the
    sides of a ratio) where every source stores one."""
    why = [(s.sd.name, w) for s, w in ((s, _status_words(s.status)) for s in sources if s.status is not None) if w]
    if len(why) == 1:
        m.cannot_judge = why[0][1]
    elif why:  # the sides of a ratio: one sentence, each side named
        m.cannot_judge = "cannot judge: " + "; ".join(
            f"side {k + 1} ({name}): {w.removeprefix('cannot judge: ')}" for k, (name, w) in enumerate(why))
    if not sources or any(s.uncertainty is None for s in sources) or not isinstance(m.value, float):
        return
    rel = 0.0
    for s in sources:
        u = np.asarray(s.uncertainty.values, dtype=np.float64)
        if index is not None and u.size > 1 and len(sources) == 1:
            u = u.ravel()[index: index + 1]
        if not np.isfinite(u).any():
            return
        rel += float(np.nanmax(np.abs(u)))
    if math.isfinite(m.value):
        m.error_value = rel * abs(m.value)
        m.error = f"polish uncertainty {rel:.2g} (relative; the polish record)"


_SAMPLED = ("anisotropy_ratio", "scaled_period")


def stat(stores, *, scene, statistic="only", test=None, location=None, where_best=None, **source) -> Measurement:
    """One value of a store (see the module docstring for the selection). ``where_best``: the
    value of ``role`` at the cell where role ``where_best`` of the same selection is largest
    (e.g. A1/A0 at the peak relative efficiency of a regime)."""
    if where_best is not None:
        return _at_best(stores, scene, where_best, source)
    src = _selected(stores, scene, **source)
    sd, da = src.sd, src.da
    value, where, index = _collapse(da, statistic, test, location)
    m = Measurement(value=value, where=where, failed=_failures(da, src.excluded))
    if statistic in ("max", "min") and index is not None and not location:
        m.edges = _period_edge(da, index)
    counted = statistic == "fraction" or source.get("location_along") or location
    reduction = source.get("reduction")
    if reduction:
        red = _reduction(sd, reduction)
        over = [a for a in red.get("over", []) if a in sd.ds.sizes]
        m.resolution = (_grid_text(sd, over) + (", polished optimum" if src.polished else ", grid optimum")
                        + f"; solver rtol {sd.rtol:g}")
        if src.grid is not None and not counted:
            _polish_change(m, da, src.grid, index)
        if not counted:
            _apply_record(m, src, index=index)
        elif src.status is not None:
            m.cannot_judge = _status_words(src.status)
        role = source.get("role", "value")
        if not src.polished and role in over and not counted:
            coord = np.asarray(sd.ds[role].values, dtype=np.float64)
            step = float(np.min(np.diff(coord)))
            m.error, m.error_value = f"grid optimum: {axis_name(role)} within one grid step ({step:.3g})", step
        if index is not None or statistic == "only":
            m.edges = tuple(m.edges) + _edges(sd, reduction, lambda arr: _cell(src.sel(arr), index))
        elif not source.get("peak_over"):
            m.edges = _edge_shares(sd, reduction, src.sel)
    elif source.get("quantity"):
        m.resolution = _grid_text(sd, sd.dims) + f"; solver rtol {sd.rtol:g}"
        m.error = f"solver rtol {sd.rtol:g}"
    else:
        m.resolution, m.error = _optima_resolution(sd)
        if source.get("role") == "share_at_best" and index is not None and math.isfinite(value) and value < 1:
            m.where += "; " + _basins(sd, _cell(da, index))
        if not counted and isinstance(value, float) and math.isfinite(value):
            m.error_value = abs(value) * float(sd.science.get("optimizer", {}).get("grid_rtol", math.nan))
    is_axis = reduction and source.get("role", "value") in _reduction(sd, reduction).get("over", [])
    if statistic in ("max", "min") and index is not None and not is_axis and not source.get("location_along"):
        if location:
            m.neighbours = _neighbour_coords(da, index, location)
            m.coarse = f"{axis_name(location)} located on its grid"
            if m.neighbours:  # the shared rule "grid": a located coordinate is known to one step
                m.error_value = max(abs(n - value) for n in m.neighbours)
                m.error = f"{axis_name(location)} located on its grid: within one step ({m.error_value:.3g})"
        else:
            spread, words = _neighbour_spread(da, index, _SAMPLED)
            if words:
                m.coarse, m.coarse_value = f"the {statistic} over {words}; its neighbours differ by {spread:.2g}", spread
            gap = _unsampled_end(da, index, source.get("ranges") or {})
            if gap:
                m.coarse, m.coarse_value = gap, math.inf
            # a finer sampling can only raise a maximum (lower a minimum)
            m.coarse_side = "below" if statistic == "max" else "above"
    return m


def _period_edge(da, index) -> tuple:
    """An extremum over the periods at our shortest or longest sampled period: a supremum over
    our period range (issue 44, REREADING44 P6), said in the verdict."""
    if "scaled_period" not in da.dims or da.sizes["scaled_period"] < 2:
        return ()
    k = da.dims.index("scaled_period")
    i = np.unravel_index(index, da.shape)[k]
    c = np.asarray(da["scaled_period"].values, dtype=np.float64)
    if i in (0, c.size - 1):
        end = "shortest" if i == 0 else "longest"
        return (f"scaled period at our {end} sample {value_text('scaled_period', c[i])}: a supremum over our "
                "period range",)
    return ()


def _at_best(stores, scene, best_role, source) -> Measurement:
    """``role`` of the cell where ``best_role`` (same selection) is largest."""
    role = source.get("role", "value")
    best = _selected(stores, scene, **{**source, "role": best_role})
    v = np.asarray(best.da.values, dtype=np.float64)
    if not np.isfinite(v).any():
        return Measurement(value=math.nan, where="no valid value")
    index = int(np.nanargmax(v))
    src = _selected(stores, scene, **source)
    value = float(np.asarray(src.da.values, dtype=np.float64).ravel()[index])
    m = Measurement(value=value, where=f"{axis_name(role) if role != 'value' else 'value'} at the largest "
                                      f"{best_role} ({v.ravel()[index]:.3g}, {_where(best.da, index)})")
    reduction = source.get("reduction")
    if reduction:
        sd = src.sd
        over = [a for a in _reduction(sd, reduction).get("over", []) if a in sd.ds.sizes]
        m.resolution = _grid_text(sd, over) + (", polished optimum" if src.polished else ", grid optimum")
        m.edges = _period_edge(best.da, index) + _edges(sd, reduction, lambda arr: _cell(src.sel(arr), index))
        _apply_record(m, _without_uncertainty(src), index=index)
    return m


def _unsampled_end(da, index, ranges) -> str:
    """When the extremum sits at the last sample of a claim's range that the grid does not reach
    (e.g. μn/μs in [2^-7, 1) sampled from 2^-6 on), the unsampled stretch in words."""
    ix = np.unravel_index(index, da.shape)
    for d, (lo, hi) in ranges.items():
        if d not in da.dims or d not in _SAMPLED:
            continue
        k = da.dims.index(d)
        coord = np.asarray(da[d].values, dtype=np.float64)
        c = coord[ix[k]]
        for end, bound, at_end in (("lower", lo, ix[k] == 0), ("upper", hi, ix[k] == coord.size - 1)):
            if at_end and bound > 0 and math.isfinite(bound) and abs(math.log2(c / bound)) > 0.05:
                return (f"the extremum is at our {end}most sample {value_text(d, c)} of the claim's range, which "
                        f"extends to {value_text(d, bound)}: the grid does not sample that end")
    return ""


def _basins(sd, cell) -> str:
    """The starts of ``cell`` (a one-cell selection) that did not reach its best optimum, in
    words: how many reached each other kept optimum (its basin's share) and its |λ|/λub, and how
    many reached none kept (failed, or not accepted)."""
    ds = sd.ds
    n = ds.sizes["start"]
    at = {d: cell[d].values.item() for d in ("anisotropy_ratio", "max_wavenumber", "p") if d in cell.coords}
    mult = np.asarray(ds["optimum_multiplicity"].where(ds["optimum_start"] >= 0, 0).sel(at).values).ravel()
    rel = np.asarray(abs(ds["optimum_relative_efficiency"]).sel(at).values).ravel()
    others = [f"{int(k)} at |λ|/λub {r:.3g} ({100 * (1 - r / rel[0]):.0f} % below the best)"
              for k, r in zip(mult[1:], rel[1:]) if k > 0]
    lost = n - int(mult.sum())
    return (f"{int(mult[0])} of {n} starts at the best optimum (|λ|/λub {rel[0]:.3g})"
            + (f"; other optima: {', '.join(others)}" if others else "")
            + (f"; {lost} starts at no kept optimum (stopped, not accepted, or at rest)" if lost else ""))


def _optima_resolution(sd):
    sc = sd.science
    ratios = np.asarray(sd.ds["anisotropy_ratio"].values, dtype=np.float64)
    step = float(np.min(np.diff(np.log2(ratios)))) if ratios.size > 1 else math.nan
    opt = sc.get("optimizer", {})
    convention = ("the paper's convention (signed λ minimised)" if opt.get("direction") == "negative"
                  else "|λ| maximised in each start's direction")
    return (f"{sc.get('starts', {}).get('num', '?')} random starts per cell; μn/μs in steps of 2^{step:g}; "
            f"best of the kept distinct optima; {convention}",
            f"gradient norm ≤ {opt.get('gtol', '?')}, τ grid rtol {opt.get('grid_rtol', '?')}")


def gain(stores, *, numerator: dict, denominator: dict, statistic="only", test=None) -> Measurement:
    """The ratio numerator / denominator of two selections (of one or two stores), cell by cell
    over their shared coordinates (a collapsed side broadcasts), then ``statistic``."""
    import xarray as xr

    [(sa, a, pa), (sb, b, pb)], excluded, unpolished, srcs = _aligned_sides(stores, numerator, denominator)
    with np.errstate(invalid="ignore", divide="ignore"):
        r = a / b
    if test and test.get("figure_equal"):
        r = xr.where(_figure_equal(a, b), 1.0, 0.0).where(np.isfinite(r))
        test = {"min": 1.0}
    value, where, index = _collapse(r, statistic, test)
    m = Measurement(value=value, where=where, failed=_failures(r, excluded))
    m.resolution = _sides_resolution((sa, pa), (sb, pb))
    m.error = "ratio of two optima, each within its own resolution"
    if unpolished:  # a ratio of grid optima: the grid's error is not bounded by anything stored
        m.coarse, m.coarse_value = "; ".join(dict.fromkeys(unpolished)) + ", an error we cannot bound", math.inf
    if statistic in ("only", "max", "min", "median") and not test:
        _apply_record(m, *srcs)
    else:  # a share of cells: the record decides only whether the cells can be judged
        _apply_record(m, *[_without_uncertainty(x) for x in srcs])
    return m


def _without_uncertainty(src: _Source) -> _Source:
    return _Source(src.sd, src.da, src.sel, src.grid, src.polished, src.excluded, src.status, None)


def _figure_equal(a, b):
    """The shared rule "figure" (reports/CAUSES.md): a and b equal to two significant digits,
    |a - b| <= half a unit in the second significant digit of the larger (elementwise)."""
    big = np.maximum(abs(a), abs(b))
    with np.errstate(invalid="ignore", divide="ignore"):
        half = 0.5 * 10.0 ** (np.floor(np.log10(big)) - 1)
    return abs(a - b) <= half


def _sides_resolution(*sides) -> str:
    res = []
    for sd, pol in sides:
        if sd.meta.get("kind", "grid") == "optima":
            res.append(f"{sd.name}: " + _optima_resolution(sd)[0])
        else:
            res.append(f"{sd.name}: rtol {sd.rtol:g}, " + ("polished optima" if pol else "grid optima"))
    return "; ".join(dict.fromkeys(res))


def _aligned_sides(stores, *sides):
    """The selected arrays of two or more selections (gain's sides), aligned on the coordinates
    they share (a side collapsed by its own ``statistic`` broadcasts): ([(store, array,
    polished)], masked cells, notes on unpolished grid optima, the sides' sources (their polish
    records))."""
    import xarray as xr

    parts, excluded, unpolished, sources = [], 0, [], []
    for side in sides:
        side = dict(side)
        scene = side.pop("scene")
        side_stat = side.pop("statistic", None)
        src = _selected(stores, scene, **side)
        sources.append(src)
        sd, da, polished = src.sd, src.da, src.polished
        excluded = max(excluded, src.excluded)
        if side.get("reduction") and not polished:
            over = [a for a in _reduction(sd, side["reduction"]).get("over", []) if a in sd.ds.sizes]
            unpolished.append(f"{sd.name}: grid optima over {_grid_text(sd, over)}, not polished")
        if side_stat:
            v, _, _ = _collapse(da, side_stat)
            da = xr.DataArray(v)
        parts.append((sd, da, polished))
    arrays = [p[1] for p in parts]
    for k in range(1, len(arrays)):  # align every side with the first on the coordinates both hold
        a, b = arrays[0], arrays[k]
        for d in [d for d in a.dims if d in b.dims]:
            common = np.intersect1d(np.round(a[d].values, 9), np.round(b[d].values, 9))
            if not common.size:
                raise NotComputed(f"the two selections share no {axis_name(d)}")
            a = a.isel({d: np.flatnonzero(np.isin(np.round(a[d].values, 9), common))})
            b = b.isel({d: np.flatnonzero(np.isin(np.round(b[d].values, 9), common))})
            b = b.assign_coords({d: a[d].values})
        arrays[0], arrays[k] = a, b
    for k in range(1, len(arrays)):  # the first side's alignment may have narrowed after side k
        arrays[k] = arrays[k].sel({d: arrays[0][d].values for d in arrays[k].dims if d in arrays[0].dims})
    a = arrays[0]
    extra_a = [c for c in a.coords if c not in a.dims and all(c in b.coords and c not in b.dims for b in arrays[1:])]
    arrays[0] = a.drop_vars(extra_a, errors="ignore")
    for k in range(1, len(arrays)):
        arrays[k] = arrays[k].drop_vars([c for c in arrays[k].coords if c not in arrays[k].dims], errors="ignore")
    return [(p[0], arr, p[2]) for p, arr in zip(parts, arrays)], excluded, unpolished, sources


def monotone(stores, *, along: str, scene=None, numerator=None, denominator=None, direction="increasing",
             slack=0.0, tie=None, dims=None, **source) -> Measurement:
    """Share of adjacent pairs along ``along`` (or each of ``dims``) that do not decrease
    (``increasing``) or increase (``decreasing``) by more than ``slack`` (relative); with
    ``tie = "figure"`` a pair equal to two significant digits (the shared rule "figure") is a
    tie, which counts as not going the other way. The array is one selection (``scene`` and
    its source arguments) or the ratio ``numerator / denominator`` of two (as for :func:`gain`,
    e.g. a gain along the period axis)."""
    if numerator is not None:
        if scene is not None or denominator is None:
            raise NotComputed("monotone takes a scene, or a numerator and a denominator")
        [(sd, a, pa), (sb, b, pb)], excluded, unpolished, srcs = _aligned_sides(stores, numerator, denominator)
        with np.errstate(invalid="ignore", divide="ignore"):
            da = a / b
        source = {}
    else:
        src = _selected(stores, scene, **source)
        sd, da, excluded, srcs = src.sd, src.da, src.excluded, [src]
    shares, pairs, against = [], 0, []
    for d in dims or [along]:
        dt = da.transpose(*[x for x in da.dims if x != d], d)
        v = np.asarray(dt.values, dtype=np.float64)
        step = np.diff(v, axis=-1)
        if direction == "decreasing":
            step = -step
        scale = np.maximum(np.abs(v[..., 1:]), np.abs(v[..., :-1]))
        ok = np.isfinite(step)
        good = step >= -slack * scale
        if tie == "figure":
            good |= np.asarray(_figure_equal(v[..., 1:], v[..., :-1]))
        elif tie is not None:
            raise NotComputed(f"unknown tie rule {tie!r}")
        shares.append(np.mean(good[ok]) if ok.any() else math.nan)
        pairs += int(ok.sum())
        bad = ok & ~good
        if bad.any():  # the pairs that go the other way: how many, and the largest (relative) of them
            with np.errstate(invalid="ignore", divide="ignore"):
                rel = np.where(bad, -step / np.where(scale > 0, scale, np.inf), -np.inf)
            ix = np.unravel_index(int(np.argmax(rel)), rel.shape)
            cell = dt.isel({x: i for x, i in zip(dt.dims[:-1], ix[:-1])})
            at = _where(cell)
            c = np.asarray(dt[d].values, dtype=np.float64)
            against.append(f"{int(bad.sum())} of {int(ok.sum())} pairs along {axis_name(d)} go the other way, the "
                           f"largest {v[ix[:-1]][ix[-1]]:.4g} → {v[ix[:-1]][ix[-1] + 1]:.4g} ({100 * rel[ix]:.2g} %) "
                           f"from {axis_name(d)} = {value_text(d, c[ix[-1]])} to {value_text(d, c[ix[-1] + 1])}"
                           + (f" at {at}" if at else ""))
    # an axis without a pair (one sample in the selection) says nothing either way
    value = float(np.nanmin(shares)) if np.isfinite(shares).any() else math.nan
    m = Measurement(value=value, where=f"{pairs} adjacent pairs along "
                    + ", ".join(axis_name(d) for d in dims or [along]) + ("; " + "; ".join(against) if against else ""),
                    failed=_failures(da, excluded))
    # a share of n pairs is resolved to one pair (the shared rule "grid": one step of what is counted)
    share_error = 1.0 / pairs if pairs else math.nan
    if numerator is not None:
        m.resolution = _sides_resolution((sd, pa), (sb, pb))
        m.error = "ratio of two optima, each within its own resolution"
        if unpolished:
            m.coarse, m.coarse_value = "; ".join(dict.fromkeys(unpolished)) + ", an error we cannot bound", math.inf
    elif source.get("quantity"):
        m.resolution = _grid_text(sd, sd.dims) + f"; solver rtol {sd.rtol:g}"
        m.error = f"solver rtol {sd.rtol:g}"
    elif source.get("reduction"):
        red = _reduction(sd, source["reduction"])
        m.resolution = _grid_text(sd, [a for a in red.get("over", []) if a in sd.ds.sizes])
    else:
        m.resolution, m.error = _optima_resolution(sd)
    m.error = (m.error + "; " if m.error else "") + f"a share of {pairs} pairs: one pair is {share_error:.2g}"
    m.error_value = share_error
    _apply_record(m, *[_without_uncertainty(x) for x in srcs])
    return m


def harmonic_phi_span(stores, *, scene, reduction, statistic="max", **select_args) -> Measurement:
    """(min, max) of φ = A0 + A1 cos 2πτ over a period, A0 ± A1, at the optimum of the cell
    where ``reduction`` is ``statistic`` (its polished arg-max where stored)."""
    sd = scene_store(stores, scene)
    value, _, _ = grid_role_array(sd, reduction, "value")
    a0, _, polished = grid_role_array(sd, reduction, "A0")
    ratio, _, _ = grid_role_array(sd, reduction, "A1_ratio")
    v, _ = select(value, **select_args)
    _, where, index = _collapse(v, statistic)
    pick = (lambda arr: float(np.asarray(select(arr, **select_args)[0].values).ravel()[index]))
    A0, r = pick(a0), pick(ratio)
    m = Measurement(value=(A0 * (1 - r), A0 * (1 + r)), where=where + f" (A0 = {A0:.3g}, A1/A0 = {r:.3g})")
    red = _reduction(sd, reduction)
    m.resolution = _grid_text(sd, red.get("over", [])) + (", polished optimum" if polished else ", grid optimum")
    step = float(np.min(np.diff(sd.ds["A0"].values)))
    # the compass polish stops at 1/64 of a grid spacing (pipeline._reduce)
    m.error = f"grid spacing of A0 {step:.2g} rad" + (" (polished to 1/64 of it)" if polished else "")
    m.error_value = step / 64 if polished else step

    def cell_sel(arr):
        a, _ = select(arr, **select_args)
        return a.isel(dict(zip(a.dims, np.unravel_index(index, a.shape)))) if a.size > 1 else a
    m.edges = _edges(sd, reduction, cell_sel)
    status, _ = polish_record(sd, reduction)
    if polished and status is not None:  # the polish record (issue 44): the optimum read must have converged
        m.cannot_judge = _status_words(cell_sel(status))
    return m


def improvement_share(stores, *, base: dict, partial: dict, full: dict, statistic="fraction", test=None) -> Measurement:
    """Per cell, the share of the improvement from ``base`` to ``full`` that ``partial`` already
    reaches, (partial − base) / (full − base) (three selections of nested families, aligned as
    for :func:`gain`), over the cells where the improvement shows on a figure (``full`` and
    ``base`` not equal to two significant digits, the shared rule "figure"); then ``statistic``
    (e.g. the share of those cells where ``partial`` reaches more than half, "most of the
    improvement")."""
    [(sa, b, pa), (sp, p, pp), (sf, f, pf)], excluded, unpolished, srcs = _aligned_sides(stores, base, partial, full)
    shows = ~np.asarray(_figure_equal(f, b)) & np.isfinite(np.asarray(f - b, dtype=np.float64))
    with np.errstate(invalid="ignore", divide="ignore"):
        share = ((p - b) / (f - b)).where(shows)
    value, where, _ = _collapse(share, statistic, test)
    n_cells = int(np.asarray(np.isfinite(f - b)).sum())
    m = Measurement(value=value, where=f"{where}; {int(shows.sum())} of {n_cells} cells show an improvement "
                                       "(the others equal to two significant digits)",
                    failed=_failures(f - b, excluded))
    m.resolution = _sides_resolution((sa, pa), (sp, pp), (sf, pf))
    m.error = "shares of differences of optima, each within its own resolution"
    if unpolished:
        m.coarse, m.coarse_value = "; ".join(dict.fromkeys(unpolished)) + ", an error we cannot bound", math.inf
    _apply_record(m, *[_without_uncertainty(x) for x in srcs])
    return m


def switched(stores, *, scene: str, quantity: str, at: dict, change: dict, absolute=True) -> Measurement:
    """The factor by which one change of a motion's law reduces its value: the best |quantity|
    of the grid store ``scene`` in the slice ``at`` (over every other dimension: the "efficient
    motion" with the law ``at`` names), over |quantity| of the same grid point with the
    dimensions of ``change`` set to their new values (e.g. ``opening_shape`` 3 → −3: the
    opening stroke from concave up to concave down, all else the same). Grid values of the
    stored field (solver-converged points only)."""
    sd = scene_store(stores, scene)
    if quantity not in sd.ds:
        raise NotComputed(f"store {sd.name} has no quantity {quantity!r}")
    da = sd.ds[quantity]
    if "status" in sd.ds:
        da = da.where(sd.ds["status"] == 0)
    if absolute:
        da = abs(da)
    for d in change:
        if d not in at:
            raise NotComputed(f"the change of {axis_name(d)} needs its value before the change in 'at'")
    before = _at(da, at)
    v = np.asarray(before.values, dtype=np.float64)
    if not np.isfinite(v).any():
        return Measurement(value=math.nan, where="no valid value in the slice")
    i = int(np.nanargmax(v))
    best = before.isel(dict(zip(before.dims, np.unravel_index(i, before.shape))))
    point = {d: float(best[d].values) for d in before.dims}
    after = float(np.asarray(_at(da, {**at, **change, **point}).values))
    m = Measurement(value=float(v.ravel()[i]) / after if after else math.inf,
                    where=(f"best {float(v.ravel()[i]):.4g} at {_where(best)}; changed to "
                           + ", ".join(f"{axis_name(d)} = {value_text(d, x)}" for d, x in change.items())
                           + f": {after:.4g}"))
    m.resolution = (_grid_text(sd, before.dims) + f" (grid values, no polish); solver rtol {sd.rtol:g}")
    m.error = f"solver rtol {sd.rtol:g} of each value"
    m.error_value = 2 * sd.rtol * abs(m.value) if math.isfinite(m.value) else math.nan
    return m


def aitken_limit(v1: float, v2: float, v3: float) -> float:
    """The geometric (Aitken) extrapolation of v1, v2, v3 (v3 nearest the limit): v3 + d q/(1 − q)
    with d = v3 − v2, q = d/(v2 − v1); 0 when q ≥ 1 (a fall that does not slow reaches 0), NaN
    when the steps change sign or the middle step is 0 (no geometric trend)."""
    d, dprev = v3 - v2, v2 - v1
    if dprev == 0 or not math.isfinite(d / dprev) or d / dprev < 0:
        return math.nan
    q = d / dprev
    return 0.0 if q >= 1 else v3 + d * q / (1 - q)


def limit(stores, *, scene, along="scaled_period", toward="min", fraction_of_peak=0.1, **source) -> Measurement:
    """The shared rule "limit" (reports/CAUSES.md): "X tends to zero as ``along`` → its ``toward``
    end", per line of the selection (every other dimension): the three samples nearest that end
    fall toward it and their Aitken limit (:func:`aitken_limit`) is at most ``fraction_of_peak``
    of the line's peak over ``along``. The value: the share of lines where it holds."""
    src = _selected(stores, scene, **source)
    sd, da = src.sd, src.da
    if along not in da.dims or da.sizes[along] < 3:
        raise NotComputed(f"the limit along {axis_name(along)} needs three samples of it")
    dt = da.sortby(along, ascending=(toward == "min")).transpose(*[d for d in da.dims if d != along], along)
    v = np.asarray(dt.values, dtype=np.float64).reshape(-1, da.sizes[along])
    lines = dt.isel({along: 0}, drop=True)
    held, words, n = 0, [], 0
    for k, row in enumerate(v):
        if not np.isfinite(row[:3]).all():
            continue
        n += 1
        v3, v2, v1 = row[0], row[1], row[2]
        peak = float(np.nanmax(row))
        L = aitken_limit(v1, v2, v3)
        ok = bool(v3 < v2 < v1 and math.isfinite(L) and L <= fraction_of_peak * peak)
        held += ok
        if not ok:
            at = _where(lines, k) if lines.ndim else ""
            words.append(f"{at}: {v1:.3g}, {v2:.3g}, {v3:.3g} toward the limit, Aitken limit "
                         f"{L:.3g} vs a tenth of the peak {fraction_of_peak * peak:.3g}")
    if not n:
        return Measurement(value=math.nan, where="no line with three valid samples")
    c = np.sort(np.asarray(da[along].values, dtype=np.float64))
    ends = c[:3] if toward == "min" else c[::-1][:3]
    m = Measurement(value=held / n, where=(f"{held} of {n} lines fall toward {axis_name(along)} → {toward} with an "
                                           f"Aitken limit ≤ {fraction_of_peak:g} of the peak (samples "
                                           + ", ".join(value_text(along, x) for x in ends[::-1]) + ")"
                                           + ("; not at " + "; ".join(words[:3]) + (" …" if len(words) > 3 else "")
                                              if words else "")),
                    failed=_failures(da, src.excluded))
    m.resolution = _grid_text(sd, sd.dims) + f"; solver rtol {sd.rtol:g}"
    m.error, m.error_value = f"a share of {n} lines: one line is {1 / n:.2g}", 1.0 / n
    return m


#: The reductions a claim may name (``compute = "<key>"``).
COMPUTE = {"stat": stat, "gain": gain, "monotone": monotone, "harmonic_phi_span": harmonic_phi_span,
           "improvement_share": improvement_share, "switched": switched, "limit": limit}
