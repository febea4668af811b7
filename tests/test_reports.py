"""The static report: built from real (tiny) pipeline stores and from full-resolution synthetic
stores of every shipped scene, then opened in headless chromium.

Browser checks are skipped (with the reason) only when chromium is not installed.
"""

from __future__ import annotations

import json
import os
import re
import subprocess
import sys
import warnings
from pathlib import Path

import numpy as np
import pytest

import report_helpers as rh

REPO = Path(__file__).resolve().parent.parent
SHIPPED = sorted(p.stem for p in (REPO / "workflows").glob("*.toml"))
MB = 1024 * 1024


def _cli(*args, cwd) -> subprocess.CompletedProcess:
    env = dict(os.environ, PYTHONPATH=str(REPO) + os.pathsep + os.environ.get("PYTHONPATH", ""))
    return subprocess.run([sys.executable, "-m", "reports", *map(str, args)], cwd=cwd, env=env,
                          capture_output=True, text=True, timeout=300)


@pytest.fixture(scope="module")
def site(tmp_path_factory):
    """``out/`` holding the three tiny real stores and a synthetic store of every shipped scene;
    the report built by ``python -m reports build`` with no store arguments (default: every store under out/)."""
    root = tmp_path_factory.mktemp("site")
    out = root / "out"
    out.mkdir()
    for name in rh.SCENES:
        rh.build_store(out, name)
    for name in SHIPPED:
        rh.synthetic_store(out / f"{name}.zarr", REPO / "workflows" / f"{name}.toml")
    proc = _cli("build", cwd=root)
    assert proc.returncode == 0, proc.stderr
    index = out / "report" / "index.html"
    return {"root": root, "out": out, "index": index, "html": index.read_text(encoding="utf-8"),
            "stdout": proc.stdout, "stderr": proc.stderr}


@pytest.fixture(scope="module")
def browser(site):
    if rh.chromium() is None:
        pytest.skip("chromium not installed (apt-get install -y chromium)")
    return rh.probe(site["index"])


@pytest.fixture(scope="module")
def opened(site):
    """The report opened as a reader would, 1280 px wide: time to ready, tables' layout."""
    if rh.chromium() is None:
        pytest.skip("chromium not installed (apt-get install -y chromium)")
    return rh.page_ready(site["index"], width=1280, repeats=2)


# ---------------------------------------------------------------------------
# Static structure
# ---------------------------------------------------------------------------


def _view(html: str, anchor: str) -> str:
    """The HTML of one store view: from its h3 to the next view or section."""
    start = html.index(f"<h3 id='{anchor}'>")
    return re.split(r"<div class='view'>|</section>", html[start:], maxsplit=1)[0]


def test_plotly_js_included_once_and_offline(site):
    html = site["html"]
    js = site["index"].parent / "plotly.min.js"
    assert js.is_file() and js.stat().st_size > 1 * MB
    # Referenced once, relatively (deferred: the first layout does not wait for it); never inlined.
    assert html.count("<script src=") == 1
    assert html.count('<script src="plotly.min.js" defer></script>') == 1
    assert "plotly.js v" not in html
    # One loader draws every figure from its JSON spec when it scrolls into view.
    n_divs = html.count("class='plotly-graph-div lazy-plot'")
    assert len(re.findall(r"Plotly\.newPlot\(", html)) == 1
    assert "IntersectionObserver" in html
    assert len(re.findall(r"<script type='application/json' id='fig-\d+-spec'>", html)) == n_divs > 20
    # Nothing loaded from the network.
    assert not re.search(r"""(src|href)=["']?(https?:)?//""", html)


def test_one_view_per_scene_with_toc(site):
    html = site["html"]
    names = sorted(list(rh.SCENES) + SHIPPED)
    for name in names:
        assert f"<a href='#scene-{name}'>" in html, name
        assert f"<h3 id='scene-{name}'>" in html, name
    assert "panel failed" not in html, re.findall(r"panel failed[^<]*", html)
    assert "not yet run" not in html.split("<nav id='toc'>")[1].split("</nav>")[0]
    assert f"report: {site['index'].relative_to(site['root'])}" in site["stdout"]


def test_contents_then_audit_then_figures_in_the_papers_order_then_studies(site):
    from reports._paper import load_figures

    html = site["html"]
    positions = [html.index(f"<section class='figure' id='fig-{f.label}'>") for f in load_figures()]
    assert html.index("<nav id='toc'>") < html.index("id='audit'") < positions[0]
    assert positions == sorted(positions)
    assert positions[-1] < html.index("id='scene-accuracy'") < html.index("id='honest-tolerances'")
    # a figure section opens with its label and what the paper found there
    fig = html.split("id='fig-EtaA0A1'>")[1]
    assert fig.startswith("<h2>Figure 3 <span class='label'>fig:EtaA0A1</span>")
    assert "<p class='finding'><b>The paper:</b>" in fig.split("<div class='view'>")[0]
    # a scene drawing two figures is split between them; test scenes land under their figure
    diag1 = html.split("id='fig-UPEtaDiag1'>")[1].split("</section>")[0]
    assert "id='scene-harmonic_diagonals'" in diag1 and "anisotropy_ratio = 16" in diag1
    assert "id='scene-harmonic_diagonals-2'" in html.split("id='fig-UPEtaDiag2'>")[1].split("</section>")[0]
    assert "id='scene-tiny_plane'" in html.split("id='fig-UEtaMax'>")[1].split("</section>")[0]


def _window_pending(row) -> bool:
    """Until the scene files repeat their reductions over τ0 windows (issue 44, the polish
    helper's scene change), a claim on the paper's τ0 window is "not run" for that reason and no
    other; once a scene defines the window, its claims must run."""
    import tomllib

    if "no τ0 window" not in row["reason"]:
        return False
    for name in row["scenes"]:
        doc = tomllib.loads((Path(__file__).resolve().parent.parent / "workflows" / f"{name}.toml").read_text())
        if any("window" in r for r in doc.get("reductions", [])):
            return False
    return True


def test_audit_is_written_and_every_claim_reads_the_full_resolution_scenes(site):
    """Synthetic stores of every shipped scene at full resolution: every claim finds its cells
    (agrees or differs, never not run) and audit.json matches the table."""
    from reports._audit import load_claims

    doc = json.loads((site["index"].parent / "audit.json").read_text())
    assert [o["id"] for o in doc] == [c.id for c in load_claims()]
    not_run = [(o["id"], o["reason"]) for o in doc if o["verdict"] == "not run"
               and not _window_pending(o)]
    assert not not_run, not_run
    audit = site["html"].split("id='audit'>")[1].split("</section>")[0]
    assert audit.count("<tr id='claim-") == len(doc)
    for o in doc[:5]:
        assert f"<tr id='claim-{o['id']}'>" in audit


def test_section_states_provenance_failures_and_errors(site):
    import pipeline

    html = site["html"]
    section = _view(html, "scene-tiny_plane")
    scene = pipeline.parse_scene(rh.PLANE)
    assert scene.hash[:16] in section
    for key in ("package version", "created (UTC)", "run time", "git commit"):
        assert f"<th>{key}</th>" in section
    assert re.search(r"<th>run time</th><td>last run: [0-9.]+ s wall", section)
    assert "36 points" in section
    assert "Solver error estimate over the" in section
    assert "grid and polished maxima side by side" in section
    # The synthetic stores carry failures with status 6: counted and explained.
    grid = _view(html, "scene-harmonic_grid")
    n_failed = len(range(0, 9 * 64 * 64, 997))
    assert f"<b>{n_failed:,} failures</b>" in grid
    assert "its refinement rounds ran out before the error estimate fell below rtol" in grid
    # Axis labels in the paper's notation, powers of two on log2 axes.
    assert "μ<sub>n</sub>/μ<sub>s</sub>" in html and "(μ<sub>n</sub>μ<sub>s</sub>)<sup>1/4</sup> T" in html
    assert "2<sup>-4</sup>" in html and "λ/λ<sub>ub</sub>" in html and "A<sub>1</sub>/A<sub>0</sub>" in html


def test_polished_reductions_say_status_uncertainty_and_edges(site):
    """Issue 44, item 3: a polished reduction's summary and table say whether each maximum
    converged, how well, and which domain ends its arg-max lies on."""
    section = _view(site["html"], "scene-tiny_plane")
    # its scene caps the polish at 6 solves per start (report_helpers.PLANE): said, never "converged"
    assert re.search(r"polish status: (\d+ converged, )?\d+ cap reached \(not converged\)", section)
    assert "<td>cap reached (not converged)</td>" in section
    assert "relative uncertainty median" in section
    assert "<th>uncertainty (relative)</th><th>on the domain's edge</th>" in section
    synthetic = _view(site["html"], "scene-duty_cycle")  # report_helpers puts tau0 on its upper edge
    assert "arg-max on the polish domain's edge: τ<sub>0</sub> at its lower end in 0 cells, upper end in 200;" in synthetic
    assert "upper</td>" in synthetic


def test_optima_section_has_motions_curves_and_outcomes(site):
    import pipeline

    html = site["html"]
    section = _view(html, "scene-tiny_optima")
    assert pipeline.parse_scene(rh.OPTIMA).hash[:16] in section
    for key in ("package version", "created (UTC)", "run time", "git commit", "ensemble"):
        assert f"<th>{key}</th>" in section
    assert "2 ratios" not in section and "= 8 optimisations" in section
    assert "Optimisations, stop reasons and cost" in section and "ill-conditioned" in section
    # one phi(tau) figure and one efficiency/period figure per p; hover carries the coefficients
    assert section.count("class='plotly-graph-div lazy-plot'") == 2
    spec = section.split("<script type='application/json'")[1]
    assert "Best optimal" in spec and "A1 = " in spec and "K\\u003csub\\u003emax" in spec
    # force_laws: one view per p (figures OptMotionsp0p5, p1, p1p5), two figures each
    for anchor in ("scene-force_laws", "scene-force_laws-2", "scene-force_laws-3"):
        assert _view(html, anchor).count("class='plotly-graph-div lazy-plot'") == 2, anchor


def test_report_of_all_scenes_under_25_mb(site):
    files = [f for f in site["index"].parent.rglob("*") if f.is_file()]
    total = sum(f.stat().st_size for f in files)
    assert total < 25 * MB, f"report is {total / MB:.1f} MB"


# ---------------------------------------------------------------------------
# In the browser
# ---------------------------------------------------------------------------


def test_every_figure_renders_with_data(site, browser):
    n_divs = site["html"].count("class='plotly-graph-div lazy-plot'")
    plots = browser["plots"]
    assert browser["plotly"], "Plotly not defined in the page"
    assert len(plots) == n_divs
    bad = [p for p in plots if not (p["rendered"] and p["traces"] > 0 and p["points"] > 0)]
    assert not bad, bad


#: The issue's target: the full report ready in at most 5 s in Chromium (today's eager drawing: 22 s).
READY_SECONDS = 5.0


def test_page_is_ready_within_5_s_and_draws_only_what_is_in_view(site, opened):
    """Time from navigation to the page's ``data-ready`` mark (set once the first screen's figures
    are drawn), for a report of every shipped scene at full size."""
    size = sum(f.stat().st_size for f in site["index"].parent.iterdir() if f.is_file())
    assert size > 5 * MB  # a report as large as the real one
    assert opened["wall_seconds"] <= READY_SECONDS, opened
    assert opened["page_ms"] <= 1000 * READY_SECONDS, opened
    assert opened["figures"] == site["html"].count("class='plotly-graph-div lazy-plot'")
    assert opened["drawn"] < opened["figures"] / 4, opened  # figures below the fold wait


def test_no_table_is_wider_than_its_section_at_1280_px(opened):
    layout = opened["layout"]
    assert layout["viewport"] == 1280
    assert layout["tables"] > 20
    assert layout["bad"] == [], layout["bad"]
    assert layout["wide_sections"] == [], layout["wide_sections"]
    assert layout["page"] <= layout["viewport"]


#: Words of letters (a run of them has no legitimate break) split over two lines in a header
#: or a table's header cell, and header cells whose text overflows them, every <details> open.
BROKEN_HEADERS = r"""(function () {
  document.querySelectorAll('details').forEach(function (d) { d.open = true; });
  var broken = [], words = 0, over = [];
  document.querySelectorAll('h1, h2, h3, h4, th, summary').forEach(function (el) {
    var walker = document.createTreeWalker(el, NodeFilter.SHOW_TEXT);
    for (var node = walker.nextNode(); node; node = walker.nextNode()) {
      var re = /[A-Za-z\u00C0-\u024F\u0370-\u03FF]{2,}/g, m;
      while ((m = re.exec(node.data))) {
        words += 1;
        var r = document.createRange();
        r.setStart(node, m.index);
        r.setEnd(node, m.index + m[0].length);
        var tops = {};
        Array.prototype.forEach.call(r.getClientRects(), function (q) { if (q.width > 0) tops[Math.round(q.top)] = 1; });
        if (Object.keys(tops).length > 1) broken.push(el.tagName + ': ' + m[0] + ' in "' + el.textContent.slice(0, 60) + '"');
      }
    }
    if (el.tagName === 'TH' && el.scrollWidth > el.clientWidth + 1) over.push(el.textContent.slice(0, 40));
  });
  return {words: words, broken: broken, over: over};
})()"""


@pytest.mark.parametrize("width", [1280, 700])
def test_no_header_breaks_a_word(site, width):
    """Issue 45: ``overflow-wrap: anywhere`` on every section broke table headers mid-word
    (67 words at 1280 px in the quick paper's report, e.g. "verdi|ct", "optimi|sations")."""
    if rh.chromium() is None:
        pytest.skip("chromium not installed (apt-get install -y chromium)")
    with rh.Browser(width=width) as b:
        b.open(site["index"])
        r = b.evaluate(BROKEN_HEADERS)
    assert r["words"] > 500
    assert r["broken"] == [] and r["over"] == []


def test_no_javascript_errors(browser):
    assert browser["errors"] == []


def test_animation_has_frames_and_controls(site, browser):
    anims = [p for p in browser["plots"] if p["frames"] > 0]
    # One animation per grid scene with an optimum (every grid scene here has a reduction;
    # optima and study scenes have none).
    from reports._paper import load_figures

    grid = [n for n in SHIPPED if 'kind = "' not in (REPO / "workflows" / f"{n}.toml").read_text()]
    # a scene drawing several figures has one view, and so one animation, per figure
    views = [v.scene for f in load_figures() for v in f.views]
    assert len(anims) == len(rh.ANIMATED) + sum(max(1, views.count(n)) for n in grid)
    for p in anims:
        assert p["frames"] >= 48 and p["sliders"] == 1 and p["buttons"] == 1


# ---------------------------------------------------------------------------
# Scenes not yet run, refused stores
# ---------------------------------------------------------------------------


def test_scenes_not_run_are_listed(tmp_path):
    import reports

    index = reports.build_report([], tmp_path / "report")
    html = index.read_text()
    toc = html.split("<nav id='toc'>")[1].split("</nav>")[0]
    for name in SHIPPED:
        assert f"{name} — not yet run" in toc
    assert "Built " in html and " from 0 store(s)" in html


def test_count_is_of_stores_read(site):
    n = len(list(site["out"].glob("*.zarr")))
    assert f"({n} store(s) read, " in site["stdout"], site["stdout"]
    assert f" from {n} store(s);" in site["html"]


def test_refuses_a_path_that_does_not_exist(site, tmp_path):
    """A mistyped path is an error naming it (exit 2, one line, nothing written), even beside a
    store that reads, and not a scene "not yet run"."""
    missing = tmp_path / "no" / "such.zarr"
    out = tmp_path / "report"
    proc = _cli("build", site["out"] / "quick.zarr", missing, "--out", out, cwd=tmp_path)
    assert proc.returncode == 2, proc.stdout
    lines = proc.stderr.strip().splitlines()
    assert lines == [f"error: {missing}: no such store"], proc.stderr
    assert proc.stdout == "" and not out.exists()
    # a folder of stores is named as such
    proc = _cli("build", site["out"], "--out", out, cwd=tmp_path)
    assert proc.returncode == 2 and "a folder of " in proc.stderr and not out.exists(), proc.stderr
    # control: the same command without the mistyped path builds
    proc = _cli("build", site["out"] / "quick.zarr", "--out", out, cwd=tmp_path)
    assert proc.returncode == 0 and "(1 store(s) read, " in proc.stdout, proc.stderr


def test_incomplete_store_is_reported_not_fatal(tmp_path):
    """A store whose run was interrupted before any task: every section still builds."""
    import pipeline
    import reports
    from pipeline import _store

    scene = pipeline.load_scene(REPO / "workflows" / "linear_two_phase.toml")
    store = tmp_path / "linear_two_phase.zarr"
    _store.create_skeleton(store, scene, (1, 1, 10, 10, 10))
    html = reports.build_report([store], tmp_path / "report", list_unrun=False).read_text()
    assert "This store is incomplete" in html
    assert "panel failed" not in html
    assert f"{scene.n_points:,} points; 0 computed" in html


def _group(path: Path, attrs: dict | None, zarr_format: int = 3) -> Path:
    import zarr

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        g = zarr.open_group(str(path), mode="w", zarr_format=zarr_format)
        if attrs is not None:
            g.attrs.update(attrs)
    return path


def test_reads_the_optima_layout_version():
    from pipeline import _optima

    from reports import _optima as report_optima

    assert report_optima.KIND_VERSION == _optima.KIND_VERSION


def test_reads_the_pipelines_format_version():
    from pipeline import _store

    import reports

    assert reports.SUPPORTED_FORMAT == _store.FORMAT_VERSION


@pytest.mark.parametrize("kind, message", [
    ("newer", "store format version 4 is newer than the versions this report reads (1, 2, 3)"),
    ("foreign", "not a pipeline store"),
    ("zarr2", "a Zarr format 2 store"),
    ("not_zarr", "not a Zarr store"),
])
def test_refuses_other_formats(tmp_path, kind, message):
    store = tmp_path / "x.zarr"
    if kind == "newer":
        _group(store, {"pipeline": json.dumps({"format_version": 4, "provenance": {}, "layout": {}, "state": {}})})
    elif kind == "foreign":
        _group(store, {"something": 1})
    elif kind == "zarr2":
        _group(store, {"pipeline": {}}, zarr_format=2)
    else:
        store.mkdir()
        (store / "data.bin").write_bytes(b"\0")
    out = tmp_path / "report"
    proc = _cli("build", store, "--out", out, cwd=tmp_path)
    assert proc.returncode == 2
    lines = proc.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith(f"error: {store}: ") and message in lines[0], proc.stderr
    assert not out.exists()


# ---------------------------------------------------------------------------
# Motions: the force field and the path agree with the solver
# ---------------------------------------------------------------------------


def test_force_density_integrates_to_the_solvers_force():
    """2 * int_0^{1/2} f_x(s) ds is the solver's F (eq. Newtonu), for Coulomb and p = 1/2."""
    import solver
    from reports._motion import force_density

    rng = np.random.default_rng(3)
    x, w = np.polynomial.legendre.leggauss(200)
    s, ws = 0.25 * (x + 1), 0.25 * w
    for p in (0.0, 0.5):
        for _ in range(5):
            u, phi, omega = rng.normal(0, 0.5), rng.uniform(0.2, 2.9), rng.normal(0, 3)
            mu_n, mu_s, delta_tau = 2.0, 0.5, 1e-2
            f = force_density([u], [phi], [omega], mu_n, mu_s, p, delta_tau, s)[0]
            F, _ = solver.force_and_slope(u, phi, omega, mu_n, mu_s, p, delta_tau)
            assert 2 * np.dot(ws, f) == pytest.approx(F, rel=1e-6, abs=1e-10)


def test_motion_reproduces_the_stored_series_and_speed(site):
    import xarray as xr

    from reports._motion import compute_motion

    store = site["out"] / "tiny_plane.zarr"
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        ds = xr.open_zarr(str(store)).load()
    i = 0
    params = {d: float(ds[f"series_{d}"].values[i]) for d in ("anisotropy_ratio", "scaled_period", "A0", "A1_ratio")}
    m = compute_motion("harmonic", {**params, "p": 0.0, "delta": 1e-5}, rtol=1e-3, n_tau=32)
    np.testing.assert_allclose(m.u, ds["series_u"].values[i], rtol=1e-9, atol=1e-12)
    # x_cm after one period is T U = scaled period * scaled speed (mu_n mu_s = 1).
    sel = ds["scaled_speed"].sel(anisotropy_ratio=params["anisotropy_ratio"], scaled_period=params["scaled_period"],
                                 A0=params["A0"], A1_ratio=params["A1_ratio"])
    assert m.displacement == pytest.approx(params["scaled_period"] * float(sel), rel=1e-6)
    # The body's centre of mass: the mean of the two links' points is x_cm.
    from reports._motion import body_outline

    bx, by = body_outline(m.x_cm, m.phi)
    np.testing.assert_allclose(0.5 * (bx[:, 0] + bx[:, 1]), m.x_cm)
    np.testing.assert_allclose(by[:, 0], -by[:, 2])


# ---------------------------------------------------------------------------
# Reports bounded by the screen (issue 36)
# ---------------------------------------------------------------------------

#: 2 x 1 x 1000 x 1000 = 2,000,000 points: two 1,000,000-point (A0, A1/A0) planes, a reduction
#: keeping the whole plane (its maps and 1,000 curves) and one keeping the anisotropy axis.
BIG_PLANE = """
[scene]
name = "big_plane"
title = "report test: two 1000 x 1000 planes"
figure = "UEtaMax (test)"
family = "harmonic"

[axes]
anisotropy_ratio = { values = [0.25, 4.0] }
scaled_period = { values = [2.0] }
A0 = { range = [0.01, 1.5], num = 1000 }
A1_ratio = { range = [0.01, 0.99], num = 1000 }

[solver]
rtol = 1e-4

[outputs]
quantities = ["scaled_efficiency", "relative_efficiency"]
diagnostics = ["error_estimate"]

[[reductions]]
name = "best_ratio"
quantity = "scaled_efficiency"
statistic = "absmax"
over = ["anisotropy_ratio"]
report = ["relative_efficiency"]
polish = true

[[reductions]]
name = "best_shape"
quantity = "scaled_efficiency"
statistic = "max"
over = ["A0", "A1_ratio"]

[execution]
points_per_chunk = 250000
"""


def _specs(html: str) -> list[dict]:
    return [json.loads(m) for m in re.findall(r"<script type='application/json' id='fig-\d+-spec'>(.*?)</script>",
                                               html, flags=re.S)]


@pytest.fixture(scope="module")
def big_site(tmp_path_factory):
    root = tmp_path_factory.mktemp("big")
    (root / "big_plane.toml").write_text(BIG_PLANE)
    store = rh.synthetic_store(root / "big_plane.zarr", root / "big_plane.toml")
    proc = _cli("build", store, "--out", root / "report", "--no-unrun", cwd=root)
    assert proc.returncode == 0, proc.stderr
    index = root / "report" / "index.html"
    return {"store": store, "index": index, "html": index.read_text(encoding="utf-8"), "stderr": proc.stderr}


def test_report_of_a_million_point_plane_is_under_25_mb(big_site):
    """Maps are aggregated to the screen, so the report does not grow with the scene: the two
    1,000,000-point planes (31 MB for one plane before issue 36) stay under 25 MB in all."""
    files = [f for f in big_site["index"].parent.rglob("*") if f.is_file()]
    total = sum(f.stat().st_size for f in files)
    assert total < 25 * MB, f"report is {total / MB:.1f} MB"
    assert "panel failed" not in big_site["html"], big_site["stderr"]


def test_every_map_panel_is_at_most_400_cells_a_side_and_says_how(big_site):
    from reports._panels import MAX_LINES, MAX_MAP_CELLS

    specs = _specs(big_site["html"])
    maps = [t for s in specs for t in s["data"] if t["type"] in ("heatmap", "contour")]
    assert len(maps) >= 6  # 3 quantities x 2 facets; the reduction's maps
    for t in maps:
        z = t["z"]
        assert len(z) <= MAX_MAP_CELLS and max(len(row) for row in z) <= MAX_MAP_CELLS
    titles = [s["layout"]["title"]["text"] for s in specs if s["layout"].get("title")]
    quantity = [t for t in titles if "block mean" in t]
    reduction = [t for t in titles if "block max" in t]
    assert len(quantity) == 3 and len(reduction) == 1, titles
    assert all("of 1,000 × 1,000 cells" in t for t in quantity + reduction)
    # curves over one axis of the kept plane: at most MAX_LINES lines, and the title says so
    curves = [s for s in specs if "values of" in (s["layout"].get("title") or {}).get("text", "")]
    assert curves and all(len({t["name"].rsplit(" ", 1)[0] for t in s["data"]}) <= MAX_LINES for s in curves)
    # the way to the full data, once per map figure
    assert big_site["html"].count("full-resolution data") == 3 + 2  # 2 quantities and the error; 2 reductions
    assert f"xr.open_zarr({str(big_site['store'])!r}" in html_unescape(big_site["html"])


def test_curves_of_more_than_max_markers_points_are_drawn_without_markers(big_site, site):
    """A refined scene's curves (1,000 points each) are lines, and their title says so: their
    markers took chromium 5.1 s to draw. The shipped scenes' curves keep their markers (control)."""
    from reports._panels import MAX_MARKERS

    def curves(html):  # the reductions' curves: one trace per (line, grid or polished optimum)
        return [(s, t) for s in _specs(html) for t in s["data"]
                if t["type"] == "scatter" and str(t.get("name", "")).endswith(("grid", "polished"))]

    dense = [(s, t) for s, t in curves(big_site["html"]) if _length(t["x"]) > MAX_MARKERS]
    assert dense and all("markers" not in t["mode"] for _, t in dense)
    assert all("drawn without markers" in s["layout"]["title"]["text"] for s, _ in dense)
    coarse = [t for _, t in curves(site["html"]) if 1 < _length(t["x"]) <= MAX_MARKERS]
    assert any("markers" in t.get("mode", "") for t in coarse)


def _length(v) -> int:
    if isinstance(v, dict):  # a typed array
        import base64

        return len(base64.b64decode(v["bdata"])) // np.dtype(v["dtype"]).itemsize
    return len(v)


def html_unescape(text: str) -> str:
    import html

    return html.unescape(text)


def test_block_helpers_against_brute_force():
    """Block mean, max and pick against loops over the blocks, on a plane whose size is no
    multiple of the block (partial last blocks) with NaN cells and an all-NaN block."""
    from reports._panels import block_pick, block_reduce, map_blocks

    rng = np.random.default_rng(3)
    a = rng.normal(size=(23, 17))
    a[rng.random(a.shape) < 0.2] = np.nan
    a[0:4, 0:3] = np.nan  # one whole block without a finite cell
    b = map_blocks(23, 17, limit=6)
    assert (b.ky, b.kx, b.my, b.mx) == (4, 3, 6, 6)
    mean, mx, pick = block_reduce(a, b, "mean"), block_reduce(a, b, "max"), block_pick(a, b)
    for i in range(b.my):
        for j in range(b.mx):
            block = a[i * 4:(i + 1) * 4, j * 3:(j + 1) * 3]
            fin = block[np.isfinite(block)]
            if fin.size == 0:
                assert np.isnan(mean[i, j]) and np.isnan(mx[i, j])
                assert pick[i, j] == i * 4 * 17 + j * 3  # the block's first cell
                continue
            assert mean[i, j] == pytest.approx(fin.mean(), rel=1e-12)
            assert mx[i, j] == fin.max()
            assert a.ravel()[pick[i, j]] == fin.max()
            r, c = divmod(int(pick[i, j]), 17)
            assert i * 4 <= r < (i + 1) * 4 and j * 3 <= c < (j + 1) * 3
    # a plane within the limit is drawn as it is
    small = map_blocks(23, 17, limit=400)
    assert not small.decimated and np.array_equal(block_reduce(a, small), a, equal_nan=True)
    # more panels, fewer cells each
    assert map_blocks(1000, 1000, panels=1).ky == 3 and map_blocks(1000, 1000, panels=4).ky == 5


@pytest.mark.parametrize("dtype", ["float64", "float32", "int64", "int32", "int16", "int8", "uint64", "uint8", "bool"])
@pytest.mark.parametrize("shape", [(7,), (3, 5), (0,)])
def test_typed_array_spec_is_plotlys_encoding(dtype, shape):
    """reports._figure.typed_array_spec (ours, so the package imports no private plotly module)
    gives what plotly.py's own encoder gives, byte for byte, dtype narrowing included; a 64-bit
    integer beyond 32 bits stays an array (the control: plotly.js has no such typed array)."""
    _plotly_utils = pytest.importorskip("_plotly_utils.utils")
    from reports._figure import typed_array_spec

    rng = np.random.default_rng(0)
    for scale in (1, 100, 40_000, 3_000_000_000):
        with np.errstate(invalid="ignore", over="ignore"):  # wrapped casts are fine test data
            v = (rng.standard_normal(shape) * scale).astype(dtype) if dtype != "bool" else rng.random(shape) > 0.5
            if dtype.startswith("uint"):
                v = np.abs(rng.standard_normal(shape) * scale).astype(dtype)
        ours, theirs = typed_array_spec(v), _plotly_utils.to_typed_array_spec(v)
        assert type(ours) is type(theirs)
        if isinstance(ours, dict):
            assert ours == theirs
        else:
            assert np.array_equal(ours, theirs)
    big = np.array([0, 2**40], dtype=np.int64)
    assert isinstance(typed_array_spec(big), np.ndarray)
