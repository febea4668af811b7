"""Generic panels driven by a store's dimensions.

* ``quantity_maps``: a stored quantity as maps over two axes (A0, A1/A0 when present), faceted
  over up to two other axes (at most ``MAX_FACET`` values each), the best value over any
  further axis.
* ``reduction_figures``: a reduction's maxima and arg-max parameters, grid and polished
  together: curves against a single kept axis, maps over a kept plane plus curves against its
  first axis, or curves against the subset dimension faceted over the plane.
* ``series_figure``: the stored u(tau).

Every function takes a :class:`~reports._read.SceneStore` and returns Plotly figures.

Maps are drawn at the screen's resolution, not the scene's: a panel carries at most
``MAX_MAP_CELLS`` cells along each axis (fewer when many panels share a figure). A finer plane is
cut into blocks of k_y x k_x cells; a quantity map draws each block's mean (``block_reduce``), a
reduction's map the cell of each block's largest maximum with its arg-max and companions
(``block_pick``); the plot's title says which, and the store keeps the full data
(``full_data_note``). The line plots, tables and the audit read the full arrays.
"""

from __future__ import annotations

import functools
import html
import math
from dataclasses import dataclass

import numpy as np

from ._figure import Figure, subplots
from ._labels import SIGNED, AxisSpec, axis_spec, format_value, param_label, quantity_label
from ._motion import params_text

__all__ = ["quantity_maps", "reduction_figures", "series_figure", "reduction_arrays", "MAX_FACET", "FINE_GRID",
           "MAX_MAP_CELLS", "MAX_LINES", "Blocks", "map_blocks", "block_reduce", "block_pick", "full_data_note"]

MAX_FACET = 4
#: Cells drawn along each axis of a map panel at most: about the pixels of a panel on a wide
#: screen (a single panel is ~1400 x 320 px). Figures of several panels get fewer (``map_blocks``).
MAX_MAP_CELLS = 400
#: Curves of one panel at most (evenly spread over the line axis, ends kept; the title says so).
MAX_LINES = 16
#: A curve of more points than this is drawn without markers: plotly.js draws each marker as an
#: SVG element, and the 96 curves of 1,000 points of a refined scene's reduction took 5.1 s to
#: draw in chromium (every other figure of that report 0.1-0.9 s); at this many points a
#: line is as fine as the screen. The paper's scenes have at most 64 points on an axis (unchanged).
MAX_MARKERS = 200
#: Grids with at least this many points along both map axes are drawn as contour maps; coarser
#: ones as heatmaps of their cells with contour lines on top.
FINE_GRID = 48
_PALETTE = ["#1f77b4", "#ff7f0e", "#2ca02c", "#d62728", "#9467bd", "#8c564b", "#e377c2", "#7f7f7f", "#bcbd22",
            "#17becf"]


@functools.lru_cache(maxsize=4096)
def _color(i: int, n: int) -> str:
    """Colour i of n along a perceptual ramp (for ordered families of curves)."""
    import plotly.colors as pc

    if n <= 1:
        return _PALETTE[0]
    return pc.sample_colorscale("Viridis", [0.9 * i / (n - 1)])[0]


def _spec(sd, dim: str) -> AxisSpec:
    spec = axis_spec(dim, sd.ds[dim].values, sd.spacing(dim), sd.p)
    sets = sd.ds[dim].attrs.get("sets") if dim == "exponent_set" else None
    if sets and len(sets) == len(spec.values):
        # Label each subset by the exponents it allows, as in figure EtaVsMinGamma.
        text = tuple("{" + ", ".join(f"{g:g}" for g in s) + "}" for s in sets)
        spec = AxisSpec(spec.name, spec.values, spec.positions, "allowed exponents |γ|", spec.kind, spec.tickvals, text)
    return spec


def _pick(n: int, k: int = MAX_FACET) -> list[int]:
    """At most k evenly spread indices of range(n), ends included."""
    if n <= k:
        return list(range(n))
    return sorted(set(int(round(x)) for x in np.linspace(0, n - 1, k)))


def _best_over(values: np.ndarray, axes: tuple[int, ...], signed: bool, name: str) -> np.ndarray:
    """The best value over ``axes``: largest |q| (keeping its sign) for signed quantities, else the max."""
    if not axes:
        return values
    v = np.moveaxis(values, axes, tuple(range(values.ndim - len(axes), values.ndim)))
    flat = v.reshape(v.shape[: values.ndim - len(axes)] + (-1,))
    if flat.shape[-1] == 0:
        return flat[..., 0]
    key = np.abs(flat) if signed else flat
    key = np.where(np.isnan(key), -np.inf, key)
    idx = np.argmax(key, axis=-1)
    out = np.take_along_axis(flat, idx[..., None], axis=-1)[..., 0]
    return np.where(np.isfinite(np.take_along_axis(key, idx[..., None], axis=-1)[..., 0]), out, np.nan)


def _layout(fig, height: int, title: str | None = None):
    fig.update_layout(height=height, margin={"t": 90 if title else 40, "l": 60, "r": 20, "b": 50},
                      title={"text": title, "font": {"size": 14}, "x": 0.01, "xanchor": "left", "y": 0.99,
                             "yanchor": "top"} if title else None,
                      hoverlabel={"align": "left"})
    return fig


def _round(a: np.ndarray, digits: int = 6) -> np.ndarray:
    """Round to ``digits`` significant figures: smaller JSON, no visible change."""
    a = np.asarray(a, dtype=np.float64)
    with np.errstate(divide="ignore", invalid="ignore"):
        mag = np.where(np.isfinite(a) & (a != 0), np.floor(np.log10(np.abs(np.where(a == 0, 1, a)))), 0)
        scale = 10.0 ** (digits - 1 - mag)
        return np.where(np.isfinite(a), np.round(a * scale) / scale, np.nan)


# ---------------------------------------------------------------------------
# Aggregation to the screen
# ---------------------------------------------------------------------------


@dataclass(frozen=True)
class Blocks:
    """How a plane of ``ny`` x ``nx`` cells is drawn: in blocks of ``ky`` x ``kx`` cells (1 x 1:
    as it is), ``my`` x ``mx`` blocks (the last ones partial)."""

    ny: int
    nx: int
    ky: int
    kx: int

    @property
    def my(self) -> int:
        return -(-self.ny // self.ky)

    @property
    def mx(self) -> int:
        return -(-self.nx // self.kx)

    @property
    def decimated(self) -> bool:
        return self.ky > 1 or self.kx > 1

    def text(self, how: str, detail: str = "") -> str:
        """``"drawn at 334 × 334 of 1,000 × 1,000 cells: block mean over blocks of 3 × 3"`` and
        ``detail`` in parentheses ('' when not decimated)."""
        if not self.decimated:
            return ""
        return (f"drawn at {self.my:,} × {self.mx:,} of {self.ny:,} × {self.nx:,} cells: block {how} over blocks "
                f"of {self.ky} × {self.kx}" + (f" ({detail})" if detail else ""))


def map_blocks(ny: int, nx: int, panels: int = 1, limit: int = MAX_MAP_CELLS) -> Blocks:
    """The blocks that bring an ``ny`` x ``nx`` plane to at most ``limit / ceil(sqrt(panels))``
    cells per axis: ``limit`` for a figure of one panel, half for two to four panels (each is
    half as wide or as tall), so a figure carries at most about ``limit**2`` cells in all."""
    limit = max(limit // math.ceil(math.sqrt(max(panels, 1))), 1)
    return Blocks(ny, nx, -(-ny // limit), -(-nx // limit))


def _padded(a: np.ndarray, b: Blocks, fill) -> np.ndarray:
    """``a`` (..., ny, nx) padded with ``fill`` to (..., my, ky, mx, kx)."""
    lead = a.shape[:-2]
    out = np.full(lead + (b.my * b.ky, b.mx * b.kx), fill, dtype=np.result_type(a, type(fill)))
    out[..., : b.ny, : b.nx] = a
    return out.reshape(lead + (b.my, b.ky, b.mx, b.kx))


def block_reduce(a: np.ndarray, b: Blocks, how: str = "mean") -> np.ndarray:
    """Each block's NaN-ignoring ``how`` ("mean" or "max") of ``a`` (..., ny, nx) -> (..., my, mx);
    NaN where a block has no finite cell."""
    if not b.decimated:
        return np.asarray(a, dtype=np.float64)
    v = _padded(np.asarray(a, dtype=np.float64), b, np.nan)
    finite = np.isfinite(v)
    n = finite.sum(axis=(-3, -1))
    if how == "mean":
        total = np.where(finite, v, 0.0).sum(axis=(-3, -1))
        with np.errstate(invalid="ignore", divide="ignore"):
            return np.where(n > 0, total / np.maximum(n, 1), np.nan)
    if how == "max":
        return np.where(n > 0, np.where(finite, v, -np.inf).max(axis=(-3, -1)), np.nan)
    raise ValueError(f"how: must be 'mean' or 'max', got {how!r}")


def block_pick(key: np.ndarray, b: Blocks) -> np.ndarray:
    """Flat index into the (ny, nx) plane of each block's cell of largest finite ``key`` (the
    block's first cell when none is finite), shape (my, mx). ``a.ravel()[idx]`` then draws any
    array of the plane at those cells, so a maximum and its arg-max come from the same cell."""
    iy, ix = np.meshgrid(np.arange(b.ny), np.arange(b.nx), indexing="ij")
    flat = _padded(iy * b.nx + ix, b, -1)
    k = _padded(np.asarray(key, dtype=np.float64), b, np.nan)
    k = np.where(np.isfinite(k) & (flat >= 0), k, -np.inf)
    # blocks as rows of ky*kx candidates
    k = k.transpose(0, 2, 1, 3).reshape(b.my, b.mx, -1)
    flat = flat.transpose(0, 2, 1, 3).reshape(b.my, b.mx, -1)
    best = np.take_along_axis(flat, np.argmax(k, axis=-1)[..., None], axis=-1)[..., 0]
    return np.where(best >= 0, best, flat[..., 0])


def _block_axis(spec: AxisSpec, k: int) -> AxisSpec:
    """``spec`` with its values and positions averaged over runs of ``k`` (the blocks' centres)."""
    if k == 1:
        return spec
    b = Blocks(1, spec.values.size, 1, k)
    return AxisSpec(spec.name, block_reduce(spec.values[None, :], b)[0], block_reduce(spec.positions[None, :], b)[0],
                    spec.title, spec.kind, spec.tickvals, spec.ticktext)


def full_data_note(sd, names) -> str:
    """Where the full-resolution data of a figure is: the store and two lines of Python."""
    names = [n for n in dict.fromkeys(names) if n]
    sel = ", ".join(repr(n) for n in names)
    code = (f"import xarray as xr\nds = xr.open_zarr({str(sd.path)!r}, zarr_format=3, consolidated=False)"
            f"[[{sel}]]")
    return ("<details class='small'><summary>full-resolution data</summary><pre><code>"
            f"{html.escape(code)}</code></pre></details>")


# ---------------------------------------------------------------------------
# Maps of stored quantities
# ---------------------------------------------------------------------------


def _map_axes(dims: list[str], sizes: dict[str, int]) -> tuple[str, str] | None:
    live = [d for d in dims if sizes[d] > 1]
    if "A0" in live and "A1_ratio" in live:
        return "A0", "A1_ratio"
    if len(live) >= 2:
        return live[-2], live[-1]
    return None


def quantity_maps(sd, name: str):
    """Maps of ``name`` over two axes, faceted over up to two others; None when the scene has no plane."""
    da = sd.ds[name]
    dims = list(da.dims)
    sizes = dict(zip(dims, da.shape))
    pair = _map_axes(dims, sizes)
    if pair is None:
        live = [d for d in dims if sizes[d] > 1]
        return _quantity_curve(sd, name, live[0]) if live else None
    xd, yd = pair
    rest = [d for d in dims if d not in pair and sizes[d] > 1]
    facets, hidden = rest[:2], rest[2:]
    signed = name in SIGNED
    values = np.asarray(da.values, dtype=np.float64)
    if values.dtype.kind in "iu":
        values = values.astype(np.float64)
    if name in ("error_estimate", "iterations", "n_tau"):
        values = np.where(np.asarray(sd.ds["status"].values) == 0, values, np.nan) if "status" in sd.ds else values
    # Order: facets..., hidden..., y, x ; singleton dims squeezed.
    order = facets + hidden + [yd, xd]
    single = [d for d in dims if sizes[d] == 1]
    v = np.transpose(values, [dims.index(d) for d in single + order])
    v = v.reshape(v.shape[len(single):])
    v = _best_over(v, tuple(range(len(facets), len(facets) + len(hidden))), signed, name)
    fx = facets[0] if facets else None
    fy = facets[1] if len(facets) > 1 else None
    ri = _pick(sizes[fx]) if fx else [0]
    ci = _pick(sizes[fy]) if fy else [0]
    if fx and not fy and len(ri) > 3:  # one facet axis: lay it out in a row
        ci, ri, fy, fx = ri, [0], fx, None
    blocks = map_blocks(sizes[yd], sizes[xd], panels=len(ri) * len(ci))
    v = block_reduce(v, blocks, "mean")
    xs, ys = _block_axis(_spec(sd, xd), blocks.kx), _block_axis(_spec(sd, yd), blocks.ky)
    fixed_text = ", ".join(f"{param_label(d, sd.p)} = {format_value(d, float(sd.ds[d].values[0]))}" for d in single)
    held = ", ".join(f"{param_label(k, sd.p)} = {format_value(k, v)}" for k, v in sd.fixed.items()
                     if k not in ("p", "delta"))

    def facet_value(d, i):
        return float(sd.ds[d].values[i])

    titles = []
    title_colors = {}
    for i in ri:
        for j in ci:
            parts = []
            if fx:
                parts.append(f"{param_label(fx, sd.p)} = {format_value(fx, facet_value(fx, i))}")
            if fy:
                parts.append(f"{param_label(fy, sd.p)} = {format_value(fy, facet_value(fy, j))}")
            text = ", ".join(parts)
            if {fx, fy} == {"T2_mu_n", "T2_mu_s"}:
                # Equal-ratio diagonals of the (T^2 mu_n, T^2 mu_s) grid: one colour per mu_n/mu_s.
                a = facet_value(fx, i) if fx == "T2_mu_n" else facet_value(fy, j)
                b = facet_value(fy, j) if fy == "T2_mu_s" else facet_value(fx, i)
                ratio = a / b
                color = title_colors.setdefault(round(math.log2(ratio), 6), _PALETTE[len(title_colors) % 10])
                text = (f"<span style='color:{color}'>{text}<br>μ<sub>n</sub>/μ<sub>s</sub> = "
                        f"{format_value('anisotropy_ratio', ratio)}</span>")
            titles.append(text)
    nr, nc = len(ri), len(ci)
    fig = subplots(rows=nr, cols=nc, subplot_titles=titles if (fx or fy) else None, shared_xaxes=True,
                   shared_yaxes=True, horizontal_spacing=0.04 if nc > 1 else 0.1,
                   vertical_spacing=min(0.1, 0.3 / max(nr, 1)) if nr > 1 else 0.1)
    finite = v[np.isfinite(v)]
    if signed:
        vmax = float(np.max(np.abs(finite))) if finite.size else 1.0
        cax = {"colorscale": "RdBu_r", "cmin": -vmax, "cmax": vmax, "cmid": 0.0}
    else:
        cax = {"colorscale": "Viridis"}
    linear = xs.kind == "linear" and ys.kind == "linear"
    # Fine grids: a contour map coloured as a heatmap. Coarse ones: the cells as they are (a
    # heatmap) with contour lines on top, instead of contours interpolated into jagged shapes.
    style = ("contour" if min(sizes[xd], sizes[yd]) >= FINE_GRID else "heatmap+lines" if min(sizes[xd], sizes[yd]) >= 4
             else "heatmap") if linear else "heatmap"
    if blocks.decimated:
        # A plane drawn by blocks is already as fine as the screen: its cells as a heatmap. The
        # browser draws contours of a noisy 400 x 400 field (the error estimate of a
        # 1,000 x 1,000 scene) in tens of seconds, a heatmap in well under one.
        style = "heatmap"
    qlab = quantity_label(name, sd.p)
    custom = None
    if xs.kind != "linear" or ys.kind != "linear":
        gx, gy = np.meshgrid(xs.values, ys.values)
        custom = np.stack([gx, gy], axis=-1)
        hx, hy = "%{customdata[0]:.4g}", "%{customdata[1]:.4g}"
    else:
        hx, hy = "%{x:.4g}", "%{y:.4g}"
    traces = []
    for r, i in enumerate(ri):
        for c, j in enumerate(ci):
            if fx and fy:
                z = v[i, j]
            elif fx:
                z = v[i]
            elif fy:
                z = v[j]
            else:
                z = v
            extra = []
            if fx:
                extra.append(f"{param_label(fx, sd.p)} = {format_value(fx, facet_value(fx, i))}")
            if fy:
                extra.append(f"{param_label(fy, sd.p)} = {format_value(fy, facet_value(fy, j))}")
            if hidden:
                extra.append("best over " + ", ".join(param_label(d, sd.p) for d in hidden))
            if fixed_text:
                extra.append(fixed_text)
            if held:
                extra.append(held)
            hover = (f"{xs.title} = {hx}<br>{ys.title} = {hy}<br><b>{qlab} = %{{z:.4g}}</b>"
                     + (f" (mean of a {blocks.ky} × {blocks.kx} block)" if blocks.decimated else "")
                     + "".join(f"<br>{e}" for e in extra) + "<extra></extra>")
            kw = dict(x=xs.positions, y=ys.positions, z=_round(z), coloraxis="coloraxis", hovertemplate=hover,
                      customdata=custom, name=qlab)
            axes = fig.axes_of(r + 1, c + 1)
            if custom is None:
                del kw["customdata"]
            if style == "contour":
                traces.append(dict(type="contour", **kw, contours={"coloring": "heatmap", "showlines": True},
                                   line={"width": 0.5}, ncontours=16, connectgaps=False, **axes))
                continue
            traces.append(dict(type="heatmap", **kw, **axes))
            if style == "heatmap+lines":
                traces.append(dict(type="contour", x=xs.positions, y=ys.positions, z=_round(z),
                                   contours={"coloring": "none"}, line={"width": 0.8, "color": "rgba(40,40,40,0.55)"},
                                   ncontours=10, showscale=False, showlegend=False, hoverinfo="skip", connectgaps=False,
                                   name="contours", **axes))
    # One update for every panel, then titles on the outer ones (per-panel updates are slow in plotly.py).
    fig.update_xaxes(**{k: w for k, w in xs.axis_layout().items() if k != "title"})
    fig.update_yaxes(**{k: w for k, w in ys.axis_layout().items() if k != "title"})
    for c in range(nc):
        fig.update_xaxes(row=nr, col=c + 1, title_text=xs.title)
    for r in range(nr):
        fig.update_yaxes(row=r + 1, col=1, title_text=ys.title)
    fig.update_layout(coloraxis={**cax, "colorbar": {"title": {"text": qlab, "side": "right"}}})
    title = qlab
    if hidden:
        title += " (best over " + ", ".join(param_label(d, sd.p) for d in hidden) + ")"
    if fx and len(ri) < sizes[fx] or fy and len(ci) < sizes[fy]:
        title += f"; facets show at most {MAX_FACET} values of each facet axis"
    if fixed_text:
        title += f"; {fixed_text}"
    if blocks.decimated:
        title += "<br>" + blocks.text("mean")
    return _layout(fig.add_traces(traces), height=max(320, 250 * nr + 80), title=title).to_plotly_json()


def _quantity_curve(sd, name: str, dim: str):
    """A quantity of a one-axis scene as a curve."""
    xs = _spec(sd, dim)
    da = sd.ds[name]
    for d in da.dims:
        if d != dim:
            da = da.isel({d: 0})
    v = np.asarray(da.values, dtype=np.float64)
    qlab = quantity_label(name, sd.p)
    fig = Figure([dict(type="scatter", x=xs.positions, y=_round(v), customdata=xs.values,
                       mode="lines" if xs.values.size > MAX_MARKERS else "lines+markers",
                       name=qlab, hovertemplate=f"{xs.title} = %{{customdata:.4g}}<br>{qlab} = %{{y:.5g}}<extra></extra>")])
    fig.update_xaxes(**xs.axis_layout())
    fig.update_yaxes(title_text=qlab)
    return _layout(fig, 340, qlab).to_plotly_json()


# ---------------------------------------------------------------------------
# Reductions
# ---------------------------------------------------------------------------


def reduction_arrays(sd, red: dict) -> dict[str, dict[str, str]]:
    """{kind: {role: array name}} for kind "grid" and, when stored, "polished".

    Roles: "value" (the maximum), "signed", one per axis of ``over`` (the arg-max) and one per
    reported quantity.
    """
    name = red["name"]
    out = {}
    for kind, base in (("grid", name), ("polished", f"{name}_polished")):
        if base not in sd.ds:
            continue
        roles = {"value": base}
        if f"{base}_signed" in sd.ds:
            roles["signed"] = f"{base}_signed"
        for ax in red.get("over", []):
            if f"{base}_{ax}" in sd.ds:
                roles[ax] = f"{base}_{ax}"
        for q in red.get("report", []):
            if q != red.get("quantity") and f"{base}_{q}" in sd.ds:
                roles[q] = f"{base}_{q}"
        if kind == "polished":
            for extra in ("status", "evaluations"):
                if f"{base}_{extra}" in sd.ds:
                    roles[extra] = f"{base}_{extra}"
        out[kind] = roles
    return out


def _role_label(sd, red: dict, role: str) -> str:
    if role == "value":
        q = quantity_label(red["quantity"], sd.p)
        return f"max |{q}|" if red.get("statistic") == "absmax" else f"{red.get('statistic', 'max')} {q}"
    if role == "signed":
        return f"{quantity_label(red['quantity'], sd.p)} at the optimum"
    if role in red.get("over", []):
        return f"arg-max {param_label(role, sd.p)}"
    return f"{quantity_label(role, sd.p)} at the optimum"


def _plot_roles(red: dict, arrays: dict) -> list[str]:
    roles = ["value"]
    for kind in ("grid", "polished"):
        for r in arrays.get(kind, {}):
            if r not in roles and r not in ("status", "evaluations", "signed"):
                roles.append(r)
    return roles


def _arg_axis(sd, role: str) -> AxisSpec | None:
    """Arg-max parameters on power-of-two axes (e.g. the optimal scaled period) keep log2 positions."""
    if role in sd.ds.coords:
        sp = _spec(sd, role)
        if sp.kind in ("log2", "category"):
            return sp
    return None


def _to_pos(spec: AxisSpec | None, v: np.ndarray) -> np.ndarray:
    if spec is None:
        return v
    if spec.kind == "log2":
        with np.errstate(divide="ignore", invalid="ignore"):
            return np.where(v > 0, np.log2(np.where(v > 0, v, 1.0)), np.nan)
    # categorical: index of the nearest value
    idx = np.array([np.argmin(np.abs(spec.values - x)) if np.isfinite(x) else -1 for x in np.ravel(v)])
    return np.where(idx >= 0, idx, np.nan).reshape(np.shape(v)).astype(np.float64)


def _value_axis_layout(spec: AxisSpec | None, title: str) -> dict:
    if spec is None:
        return {"title": {"text": title}}
    d = spec.axis_layout()
    d["title"] = {"text": title}
    return d


def reduction_figures(sd, red: dict) -> list:
    """Figures of one reduction: curves or maps depending on how many axes it keeps."""
    arrays = reduction_arrays(sd, red)
    if "grid" not in arrays:
        return []
    da = sd.ds[arrays["grid"]["value"]]
    dims = [d for d in da.dims if da.sizes[d] > 1]
    if len(dims) == 0:
        return []
    if len(dims) == 1:
        return [_curves(sd, red, arrays, dims[0], None, None)]
    if len(dims) == 2:
        figs = [_reduction_maps(sd, red, arrays, dims[0], dims[1])]
        figs.append(_curves(sd, red, arrays, dims[0], dims[1], None))
        return figs
    # Three or more kept axes (a plane plus a subset dimension): curves against the last axis,
    # one line per value of the first, one column per value of the second; any others at index 0.
    return [_curves(sd, red, arrays, dims[-1], dims[0], dims[1])]


def _select(sd, name: str, keep: list[str]) -> np.ndarray:
    """Array ``name`` with dims ordered as ``keep``; other dims of size 1 squeezed, larger taken at
    index 0. Read-only, and kept for the rest of the build (curves select the same arrays per line)."""
    cache = sd.__dict__.setdefault("_selected", {})
    key = (name, tuple(keep))
    if key not in cache:
        da = sd.ds[name]
        for d in da.dims:
            if d not in keep:
                da = da.isel({d: 0})
        v = np.array(da.transpose(*keep).values, dtype=np.float64)
        v.flags.writeable = False
        cache[key] = v
    return cache[key]


def _curves(sd, red: dict, arrays: dict, xdim: str, line_dim: str | None, col_dim: str | None):
    roles = _plot_roles(red, arrays)
    keep = [d for d in (col_dim, line_dim, xdim) if d]
    xs = _spec(sd, xdim)
    cols = _pick(sd.ds.sizes[col_dim], 6) if col_dim else [0]
    lines = _pick(sd.ds.sizes[line_dim], MAX_LINES) if line_dim else [0]
    titles = []
    for role in roles:
        for j in cols:
            t = _role_label(sd, red, role)
            if col_dim:
                t += f"<br>{param_label(col_dim, sd.p)} = {format_value(col_dim, float(sd.ds[col_dim].values[j]))}"
            titles.append(t)
    fig = subplots(rows=len(roles), cols=len(cols), shared_xaxes=True, subplot_titles=titles,
                   vertical_spacing=min(0.08, 0.5 / len(roles)), horizontal_spacing=0.05)
    has_polished = "polished" in arrays
    dense = xs.values.size > MAX_MARKERS
    traces = []
    axes = {(r, c): fig.axes_of(r + 1, c + 1) for r in range(len(roles)) for c in range(len(cols))}
    for r, role in enumerate(roles):
        vspec = _arg_axis(sd, role)
        for c, j in enumerate(cols):
            for n_line, li in enumerate(lines):
                color = _color(n_line, len(lines)) if line_dim else "#1f77b4"
                lname = (f"{param_label(line_dim, sd.p)} = {format_value(line_dim, float(sd.ds[line_dim].values[li]))}"
                         if line_dim else "")
                for kind in ("grid", "polished"):
                    name = arrays.get(kind, {}).get(role)
                    if name is None:
                        continue
                    v = _select(sd, name, keep)
                    if col_dim:
                        v = v[j]
                    if line_dim:
                        v = v[li]
                    y = _round(_to_pos(vspec, v))
                    polished = kind == "polished"
                    hover = (f"{xs.title} = %{{customdata[0]:.4g}}<br>{_role_label(sd, red, role)} = "
                             f"%{{customdata[1]:.5g}}<br>{kind} optimum"
                             + (f"<br>{lname}" if lname else "")
                             + (f"<br>{param_label(col_dim, sd.p)} = "
                                f"{format_value(col_dim, float(sd.ds[col_dim].values[j]))}" if col_dim else "")
                             + _argmax_hover(sd, red, arrays[kind], keep, j if col_dim else None,
                                             li if line_dim else None, xs.values.size)
                             + "<extra></extra>")
                    custom = np.stack([xs.values, _round(v)] + _argmax_custom(sd, red, arrays[kind], keep,
                                                                               j if col_dim else None,
                                                                               li if line_dim else None), axis=-1)
                    legend = (lname + " " if lname else "") + kind
                    if dense:  # grid optimum dotted, polished solid
                        style = dict(mode="lines", line={"color": color, "width": 2 if polished else 1.5,
                                                         **({} if polished or not has_polished else {"dash": "dot"})})
                    else:
                        style = dict(mode="lines" if polished else ("markers" if has_polished else "lines+markers"),
                                     line={"color": color, "width": 2},
                                     marker={"color": color, "size": 6, "symbol": "circle-open"})
                    traces.append(dict(
                        type="scatter", x=xs.positions, y=y, customdata=custom, hovertemplate=hover, **style,
                        name=legend, legendgroup=legend, showlegend=(r == 0 and c == 0), **axes[r, c]))
            if vspec is not None:
                fig.update_yaxes(row=r + 1, col=c + 1, **_value_axis_layout(vspec, ""))
        short = param_label(role, sd.p) if role in red.get("over", []) else _role_label(sd, red, role)
        fig.update_yaxes(row=r + 1, col=1, title_text=short, title_standoff=4)
    fig.update_xaxes(**{k: w for k, w in xs.axis_layout().items() if k != "title"})
    for c in range(len(cols)):
        fig.update_xaxes(row=len(roles), col=c + 1, title_text=xs.title)
    what = f"{red['name']}: {red.get('statistic', 'max')} of {quantity_label(red['quantity'], sd.p)} over " + \
        ", ".join(param_label(a, sd.p) for a in red.get("over", []))
    if has_polished:
        what += (" — grid optimum (dotted) and polished optimum (lines)" if dense else
                 " — grid optimum (markers) and polished optimum (lines)")
    if dense:
        what += f"<br>{xs.values.size:,} points per curve, drawn without markers"
    if line_dim and len(lines) < sd.ds.sizes[line_dim]:
        what += (f"<br>{len(lines)} of the {sd.ds.sizes[line_dim]:,} values of {param_label(line_dim, sd.p)}, "
                 "evenly spread")
    return _layout(fig.add_traces(traces), height=max(360, 230 * len(roles) + 80), title=what).to_plotly_json()


def _argmax_custom(sd, red, roles, keep, j, li) -> list[np.ndarray]:
    out = []
    for ax in red.get("over", []):
        if ax in roles:
            v = _select(sd, roles[ax], keep)
            if j is not None:
                v = v[j]
            if li is not None:
                v = v[li]
            out.append(_round(v))
    return out


def _argmax_hover(sd, red, roles, keep, j, li, n) -> str:
    parts, k = [], 2
    for ax in red.get("over", []):
        if ax in roles:
            parts.append(f"<br>{param_label(ax, sd.p)} = %{{customdata[{k}]:.4g}}")
            k += 1
    return "".join(parts)


def _reduction_maps(sd, red: dict, arrays: dict, xd: str, yd: str):
    """The maximum, the arg-max parameters and the reported quantities over the kept plane, one
    row each (own colour scale), grid and polished optima side by side."""
    # The paper draws these planes with mu_n/mu_s across and the scaled period up.
    xs, ys = _spec(sd, xd), _spec(sd, yd)
    roles = _plot_roles(red, arrays)
    kinds = [k for k in ("grid", "polished") if k in arrays]
    titles = [f"{_role_label(sd, red, role)} — {kind} optimum" for role in roles for kind in kinds]
    nr = len(roles)
    vgap = min(0.1, 0.35 / max(nr - 1, 1)) if nr > 1 else 0.1
    fig = subplots(rows=nr, cols=len(kinds), shared_yaxes=True, shared_xaxes=True, horizontal_spacing=0.05,
                   vertical_spacing=vgap, subplot_titles=titles)
    gx, gy = np.meshgrid(xs.values, ys.values)
    # A fine plane is drawn by blocks: each block shows its cell of largest maximum (smallest
    # for a "min" reduction) with that cell's arg-max and companions, never a mix of cells.
    blocks = map_blocks(ys.values.size, xs.values.size, panels=nr * len(kinds))
    picks = {}
    if blocks.decimated:
        for kind in kinds:
            key = _select(sd, arrays[kind]["value"], [yd, xd])
            picks[kind] = block_pick(-key if red.get("statistic") == "min" else key, blocks)
        xs, ys = _block_axis(xs, blocks.kx), _block_axis(ys, blocks.ky)

    def plane(kind, name):
        v = _select(sd, name, [yd, xd])
        return v.ravel()[picks[kind]] if kind in picks else v

    def cells(kind, g):
        return g.ravel()[picks[kind]] if kind in picks else g

    row_h = (1 - vgap * (nr - 1)) / nr
    traces = []
    for r, role in enumerate(roles):
        vals = {k: plane(k, arrays[k][role]) for k in kinds if role in arrays[k]}
        vspec = _arg_axis(sd, role)
        allv = np.concatenate([v.ravel() for v in vals.values()])
        allv = allv[np.isfinite(allv)]
        label = _role_label(sd, red, role)
        cname = "coloraxis" if r == 0 else f"coloraxis{r + 1}"
        for c, kind in enumerate(kinds):
            if kind not in vals:
                continue
            v = vals[kind]
            extra = [cells(kind, gx), cells(kind, gy), _round(v)]
            hover = (f"{xs.title} = %{{customdata[0]:.4g}}<br>{ys.title} = %{{customdata[1]:.4g}}<br><b>{label} = "
                     "%{customdata[2]:.5g}</b>")
            k = 3
            for ax in red.get("over", []):
                if ax in arrays[kind] and ax != role:
                    extra.append(_round(plane(kind, arrays[kind][ax])))
                    hover += f"<br>{param_label(ax, sd.p)} = %{{customdata[{k}]:.4g}}"
                    k += 1
            if kind == "polished" and "status" in arrays[kind]:
                extra.append(plane(kind, arrays[kind]["status"]))
                hover += f"<br>polish status = %{{customdata[{k}]:.0f}}"
            hover += f"<br>{kind} optimum<extra></extra>"
            z = _to_pos(vspec, v) if vspec is not None else v
            traces.append(dict(type="heatmap", x=xs.positions, y=ys.positions, z=_round(z),
                               customdata=np.stack(extra, axis=-1), hovertemplate=hover, coloraxis=cname,
                               name=kind, **fig.axes_of(r + 1, c + 1)))
        if (role in SIGNED or role == "signed") and allv.size:
            vmax = float(np.max(np.abs(allv))) or 1.0
            cax = {"colorscale": "RdBu_r", "cmin": -vmax, "cmax": vmax}
        else:
            cax = {"colorscale": "Viridis"}
            if allv.size and vspec is None:
                cax.update(cmin=float(allv.min()), cmax=float(allv.max()))
        cb = {"title": {"text": label, "side": "right"}, "len": row_h, "y": 1 - r * (row_h + vgap) - row_h / 2,
              "yanchor": "middle", "thickness": 14}
        if vspec is not None:
            cb.update(tickmode="array", tickvals=list(vspec.tickvals), ticktext=list(vspec.ticktext))
        fig.update_layout({cname: {**cax, "colorbar": cb}})
        fig.update_yaxes(row=r + 1, col=1, **ys.axis_layout())
    for c in range(len(kinds)):
        fig.update_xaxes(row=nr, col=c + 1, **xs.axis_layout())
        for r in range(nr - 1):
            fig.update_xaxes(row=r + 1, col=c + 1, **{k: w for k, w in xs.axis_layout().items() if k != "title"})
    what = f"{red['name']} over the ({xs.title}, {ys.title}) plane"
    if blocks.decimated:
        best = "smallest" if red.get("statistic") == "min" else "largest"
        what += "<br>" + blocks.text("min" if best == "smallest" else "max",
                                     f"each drawn cell is its block's cell of {best} {_role_label(sd, red, 'value')}, "
                                     "with that cell's arg-max")
    return _layout(fig.add_traces(traces), height=max(360, 260 * nr + 60), title=what).to_plotly_json()


# ---------------------------------------------------------------------------
# Series
# ---------------------------------------------------------------------------


def series_figure(sd):
    """u(tau) at the scene's stored series points."""
    if "series_u" not in sd.ds:
        return None
    u = np.asarray(sd.ds["series_u"].values, dtype=np.float64)
    tau = np.asarray(sd.ds["series_tau"].values, dtype=np.float64)
    status = np.asarray(sd.ds["series_status"].values) if "series_status" in sd.ds else np.zeros(u.shape[0])
    fig = Figure()
    for i in range(u.shape[0]):
        params = {d: float(sd.ds[f"series_{d}"].values[i]) for d in sd.dims if f"series_{d}" in sd.ds}
        text = params_text(params, sd.p, "<br>")
        fig.add_trace(dict(type="scatter", x=tau, y=_round(u[i]), mode="lines", name=f"point {i}" +
                           ("" if status[i] == 0 else f" (status {int(status[i])})"),
                           hovertemplate="τ = %{x:.3f}<br>u = %{y:.4g}<br>" + text + "<extra></extra>"))
    fig.update_xaxes(title_text="τ = t/T")
    fig.update_yaxes(title_text="u = T dx<sub>cm</sub>/dt")
    return _layout(fig, 340, "stored u(τ) at the scene's series points").to_plotly_json()
