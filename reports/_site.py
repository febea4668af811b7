"""The static site: sections, figures drawn when they scroll into view, and the page.

``index.html`` carries every figure as a JSON block (``<script type="application/json">``, not
parsed until needed) beside an empty plot div; one small loader draws a figure with
``Plotly.newPlot`` the first time its div comes near the viewport (``IntersectionObserver``), and
marks the page ready (``<html data-ready="ms">``, milliseconds since navigation) once the
figures of the first screen are drawn. ``plotly.min.js`` is written once beside the page and
loaded with ``defer``, so the first layout never waits for it. ``window.twolinkDrawAll()``
draws every figure (for printing, and for the browser tests).
"""

from __future__ import annotations

import datetime as _dt
import html
import json
import sys
import traceback
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

__all__ = ["SiteBuilder", "Section", "PLOTLY_JS", "esc", "fmt", "provenance_table", "scroll_table"]

PLOTLY_JS = "plotly.min.js"
PLOT_CONFIG = {"displaylogo": False, "responsive": True, "toImageButtonOptions": {"format": "svg"}}

_CSS = """
body{font-family:system-ui,-apple-system,Segoe UI,Roboto,sans-serif;margin:0;color:#222;background:#fafafa}
header{background:#1f3b73;color:#fff;padding:1em 2em}header h1{margin:0 0 .3em 0;font-size:1.5em}
main{padding:0 2em 3em 2em;max-width:1500px;box-sizing:border-box}
nav#toc{background:#fff;border:1px solid #ddd;padding:.5em 1.5em;margin:1em 0}
nav#toc ol ol{font-size:.92em}
section.scene,section.figure,section.audit{background:#fff;border:1px solid #ddd;padding:.5em 1.5em 1.5em;
  margin:1.5em 0;min-width:0;overflow-wrap:break-word}
h1,h2,h3,h4,th,summary{overflow-wrap:normal;word-break:normal;hyphens:manual}
section.figure>h2 .label{font-family:ui-monospace,monospace;font-weight:normal;color:#555;font-size:.8em}
p.finding{font-size:1.05em;border-left:4px solid #1f3b73;padding-left:.7em}
div.view{border-top:1px solid #eee;margin-top:1em}
.table-scroll{overflow-x:auto;max-width:100%}
table{border-collapse:collapse;margin:.5em 0;font-size:.9em}td,th{border:1px solid #ddd;padding:2px 8px;text-align:left}
th{background:#f0f0f0}.num{text-align:right;font-variant-numeric:tabular-nums}
table.audit{table-layout:fixed;width:100%;min-width:60em}table.audit td{vertical-align:top;overflow-wrap:anywhere}
table.audit col.c-claim{width:27%}table.audit col.c-paper{width:10%}table.audit col.c-ours{width:17%}
table.audit col.c-verdict{width:6em}table.audit col.c-cause{width:19%}table.audit col.c-reason{width:auto}
.v-agrees{color:#16691e;font-weight:bold}.v-differs{color:#b03a00;font-weight:bold}.v-notrun{color:#777;font-weight:bold}.v-unexplained{color:#8a0000;font-weight:bold}
.small{font-size:.85em;color:#555}
.note{color:#555;font-size:.9em}.warn{color:#a04000}.notrun{color:#777}
header .reduced{background:#fff3d6;color:#5a3000;padding:.3em .6em;margin:.4em 0;border-radius:3px}
.panel-error{color:#b00;border:1px solid #b00;padding:.5em;white-space:pre-wrap}
details{margin:.5em 0}summary{cursor:pointer;color:#1f3b73}
pre{white-space:pre-wrap}
.plot{margin:1em 0}.plot>.plotly-graph-div{background:#fcfcfc}code{font-size:.9em}
"""

#: Draws figures as they come near the viewport; sets data-ready after the first screen's figures.
_LOADER = """
(function () {
  var config = %(config)s;
  var pending = {};
  function draw(gd) {
    if (pending[gd.id]) return pending[gd.id];
    var spec = JSON.parse(document.getElementById(gd.id + '-spec').textContent);
    var p = Plotly.newPlot(gd, spec.data, spec.layout, config).then(function () {
      if (spec.frames) return Plotly.addFrames(gd, spec.frames);
    }).then(function () { gd.setAttribute('data-drawn', '1'); });
    pending[gd.id] = p;
    return p;
  }
  var divs = Array.prototype.slice.call(document.querySelectorAll('div.lazy-plot'));
  window.twolinkDrawAll = function () { return Promise.all(divs.map(draw)); };
  function ready() {
    var root = document.documentElement;
    if (!root.hasAttribute('data-ready')) root.setAttribute('data-ready', performance.now().toFixed(1));
  }
  if (!('IntersectionObserver' in window)) { window.twolinkDrawAll().then(ready); return; }
  var first = true;
  var io = new IntersectionObserver(function (entries) {
    var drawn = [];
    entries.forEach(function (e) {
      if (e.isIntersecting) { io.unobserve(e.target); drawn.push(draw(e.target)); }
    });
    if (first) { first = false; Promise.all(drawn).then(ready, ready); }
  }, {rootMargin: '300px 0px'});
  divs.forEach(function (d) { io.observe(d); });
  if (!divs.length) ready();
})();
"""


def esc(x) -> str:
    """HTML-escaped text of ``x``."""
    return html.escape(str(x))


def fmt(x, digits: int = 4) -> str:
    """A number with ``digits`` significant digits, "n/a" when not finite, else escaped text."""
    if x is None:
        return "n/a"
    try:
        v = float(x)
    except (TypeError, ValueError):
        return esc(x)
    return "n/a" if not np.isfinite(v) else f"{v:.{digits}g}"


def scroll_table(table_html: str) -> str:
    """A table inside its own horizontally scrolling box (it never widens its section)."""
    return f"<div class='table-scroll'>{table_html}</div>"


def _template() -> dict:
    """The report's plotly template (as JSON: white background, light grid, framed axes)."""
    axis = {"showgrid": True, "gridcolor": "#e5e5e5", "zeroline": False, "linecolor": "#444", "ticks": "outside",
            "mirror": True, "showline": True}
    return {"layout": {"font": {"family": "system-ui, sans-serif", "size": 12},
                       "plot_bgcolor": "white", "paper_bgcolor": "white",
                       "xaxis": axis, "yaxis": dict(axis), "colorway": [
                           "#1f77b4", "#ff7f0e", "#2ca02c", "#d62728", "#9467bd", "#8c564b"]}}


@dataclass
class Section:
    """One top-level section of the page: its anchor, table-of-contents line, HTML, and the
    sub-entries listed under it in the table of contents ((anchor, text) pairs)."""

    anchor: str
    toc: str
    body: str
    css_class: str = "scene"
    children: list = field(default_factory=list)


class SiteBuilder:
    """Collects sections and figures, then writes the site.

    Parameters
    ----------
    out : Path
        Output directory (created).
    """

    def __init__(self, out: Path):
        self.out = Path(out)
        self.sections: list[Section] = []
        self.front: str = ""          # HTML of the first section after the contents (the audit)
        #: the page's title; ``reduced``: a sentence saying the stores are of reduced resolution,
        #: put in the title and as the header's first line
        self.title = "Intermittent sliding of a two-link body: reproduction report"
        self.reduced = ""
        #: the shipped scenes without a store are listed (the header counts them)
        self.list_unrun = True
        self.not_run: list[dict] = []
        self.n_figures = 0
        self.n_stores = 0
        self.errors: list[str] = []
        self._template_json = _template()

    # -- figures -----------------------------------------------------------
    def figure(self, fig, note: str = "") -> str:
        """A figure as an empty div and its JSON spec; drawn when it scrolls into view."""
        from plotly.io.json import to_json_plotly

        self.n_figures += 1
        spec = fig if isinstance(fig, dict) else fig.to_plotly_json()
        spec = {"data": spec.get("data", []), "layout": dict(spec.get("layout", {})),
                **({"frames": spec["frames"]} if spec.get("frames") else {})}
        spec["layout"]["template"] = self._template_json
        height = int(spec["layout"].get("height") or 450)
        div_id = f"fig-{self.n_figures}"
        note_html = f"<p class='note'>{note}</p>" if note else ""
        # to_json_plotly escapes '<' and '/', so the JSON cannot close its script element.
        return (f"<div class='plot'>{note_html}<div id='{div_id}' class='plotly-graph-div lazy-plot' "
                f"style='height:{height}px;width:100%'></div><script type='application/json' id='{div_id}-spec'>"
                f"{to_json_plotly(spec)}</script></div>")

    def maybe_figure(self, fig) -> str:
        return "" if fig is None else self.figure(fig)

    def guarded(self, what: str, build) -> str:
        """HTML from ``build()``; an exception becomes a visible error box (and a stderr line)."""
        try:
            return build()
        except Exception as exc:  # one bad panel must not cost the whole report
            msg = f"{what}: {type(exc).__name__}: {exc}"
            self.errors.append(msg)
            print(f"reports: warning: {msg}", file=sys.stderr)
            tb = traceback.format_exc(limit=3)
            return f"<div class='panel-error'>panel failed — {esc(msg)}\n{esc(tb)}</div>"

    def add_not_run(self, entry: dict) -> None:
        self.not_run.append(entry)

    # -- output ------------------------------------------------------------
    def _toc(self) -> str:
        out = ["<nav id='toc'><h2>Contents</h2><ol>"]
        if self.front:
            out.append("<li><a href='#audit'>Reproduction audit</a></li>")
        for s in self.sections:
            sub = "".join(f"<li><a href='#{a}'>{t}</a></li>" for a, t in s.children)
            out.append(f"<li><a href='#{s.anchor}'>{s.toc}</a>" + (f"<ol>{sub}</ol>" if sub else "") + "</li>")
        for e in self.not_run:
            out.append(f"<li class='notrun'>{esc(e['name'])} — not yet run (<code>{esc(e.get('command', ''))}</code>)</li>")
        out.append("</ol></nav>")
        return "".join(out)

    def write(self) -> Path:
        from plotly.offline import get_plotlyjs

        self.out.mkdir(parents=True, exist_ok=True)
        js = self.out / PLOTLY_JS
        text = get_plotlyjs()
        if not js.is_file() or js.read_text(encoding="utf-8") != text:
            js.write_text(text, encoding="utf-8")
        now = _dt.datetime.now(_dt.timezone.utc).isoformat(timespec="seconds")
        not_run = ""
        if self.not_run:
            rows = "".join(f"<tr><td>{esc(e['name'])}</td><td>{esc(e.get('title', ''))}</td>"
                           f"<td>{esc(e.get('figure', ''))}</td><td><code>{esc(e.get('command', ''))}</code></td></tr>"
                           for e in self.not_run)
            not_run = ("<section class='scene' id='not-run'><h2>Scenes not yet run</h2>" + scroll_table(
                "<table><tr><th>scene</th><th>title</th><th>paper figure</th><th>command</th></tr>"
                f"{rows}</table>") + "</section>")
        errors = ""
        if self.errors:
            errors = ("<p class='panel-error'>" + f"{len(self.errors)} panel(s) failed to build:<br>"
                      + "<br>".join(esc(e) for e in self.errors) + "</p>")
        body = "\n".join(f"<section class='{s.css_class}' id='{s.anchor}'>{s.body}</section>" for s in self.sections)
        loader = _LOADER % {"config": json.dumps(PLOT_CONFIG)}
        title = self.title + (" (reduced resolution)" if self.reduced else "")
        reduced = f"<p class='reduced'><b>Reduced resolution.</b> {esc(self.reduced)}</p>\n" if self.reduced else ""
        not_run_count = f"; {len(self.not_run)} scene(s) not yet run" if self.list_unrun else ""
        doc = f"""<!DOCTYPE html>
<html lang="en"><head><meta charset="utf-8">
<meta name="viewport" content="width=device-width, initial-scale=1">
<title>{esc(title)}</title>
<style>{_CSS}</style>
<script src="{PLOTLY_JS}" defer></script>
</head><body>
<header><h1>{esc(title)}</h1>
{reduced}<div>Built {now} from {self.n_stores} store(s){not_run_count}. Static and offline:
every figure is interactive (hover for values and parameters, drag to zoom, double-click to reset) and is
drawn when it scrolls into view.</div></header>
<main>
{errors}
{self._toc()}
{self.front}
{body}
{not_run}
</main>
<footer class='small' style='padding:0 2em 2em'>{_versions_line()}</footer>
<script>document.addEventListener('DOMContentLoaded', function () {{{loader}}});</script>
</body></html>
"""
        index = self.out / "index.html"
        index.write_text(doc, encoding="utf-8")
        return index


def _versions_line() -> str:
    """The footer: the package and solver engine versions that built the report."""
    from solver._version import DISTRIBUTION, engine_versions_text, package_version

    return (f"Built by {DISTRIBUTION} {esc(package_version())} (solver engines {esc(engine_versions_text())}); "
            "each store's own versions are in its provenance.")


# ---------------------------------------------------------------------------
# Provenance (every kind of section opens with it)
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
        parts.append(f"{esc(run.get('workers', '?'))} worker(s), {esc(run.get('scheduler', '?'))} scheduler")
    text = "last run: " + ", ".join(parts)
    if "finished" in run:
        text += f", finished {esc(run['finished'])}"
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
        ("scene hash", f"<code title='{esc(pv.get('scene_hash', ''))}'>{esc(pv.get('scene_hash', '')[:16])}…</code>"),
        ("scene file", f"<code>{esc(pv.get('scene_file', ''))}</code>"),
        ("package version", esc(pv.get("package_version", "?"))),
        ("engine versions", esc(", ".join(f"{k} {v}" for k, v in sorted((pv.get("engines") or {}).items())) or "?")),
        ("git commit", f"<code>{esc(pv.get('git_commit') or 'unknown')}</code>"),
        ("created (UTC)", esc(pv.get("created", "?"))),
        ("host", esc(pv.get("host", "?"))),
        ("run time", _run_time(sd.meta)),
        *kind_rows,
        ("libraries", esc(libs)),
        ("store", f"<code>{esc(sd.path)}</code>"),
    ]
    body = "".join(f"<tr><th>{k}</th><td>{v}</td></tr>" for k, v in rows)
    toml = pv.get("scene_toml")
    extra = f"<details><summary>scene file</summary><pre>{esc(toml)}</pre></details>" if toml else ""
    return f"<details><summary>Provenance</summary>{scroll_table(f'<table>{body}</table>')}{extra}</details>"
