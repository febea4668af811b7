"""Assemble the static site: one ``index.html`` with a table of contents and a section per scene,
and ``plotly.min.js`` written once beside it (referenced by a relative ``<script src>``).
"""

from __future__ import annotations

import datetime as _dt
import html
import sys
import traceback
from pathlib import Path

import numpy as np

from ._labels import format_value, param_label, quantity_label
from ._motion import animation_figure, compute_motion, motion_figure, params_text
from ._panels import quantity_maps, reduction_arrays, reduction_figures, series_figure
from ._read import SceneStore

__all__ = ["SiteBuilder", "PLOTLY_JS"]

PLOTLY_JS = "plotly.min.js"
_CONFIG = {"displaylogo": False, "responsive": True, "toImageButtonOptions": {"format": "svg"}}
#: Motions drawn per scene (one per reduction, best cell), the first also animated.
MAX_MOTIONS = 2

_CSS = """
body{font-family:system-ui,-apple-system,Segoe UI,Roboto,sans-serif;margin:0;color:#222;background:#fafafa}
header{background:#1f3b73;color:#fff;padding:1em 2em}header h1{margin:0 0 .3em 0;font-size:1.5em}
main{padding:0 2em 3em 2em;max-width:1500px}
nav#toc{background:#fff;border:1px solid #ddd;padding:.5em 1.5em;margin:1em 0}
section.scene{background:#fff;border:1px solid #ddd;padding:.5em 1.5em 1.5em;margin:1.5em 0}
table{border-collapse:collapse;margin:.5em 0;font-size:.9em}td,th{border:1px solid #ddd;padding:2px 8px;text-align:left}
th{background:#f0f0f0}.num{text-align:right;font-variant-numeric:tabular-nums}
.note{color:#555;font-size:.9em}.warn{color:#a04000}.notrun{color:#777}
.panel-error{color:#b00;border:1px solid #b00;padding:.5em;white-space:pre-wrap}
details{margin:.5em 0}summary{cursor:pointer;color:#1f3b73}
.plot{margin:1em 0}code{font-size:.9em}
"""


def _template():
    import plotly.graph_objects as go

    axis = {"showgrid": True, "gridcolor": "#e5e5e5", "zeroline": False, "linecolor": "#444", "ticks": "outside",
            "mirror": True, "showline": True}
    return go.layout.Template(layout={"font": {"family": "system-ui, sans-serif", "size": 12},
                                      "plot_bgcolor": "white", "paper_bgcolor": "white",
                                      "xaxis": axis, "yaxis": axis, "colorway": [
                                          "#1f77b4", "#ff7f0e", "#2ca02c", "#d62728", "#9467bd", "#8c564b"]})


def _esc(x) -> str:
    return html.escape(str(x))


def _fmt(x, digits=4) -> str:
    try:
        v = float(x)
    except (TypeError, ValueError):
        return _esc(x)
    return "n/a" if not np.isfinite(v) else f"{v:.{digits}g}"


class SiteBuilder:
    """Collects sections and figures, then writes the site.

    Parameters
    ----------
    out : Path
        Output directory (created).
    """

    def __init__(self, out: Path):
        self.out = Path(out)
        self.sections: list[tuple[str, str, str]] = []  # (anchor, toc text, html)
        self.not_run: list[dict] = []
        self.n_figures = 0
        self.errors: list[str] = []
        self._template = _template()

    # -- figures -----------------------------------------------------------
    def figure(self, fig, note: str = "") -> str:
        import plotly.io as pio

        self.n_figures += 1
        if isinstance(fig, dict):
            fig["layout"]["template"] = self._template.to_plotly_json()
            height = int(fig["layout"].get("height") or 450)
        else:
            fig.update_layout(template=self._template)
            height = int(fig.layout.height or 450)
        div = pio.to_html(fig, include_plotlyjs=False, full_html=False, div_id=f"fig-{self.n_figures}",
                          config=_CONFIG, auto_play=False, default_height=f"{height}px", validate=False)
        note_html = f"<p class='note'>{note}</p>" if note else ""
        return f"<div class='plot'>{note_html}{div}</div>"

    def guarded(self, what: str, build) -> str:
        """HTML from ``build()``; an exception becomes a visible error box (and a stderr line)."""
        try:
            return build()
        except Exception as exc:  # one bad panel must not cost the whole report
            msg = f"{what}: {type(exc).__name__}: {exc}"
            self.errors.append(msg)
            print(f"reports: warning: {msg}", file=sys.stderr)
            tb = traceback.format_exc(limit=3)
            return f"<div class='panel-error'>panel failed — {_esc(msg)}\n{_esc(tb)}</div>"

    # -- sections ----------------------------------------------------------
    def add_scene(self, sd: SceneStore) -> None:
        if sd.meta.get("kind", "grid") in ("accuracy", "stiffness"):  # studies: reports._study
            from ._study import study_section

            self.sections.append(study_section(self, sd))
            return
        anchor = f"scene-{sd.name}"
        if any(a == anchor for a, _, _ in self.sections):  # the same scene in two stores
            anchor = f"scene-{sd.name}-{len(self.sections)}"
        if sd.meta.get("kind", "grid") == "optima":
            from ._optima import optima_section

            body = optima_section(self, sd, anchor)
            self.sections.append((anchor, f"{_esc(sd.name)} — {_esc(sd.title)}", body))
            return
        parts = [f"<h2 id='{anchor}'>{_esc(sd.name)}</h2>",
                 f"<p><b>{_esc(sd.title)}</b>" + (f" — paper figure {_esc(sd.figure)}" if sd.figure else "") + "</p>"]
        if not sd.complete:
            parts.append("<p class='warn'>This store is incomplete (run interrupted or still running): "
                         f"state {_esc(sd.state)}. Points not computed yet are blank.</p>")
        parts.append(self.guarded(f"{sd.name} provenance", lambda: _provenance_html(sd)))
        parts.append(self.guarded(f"{sd.name} status", lambda: _status_html(sd)))
        for red in sd.reductions:
            parts.append(self.guarded(f"{sd.name} {red['name']} table", lambda red=red: _reduction_table(sd, red)))
        parts.append("<h3>Maps of the stored quantities</h3>")
        names = [q for q in sd.quantities if q in sd.ds] + [d for d in ("error_estimate",) if d in sd.ds]
        for q in names:
            parts.append(self.guarded(f"{sd.name} map {q}", lambda q=q: self._maybe(quantity_maps(sd, q))))
        for red in sd.reductions:
            parts.append(f"<h3>Reduction <code>{_esc(red['name'])}</code>: {_esc(red.get('statistic', 'max'))} of "
                         f"{quantity_label(red['quantity'], sd.p)} over "
                         f"{', '.join(param_label(a, sd.p) for a in red.get('over', []))}</h3>")
            parts.append(self.guarded(f"{sd.name} reduction {red['name']}",
                                      lambda red=red: "".join(self.figure(f) for f in reduction_figures(sd, red))))
        if "series_u" in sd.ds:
            parts.append("<h3>Stored velocity series</h3>")
            parts.append(self.guarded(f"{sd.name} series", lambda: self._maybe(series_figure(sd))))
        parts.append(self.guarded(f"{sd.name} motions", lambda: self._motions(sd)))
        toc = f"{_esc(sd.name)} — {_esc(sd.title)}"
        self.sections.append((anchor, toc, "\n".join(parts)))

    def _maybe(self, fig) -> str:
        return "" if fig is None else self.figure(fig)

    def _motions(self, sd: SceneStore) -> str:
        optima = chosen_optima(sd)[:MAX_MOTIONS]
        if not optima:
            return ""
        out = ["<h3>Motions of the optima</h3>",
               "<p class='note'>Recomputed with the solver (<code>solve_periodic(..., return_series=True)</code>, "
               f"rtol {sd.rtol:g}) at the best cell of each reduction. Top: the body at eight instants of one "
               "period, side by side, with the horizontal force per unit length along each link (arrows, "
               "longest = 0.2 body lengths); bottom: u(τ) (dotted: its mean T U), φ(τ), and the positions of the "
               "centre of mass, apex and link tips over three periods.</p>"]
        for k, (label, params, value_text) in enumerate(optima):
            def one(label=label, params=params, value_text=value_text, k=k):
                m = compute_motion(sd.family, params, rtol=sd.rtol, method=sd.method, label=label,
                                   value_text=value_text)
                head = (f"<h4>{_esc(label)}</h4><p>{value_text}; {params_text(params, sd.p)}; "
                        f"T U = {m.displacement:.4g} body lengths per period; solver error estimate "
                        f"{m.error_estimate:.2g}</p>")
                html_ = head + self.figure(motion_figure(m, sd.p))
                if k == 0:
                    html_ += "<h4>Animation</h4>" + self.figure(animation_figure(m, sd.p))
                return html_
            out.append(self.guarded(f"{sd.name} motion {label}", one))
        return "\n".join(out)

    def add_not_run(self, entry: dict) -> None:
        self.not_run.append(entry)

    # -- output ------------------------------------------------------------
    def write(self) -> Path:
        from plotly.offline import get_plotlyjs

        self.out.mkdir(parents=True, exist_ok=True)
        js = self.out / PLOTLY_JS
        text = get_plotlyjs()
        if not js.is_file() or js.read_text(encoding="utf-8") != text:
            js.write_text(text, encoding="utf-8")
        now = _dt.datetime.now(_dt.timezone.utc).isoformat(timespec="seconds")
        toc = ["<nav id='toc'><h2>Contents</h2><ol>"]
        for anchor, text_, _ in self.sections:
            toc.append(f"<li><a href='#{anchor}'>{text_}</a></li>")
        for e in self.not_run:
            toc.append(f"<li class='notrun'>{_esc(e['name'])} — not yet run "
                       f"(<code>{_esc(e.get('command', ''))}</code>)</li>")
        toc.append("</ol></nav>")
        not_run = ""
        if self.not_run:
            rows = "".join(f"<tr><td>{_esc(e['name'])}</td><td>{_esc(e.get('title', ''))}</td>"
                           f"<td>{_esc(e.get('figure', ''))}</td><td><code>{_esc(e.get('command', ''))}</code></td></tr>"
                           for e in self.not_run)
            not_run = ("<section class='scene' id='not-run'><h2>Scenes not yet run</h2>"
                       "<table><tr><th>scene</th><th>title</th><th>paper figure</th><th>command</th></tr>"
                       f"{rows}</table></section>")
        errors = ""
        if self.errors:
            errors = ("<p class='panel-error'>" + f"{len(self.errors)} panel(s) failed to build:<br>"
                      + "<br>".join(_esc(e) for e in self.errors) + "</p>")
        doc = f"""<!DOCTYPE html>
<html lang="en"><head><meta charset="utf-8">
<meta name="viewport" content="width=device-width, initial-scale=1">
<title>Two-link sliding: sweep report</title>
<style>{_CSS}</style>
<script src="{PLOTLY_JS}"></script>
</head><body>
<header><h1>Intermittent sliding of a two-link body: sweep report</h1>
<div>Built {now} from {len(self.sections)} store(s); {len(self.not_run)} scene(s) not yet run. Static and offline:
every figure is interactive (hover for values and parameters, drag to zoom, double-click to reset).</div></header>
<main>
{errors}
{''.join(toc)}
{''.join(f"<section class='scene'>{body}</section>" for _, _, body in self.sections)}
{not_run}
</main></body></html>
"""
        index = self.out / "index.html"
        index.write_text(doc, encoding="utf-8")
        return index


# ---------------------------------------------------------------------------
# Tables
# ---------------------------------------------------------------------------


def _run_time(meta: dict) -> str:
    """The pipeline's record of its runs (``run``: wall and solve seconds, workers), else a note."""
    run = meta.get("run")
    if not isinstance(run, dict) or "wall_seconds" not in run:
        return "not recorded in the store"
    parts = [f"{float(run['wall_seconds']):.1f} s wall"]
    if "solve_seconds" in run:
        parts.append(f"{float(run['solve_seconds']):.1f} s solving")
    if "workers" in run or "scheduler" in run:
        parts.append(f"{_esc(run.get('workers', '?'))} worker(s), {_esc(run.get('scheduler', '?'))} scheduler")
    text = "last run: " + ", ".join(parts)
    if "finished" in run:
        text += f", finished {_esc(run['finished'])}"
    if int(run.get("runs", 1)) > 1:
        text += f"; {int(run['runs'])} runs, {float(run.get('wall_seconds_all_runs', 0)):.1f} s wall in total"
    return text


def provenance_table(sd, kind_rows) -> str:
    """The provenance table of a section: scene hash and file, versions, creation, host and run
    time, then ``kind_rows`` ((label, html) describing what the scene computes), libraries, the
    store, and the scene file itself."""
    pv = sd.provenance
    libs = ", ".join(f"{k} {v}" for k, v in (pv.get("library_versions") or {}).items())
    rows = [
        ("scene hash", f"<code title='{_esc(pv.get('scene_hash', ''))}'>{_esc(pv.get('scene_hash', '')[:16])}…</code>"),
        ("scene file", f"<code>{_esc(pv.get('scene_file', ''))}</code>"),
        ("package version", _esc(pv.get("package_version", "?"))),
        ("git commit", f"<code>{_esc(pv.get('git_commit') or 'unknown')}</code>"),
        ("created (UTC)", _esc(pv.get("created", "?"))),
        ("host", _esc(pv.get("host", "?"))),
        ("run time", _run_time(sd.meta)),
        *kind_rows,
        ("libraries", _esc(libs)),
        ("store", f"<code>{_esc(sd.path)}</code>"),
    ]
    body = "".join(f"<tr><th>{k}</th><td>{v}</td></tr>" for k, v in rows)
    toml = pv.get("scene_toml")
    extra = f"<details><summary>scene file</summary><pre>{_esc(toml)}</pre></details>" if toml else ""
    return f"<h3>Provenance</h3><table>{body}</table>{extra}"


def _provenance_html(sd: SceneStore) -> str:
    shape = sd.meta.get("layout", {}).get("shape", [])
    n = int(np.prod(shape)) if shape else 0
    dims = " × ".join(f"{param_label(d, sd.p)} ({s})" for d, s in zip(sd.dims, shape))
    fixed = ", ".join(f"{param_label(k, sd.p)} = {format_value(k, v)}" for k, v in sd.fixed.items())
    return provenance_table(sd, [
        ("grid", f"{dims} = {n:,} points"),
        ("fixed", fixed or "—"),
        ("solver", f"{_esc(sd.method)}, rtol {sd.rtol:g}"),
    ])


def _status_html(sd: SceneStore) -> str:
    if "status" not in sd.ds:
        return "<p class='warn'>no status array in this store</p>"
    st = np.asarray(sd.ds["status"].values)
    meanings = sd.ds["status"].attrs.get("flag_meanings", {})
    codes, counts = np.unique(st, return_counts=True)
    n = st.size
    rows = "".join(f"<tr><td class='num'>{int(c)}</td><td class='num'>{int(k):,}</td>"
                   f"<td class='num'>{100 * k / n:.2f} %</td><td>{_esc(meanings.get(str(int(c)), '?'))}</td></tr>"
                   for c, k in zip(codes, counts))
    failed = int(np.count_nonzero(st > 0))
    computed = int(np.count_nonzero(st >= 0))
    out = [f"<h3>Points, failures and error estimates</h3><p>{n:,} points; {computed:,} computed; "
           f"<b>{failed:,} failures</b>" + (f" ({100 * failed / max(computed, 1):.2f} % of computed)" if computed else "")
           + "</p>", f"<table><tr><th>status</th><th>points</th><th>share</th><th>reason</th></tr>{rows}</table>"]
    if failed:
        idx = np.argwhere(st > 0)[:12]
        head = "".join(f"<th>{param_label(d, sd.p)}</th>" for d in sd.ds["status"].dims)
        body = ""
        for ix in idx:
            vals = "".join(f"<td class='num'>{format_value(d, float(sd.ds[d].values[i]))}</td>"
                           for d, i in zip(sd.ds["status"].dims, ix))
            code = int(st[tuple(ix)])
            body += f"<tr>{vals}<td>{code}: {_esc(meanings.get(str(code), '?'))}</td></tr>"
        out.append(f"<details><summary>first {len(idx)} failed points</summary><table><tr>{head}<th>reason</th></tr>"
                   f"{body}</table></details>")
    ok = st == 0
    if "error_estimate" in sd.ds and ok.any():
        e = np.asarray(sd.ds["error_estimate"].values)[ok]
        e = e[np.isfinite(e)]
        if e.size:
            q50, q95 = np.percentile(e, [50, 95])
            out.append(f"<p>Solver error estimate over the {e.size:,} converged points: median {q50:.2g}, "
                       f"95th percentile {q95:.2g}, max {e.max():.2g} (rtol {sd.rtol:g}; "
                       f"{int(np.count_nonzero(e > sd.rtol))} above rtol).</p>")
    else:
        out.append(f"<p class='note'>Error estimates are not stored for this scene; every converged point "
                   f"(status 0) has its solver error estimate below rtol = {sd.rtol:g}.</p>")
    return "".join(out)


def _reduction_table(sd: SceneStore, red: dict) -> str:
    """Grid and polished maxima side by side, per kept cell (or a summary when there are many)."""
    arrays = reduction_arrays(sd, red)
    if "grid" not in arrays:
        return ""
    g = sd.ds[arrays["grid"]["value"]]
    dims = list(g.dims)
    gv = np.asarray(g.values, dtype=np.float64)
    label = f"{red['name']}: {red.get('statistic', 'max')} of {quantity_label(red['quantity'], sd.p)}"
    pol = arrays.get("polished")
    if pol is None:
        finite = gv[np.isfinite(gv)]
        best = f"{np.max(finite):.5g}" if finite.size else "n/a"
        return (f"<p>Reduction <code>{_esc(red['name'])}</code>: grid maxima only (not polished); best "
                f"{best} over {gv.size} cells ({int(np.count_nonzero(~np.isfinite(gv)))} without a valid point).</p>")
    pv = np.asarray(sd.ds[pol["value"]].transpose(*dims).values, dtype=np.float64)
    pst = np.asarray(sd.ds[pol["status"]].transpose(*dims).values) if "status" in pol else np.zeros(gv.shape, int)
    pev = np.asarray(sd.ds[pol["evaluations"]].transpose(*dims).values) if "evaluations" in pol else None
    with np.errstate(divide="ignore", invalid="ignore"):
        gain = (pv - gv) / np.abs(gv)
    fin = np.isfinite(gain)
    summary = (f"<p>Reduction <code>{_esc(red['name'])}</code> ({label}): {gv.size} cells; polishing changed the "
               f"maximum by median {np.median(gain[fin]) * 100 if fin.any() else float('nan'):.3g} %, "
               f"at most {np.max(gain[fin]) * 100 if fin.any() else float('nan'):.3g} %; "
               f"{int(np.count_nonzero(pst > 0))} polished optima failed; "
               f"{int(pev.sum()) if pev is not None else '?'} solver calls spent polishing.</p>")
    head = "".join(f"<th>{param_label(d, sd.p)}</th>" for d in dims)
    over = [a for a in red.get("over", []) if a in arrays["grid"]]
    head += "<th>grid max</th><th>polished max</th><th>change</th>"
    head += "".join(f"<th>grid / polished {param_label(a, sd.p)}</th>" for a in over) + "<th>polish status</th>"
    rows = []
    for ix in np.ndindex(*gv.shape):
        if len(rows) >= 60:
            break
        cells = "".join(f"<td class='num'>{format_value(d, float(sd.ds[d].values[i]))}</td>" for d, i in zip(dims, ix))
        cells += f"<td class='num'>{_fmt(gv[ix], 5)}</td><td class='num'>{_fmt(pv[ix], 5)}</td>"
        cells += f"<td class='num'>{_fmt(gain[ix] * 100, 3)} %</td>"
        for a in over:
            ga = float(sd.ds[arrays['grid'][a]].transpose(*dims).values[ix])
            pa = float(sd.ds[pol[a]].transpose(*dims).values[ix]) if a in pol else float("nan")
            cells += f"<td class='num'>{format_value(a, ga)} / {format_value(a, pa)}</td>"
        cells += f"<td class='num'>{int(pst[ix])}</td>"
        rows.append(f"<tr>{cells}</tr>")
    more = f" (first {len(rows)} of {gv.size})" if len(rows) < gv.size else ""
    return (summary + f"<details><summary>grid and polished maxima side by side{more}</summary>"
            f"<table><tr>{head}</tr>{''.join(rows)}</table></details>")


# ---------------------------------------------------------------------------
# Choice of optima for the motions
# ---------------------------------------------------------------------------


def chosen_optima(sd: SceneStore) -> list[tuple[str, dict, str]]:
    """(label, every scene parameter, value text) of the best cell of each reduction, efficiency first.

    The polished optimum is used where it exists and is finite, else the grid optimum; the
    stored series points stand in when the scene has no reduction.
    """
    out = []
    reds = sorted(sd.reductions, key=lambda r: 0 if "efficiency" in r.get("quantity", "") else 1)
    for red in reds:
        arrays = reduction_arrays(sd, red)
        for kind in ("polished", "grid"):
            roles = arrays.get(kind)
            if roles is None:
                continue
            da = sd.ds[roles["value"]]
            v = np.asarray(da.values, dtype=np.float64)
            if red.get("statistic") == "min":
                v = -v
            if not np.isfinite(v).any():
                continue
            ix = np.unravel_index(int(np.nanargmax(v)), v.shape)
            params = dict(sd.fixed)
            for d, i in zip(da.dims, ix):
                if d in sd.dims:
                    params[d] = float(sd.ds[d].values[i])
            for a in red.get("over", []):
                if a in roles:
                    params[a] = float(np.asarray(sd.ds[roles[a]].values)[ix])
            if any(d not in params or not np.isfinite(params[d]) for d in sd.dims):
                continue
            val = float(np.asarray(sd.ds[roles.get('signed', roles['value'])].values)[ix])
            text = f"{kind} optimum of <code>{_esc(red['name'])}</code>: {quantity_label(red['quantity'], sd.p)} = {val:.5g}"
            out.append((f"best {red['name']} ({kind})", params, text))
            break
    if not out and "series_u" in sd.ds:
        for i in range(sd.ds.sizes["series_point"]):
            params = dict(sd.fixed)
            params.update({d: float(sd.ds[f"series_{d}"].values[i]) for d in sd.dims})
            out.append((f"series point {i}", params, f"stored series point {i}"))
    return out
