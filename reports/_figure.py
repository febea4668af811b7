"""Plotly figures as plain JSON: the subset of plotly.py's ``Figure`` and ``make_subplots`` the
report uses, without plotly.py's object model.

plotly.py validates every property it is given through a tree of validator objects; building the
full paper's report that way cost about half of its build time (issue 36: ``make_subplots``
alone 3.7 s of 22.8 s CPU, ``update_*`` and ``go.Scatter`` most of the rest). The report draws a
figure once and never reads it back, so it builds the JSON that plotly.js reads directly:

* :func:`subplots` lays out a grid of ``xy`` subplots exactly as ``plotly.subplots.make_subplots``
  does (axis domains, anchors, ``matches`` and hidden tick labels of shared axes, the subplot
  titles' annotations; ``tests/test_report_figure.py`` compares the two layouts key by key);
* :class:`Figure` keeps ``data`` (trace dicts) and ``layout`` (a dict) and offers the calls the
  report makes: ``add_trace(trace, row, col)``, ``update_layout``, ``update_xaxes`` /
  ``update_yaxes`` (all axes, or those of one row and/or column), ``update_annotations``,
  ``add_hline``, ``axes_of`` and ``to_plotly_json``;
* what plotly.py's validators would have changed is done here: numeric numpy arrays become
  plotly.js typed arrays (:func:`typed_array_spec`) and a named colour scale becomes its list of
  (position, colour) pairs (:func:`colorscale`; plotly.js knows neither ``RdBu_r`` nor plotly.py's
  colour-brewer ``RdBu``).

Keyword arguments follow plotly.py's "magic underscore" rule for the names the report uses:
``title_text="u"`` is ``title={"text": "u"}``; the property names that contain an underscore
(``plot_bgcolor``, ``paper_bgcolor``, ``error_x``, ``error_y``) are kept whole.
"""

from __future__ import annotations

import base64
import functools

import numpy as np

__all__ = ["Figure", "subplots", "colorscale", "typed_array_spec", "encode_trace"]

#: plotly property names that contain an underscore (not split by the magic-underscore rule)
_UNDERSCORED = frozenset({"plot_bgcolor", "paper_bgcolor", "error_x", "error_y", "error_z"})
#: keys whose string value is a named colour scale plotly.py would expand
_COLORSCALE_KEYS = frozenset({"colorscale"})

#: numpy dtypes plotly.js reads as typed arrays, and their short names
_TYPED_ARRAY_DTYPES = {"int8": "i1", "uint8": "u1", "int16": "i2", "uint16": "u2", "int32": "i4",
                       "uint32": "u4", "float32": "f4", "float64": "f8"}


def typed_array_spec(v: np.ndarray):
    """``v`` as a plotly.js typed array, ``{"dtype": "f8", "bdata": base64, "shape": "r, c"}`` (the
    encoding plotly.py gives arrays it validates; written here rather than imported from plotly's
    private ``_plotly_utils``). 64-bit integers are narrowed to the smallest type that holds them;
    an array no typed array holds (empty, bool, out-of-range 64-bit) is returned unchanged."""
    v = np.ascontiguousarray(v)
    if v.size == 0:
        return v
    if v.dtype.kind in "iu" and v.dtype.itemsize == 8:
        lo, hi = v.min(), v.max()
        for t in (("int8", "int16", "int32") if v.dtype.kind == "i" else ("uint8", "uint16", "uint32")):
            if np.iinfo(t).min <= lo and hi <= np.iinfo(t).max:
                v = v.astype(t)
                break
        else:
            return v
    short = _TYPED_ARRAY_DTYPES.get(str(v.dtype))
    if short is None:
        return v
    spec = {"dtype": short, "bdata": base64.b64encode(v).decode("ascii")}
    if v.ndim > 1:
        spec["shape"] = str(v.shape)[1:-1]
    return spec


@functools.lru_cache(maxsize=1)
def _colour_sequences() -> dict:
    """{lower-case name: colours} of plotly's named sequential, diverging and cyclical scales (the
    tables plotly.py's colour-scale validator reads)."""
    from plotly.colors import cyclical, diverging, sequential  # the colour tables only

    return {name.lower(): seq for mod in (sequential, diverging, cyclical) for name, seq in vars(mod).items()
            if isinstance(seq, list) and not name.startswith("_") and not name.endswith("_r")}


@functools.lru_cache(maxsize=64)
def _named_colorscale(name: str) -> tuple:
    low = name.lower()
    seqs = _colour_sequences()
    if low in seqs:
        colours = seqs[low]
    elif low.endswith("_r") and low[:-2] in seqs:
        colours = seqs[low[:-2]][::-1]
    else:
        raise ValueError(f"no colour scale named {name!r}")
    d = len(colours) - 1
    return tuple((1.0 * i / (1.0 * d), c) for i, c in enumerate(colours))


def colorscale(value):
    """A colour scale as plotly.js reads it: a name (``"Viridis"``, ``"RdBu_r"``) becomes its list
    of [position, colour] pairs, as plotly.py's validator makes it; a list is returned unchanged."""
    if isinstance(value, str):
        return [list(step) for step in _named_colorscale(value)]
    return value


def _encode(key, value):
    """One property value as plotly.js reads it (typed arrays, expanded colour scales), recursively."""
    if isinstance(value, np.ndarray):
        return typed_array_spec(value) if value.dtype.kind in "fiub" else value.tolist()
    if key in _COLORSCALE_KEYS and isinstance(value, str):
        return colorscale(value)
    if isinstance(value, dict):
        return {k: _encode(k, v) for k, v in value.items()}
    return value


def encode_trace(trace: dict) -> dict:
    """``trace`` with numeric numpy arrays as typed arrays and named colour scales expanded."""
    return {k: _encode(k, v) for k, v in trace.items()}


def _expand(props: dict) -> dict:
    """plotly.py's magic underscores: ``{"title_text": t}`` -> ``{"title": {"text": t}}``, merged."""
    out: dict = {}
    for key, value in props.items():
        if "_" in key and key not in _UNDERSCORED:
            head, rest = key.split("_", 1)
            value, key = _expand({rest: value}), head
        elif isinstance(value, dict):
            value = _expand(value)
        _merge(out, {key: value})
    return out


def _merge(into: dict, update: dict) -> dict:
    """Deep-merge ``update`` into ``into`` (dicts merged key by key, None removes, anything else replaced)."""
    for key, value in update.items():
        if value is None:  # plotly.py: assigning None unsets a property
            into.pop(key, None)
        elif isinstance(value, dict) and isinstance(into.get(key), dict):
            _merge(into[key], value)
        else:
            into[key] = _encode(key, value)
    return into


def _axis_key(letter: str, number: int) -> str:
    return f"{letter}axis{number if number > 1 else ''}"


class Figure:
    """A figure's JSON (``data``: trace dicts, ``layout``: dict) with the plotly.py calls the report
    makes. ``grid[r][c]`` is the axis number of subplot (r + 1, c + 1), None outside a subplot."""

    def __init__(self, data=None, layout=None):
        self.data: list[dict] = [encode_trace(t) for t in (data or [])]
        self.layout: dict = _expand(layout or {})
        self.grid: list[list[int | None]] = [[1]]

    # -- traces ------------------------------------------------------------
    def axes_of(self, row: int, col: int) -> dict:
        """``{"xaxis": "x2", "yaxis": "y2"}``: the axes of subplot (row, col), counted from 1."""
        n = self.grid[row - 1][col - 1]
        if n is None:
            raise ValueError(f"no subplot at row {row}, col {col}")
        suffix = str(n) if n > 1 else ""
        return {"xaxis": f"x{suffix}", "yaxis": f"y{suffix}"}

    def add_trace(self, trace: dict, row: int | None = None, col: int | None = None) -> "Figure":
        """Append ``trace`` (a dict with its ``type``), on subplot (row, col) when given."""
        trace = encode_trace(trace)
        if row is not None:
            trace.update(self.axes_of(row, col))
        self.data.append(trace)
        return self

    def add_traces(self, traces) -> "Figure":
        for t in traces:
            self.add_trace(t)
        return self

    # -- layout ------------------------------------------------------------
    def update_layout(self, update: dict | None = None, **props) -> "Figure":
        _merge(self.layout, _expand({**(update or {}), **props}))
        return self

    def _cells(self, row, col):
        for r, cells in enumerate(self.grid, start=1):
            for c, n in enumerate(cells, start=1):
                if n is not None and (row is None or row == r) and (col is None or col == c):
                    yield n

    def _update_axes(self, letter: str, row, col, props: dict) -> "Figure":
        update = _expand(props)
        for n in self._cells(row, col):
            _merge(self.layout.setdefault(_axis_key(letter, n), {}), update)
        return self

    def update_xaxes(self, row: int | None = None, col: int | None = None, **props) -> "Figure":
        """Merge ``props`` into the x axes of every subplot, or of row ``row`` and/or column ``col``."""
        return self._update_axes("x", row, col, props)

    def update_yaxes(self, row: int | None = None, col: int | None = None, **props) -> "Figure":
        return self._update_axes("y", row, col, props)

    def update_annotations(self, **props) -> "Figure":
        update = _expand(props)
        for a in self.layout.get("annotations", []):
            _merge(a, update)
        return self

    def add_hline(self, y: float, line: dict | None = None, row: int | None = None,
                  col: int | None = None) -> "Figure":
        """A horizontal line across subplot (row, col) at ``y`` (as plotly.py's ``add_hline``, which
        draws it only on a subplot that holds a trace)."""
        ax = self.axes_of(row or 1, col or 1)
        if not any(t.get("xaxis", "x") == ax["xaxis"] and t.get("yaxis", "y") == ax["yaxis"] for t in self.data):
            return self
        shape = {"line": dict(line or {}), "type": "line", "x0": 0, "x1": 1, "xref": f"{ax['xaxis']} domain",
                 "y0": y, "y1": y, "yref": ax["yaxis"]}
        self.layout.setdefault("shapes", []).append(shape)
        return self

    def to_plotly_json(self) -> dict:
        return {"data": self.data, "layout": self.layout}


def subplots(rows: int = 1, cols: int = 1, *, shared_xaxes: bool = False, shared_yaxes: bool = False,
             horizontal_spacing: float | None = None, vertical_spacing: float | None = None,
             subplot_titles=None, row_heights=None, column_widths=None, specs=None) -> Figure:
    """A :class:`Figure` with a rows x cols grid of ``xy`` subplots laid out as
    ``plotly.subplots.make_subplots`` lays them out (start cell top-left; ``specs`` cells may be
    None or carry ``colspan`` / ``rowspan``; shared axes match the bottom row's x axis of their
    column and the first column's y axis of their row, and hide the others' tick labels)."""
    if horizontal_spacing is None:
        horizontal_spacing = 0.2 / cols
    if vertical_spacing is None:
        vertical_spacing = 0.5 / rows if subplot_titles is not None else 0.3 / rows
    for n, s, name in ((cols, horizontal_spacing, "horizontal_spacing"), (rows, vertical_spacing, "vertical_spacing")):
        if not 0 <= s <= 1 or (n > 1 and s > 1.0 / (n - 1)):
            raise ValueError(f"{name} = {s} does not fit {n} subplots")
    if specs is None:
        specs = [[{} for _ in range(cols)] for _ in range(rows)]
    if column_widths is None:
        widths = [(1.0 - horizontal_spacing * (cols - 1)) / cols] * cols
    else:
        total = float(sum(column_widths))
        widths = [(1.0 - horizontal_spacing * (cols - 1)) * (w / total) for w in column_widths]
    if row_heights is None:
        heights = [(1.0 - vertical_spacing * (rows - 1)) / rows] * rows
    else:
        total = float(sum(row_heights))
        heights = [(1.0 - vertical_spacing * (rows - 1)) * (h / total) for h in row_heights][::-1]
    # plotly's grid of (x start, y start), rows counted from the top (row_dir -1)
    grid = [[(sum(widths[:c]) + c * horizontal_spacing, sum(heights[:r]) + r * vertical_spacing)
             for c in range(cols)] for r in range(rows)[::-1]]
    fig = Figure()
    fig.grid = [[None] * cols for _ in range(rows)]
    layout: dict = {}
    domains = []
    spans: dict[int, tuple[int, int]] = {}
    n = 0
    for r, spec_row in enumerate(specs):
        for c, spec in enumerate(spec_row):
            if spec is None:
                continue
            c_end = c + spec.get("colspan", 1) - 1
            r_end = r + spec.get("rowspan", 1) - 1
            x_domain = [grid[r][c][0] + spec.get("l", 0.0), grid[r][c_end][0] + widths[c_end] - spec.get("r", 0.0)]
            y_domain = [_clip_near(grid[r_end][c][1] + spec.get("b", 0.0)),
                        _clip_near(grid[r][c][1] + heights[-1 - r] - spec.get("t", 0.0))]
            domains.append((x_domain, y_domain))
            x_domain = [max(0.0, x_domain[0]), min(1.0, x_domain[1])]
            y_domain = [max(0.0, y_domain[0]), min(1.0, y_domain[1])]
            n += 1
            suffix = str(n) if n > 1 else ""
            layout[_axis_key("x", n)] = {"anchor": f"y{suffix}", "domain": x_domain}
            layout[_axis_key("y", n)] = {"anchor": f"x{suffix}", "domain": y_domain}
            fig.grid[r][c] = n
            spans[n] = (spec.get("colspan", 1), spec.get("rowspan", 1))
    if shared_xaxes:  # per column, bottom row first: the bottom subplot's x axis is the one matched
        for c in range(cols):
            _share(layout, "x", [fig.grid[r][c] for r in range(rows - 1, -1, -1)], spans, 0)
    if shared_yaxes:  # per row, first column first
        for r in range(rows - 1, -1, -1):
            _share(layout, "y", [fig.grid[r][c] for c in range(cols)], spans, 1)
    titles = list(subplot_titles) if subplot_titles is not None else []
    annotations = [{"font": {"size": 16}, "showarrow": False, "text": text, "x": sum(xd) / 2.0,
                    "xanchor": "center", "xref": "paper", "y": yd[1], "yanchor": "bottom", "yref": "paper"}
                   for text, (xd, yd) in zip(titles, domains) if text]
    if annotations:
        layout["annotations"] = annotations
    fig.layout = layout
    return fig


def _clip_near(v: float) -> float:
    """plotly's rounding of a subplot's y edge within 0.01 outside [0, 1]."""
    if -0.01 < v < 0.0:
        return 0.0
    if 1.0 < v < 1.01:
        return 1.0
    return v


def _share(layout: dict, letter: str, numbers, spans, which: int) -> None:
    first = None
    for n in numbers:
        if n is None or spans[n][which] != 1:
            continue
        if first is None:
            first = f"{letter}{n if n > 1 else ''}"
            continue
        axis = layout[_axis_key(letter, n)]
        axis["matches"] = first
        axis["showticklabels"] = False
