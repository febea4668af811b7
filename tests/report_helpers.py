"""Helpers for the report tests: small stores built with the pipeline, and a headless-browser probe."""

from __future__ import annotations

import html
import json
import os
import re
import shutil
import subprocess
import tempfile
from pathlib import Path

#: A tiny harmonic scene on the (mu_n/mu_s, scaled period) plane: 2 x 2 x 3 x 3 = 36 points,
#: one polished reduction, error estimates and two series points.
PLANE = """
[scene]
name = "tiny_plane"
title = "report test: harmonic plane"
figure = "UEtaMax (test)"
family = "harmonic"

[axes]
anisotropy_ratio = { values = [0.0625, 16.0] }
scaled_period = { log2_range = [0, 1], step = 1 }
A0 = { range = [0.4, 1.4], num = 3 }
A1_ratio = { range = [0.3, 0.8], num = 3 }

[fixed]
p = 0.0
delta = 1e-5

[solver]
method = "periodic"
rtol = 1e-3

[outputs]
quantities = ["scaled_speed", "scaled_efficiency", "relative_efficiency"]
diagnostics = ["error_estimate"]

[[reductions]]
name = "best_efficiency"
quantity = "scaled_efficiency"
statistic = "absmax"
over = ["A0", "A1_ratio"]
report = ["relative_efficiency"]
polish = true
polish_max_evaluations = 6

[series]
n_tau = 32
points = [{ anisotropy_ratio = 16.0, scaled_period = 2.0, A0 = 0.4, A1_ratio = 0.8 },
          { anisotropy_ratio = 0.0625, scaled_period = 1.0, A0 = 1.4, A1_ratio = 0.3 }]

[execution]
points_per_chunk = 9
points_per_task = 9
"""

#: The 3 x 3 (T^2 mu_n, T^2 mu_s) grid of figure EtaA0A1 at a tiny resolution: 9 x 3 x 3 points,
#: a reduction keeping the whole facet plane, no polishing.
FACETS = """
[scene]
name = "tiny_facets"
title = "report test: T^2 mu grid"
figure = "EtaA0A1 (test)"
family = "harmonic"

[axes]
T2_mu_n = { values = [0.0625, 1.0, 16.0] }
T2_mu_s = { values = [0.0625, 1.0, 16.0] }
A0 = { range = [0.5, 1.3], num = 3 }
A1_ratio = { range = [0.3, 0.7], num = 3 }

[solver]
rtol = 1e-3

[outputs]
quantities = ["scaled_efficiency"]

[[reductions]]
name = "best_efficiency"
quantity = "scaled_efficiency"
statistic = "absmax"
over = ["A0", "A1_ratio"]

[execution]
points_per_chunk = 9
points_per_task = 9
"""

#: Linear two-phase strokes with a duty-cycle window: a reduction with a subset dimension
#: (kept: ratio x period x window) and a polished one over the (ratio, period) plane.
WINDOW = """
[scene]
name = "tiny_window"
title = "report test: duty-cycle windows"
figure = "EtaVsMint0 (test)"
family = "powerlaw"

[axes]
anisotropy_ratio = { values = [0.125, 8.0] }
scaled_period = { values = [1.0, 2.0] }
duty_cycle = { range = [0.3, 0.7], step = 0.2 }
A0 = { range = [0.6, 1.2], num = 2 }
A1_ratio = { range = [0.4, 0.8], num = 2 }

[fixed]
closing_shape = "linear"
opening_shape = "linear"

[solver]
rtol = 1e-3

[outputs]
quantities = ["relative_efficiency", "scaled_efficiency"]

[[reductions]]
name = "windowed"
quantity = "relative_efficiency"
statistic = "absmax"
over = ["A0", "A1_ratio", "duty_cycle"]
[reductions.window]
axis = "duty_cycle"
center = 0.5
halfwidths = [0.0, 0.2]

[[reductions]]
name = "best_efficiency"
quantity = "scaled_efficiency"
statistic = "absmax"
over = ["A0", "A1_ratio", "duty_cycle"]
polish = true
polish_max_evaluations = 8

[execution]
points_per_chunk = 12
points_per_task = 12
"""

#: Optimal Fourier motions (scene kind "optima"): 2 ratios x Kmax {1, 2} x 2 starts.
OPTIMA = """
[scene]
kind = "optima"
name = "tiny_optima"
title = "report test: optimal Fourier motions"
figure = "OptMotionsLowMun (test)"

[axes]
anisotropy_ratio = { values = [0.0625, 16.0] }
max_wavenumber = [1, 2]

[starts]
num = 2
seed = 5

[optimizer]
max_iterations = 40

[keep]
best = 3
n_tau = 32

[execution]
starts_per_task = 2
"""

SCENES = {"tiny_plane": PLANE, "tiny_facets": FACETS, "tiny_window": WINDOW, "tiny_optima": OPTIMA}
#: Scenes whose sections draw the motion of an optimum with its animation (the grid kind).
ANIMATED = ("tiny_plane", "tiny_facets", "tiny_window")


def is_optima_scene(scene_file: Path) -> bool:
    import tomllib

    return tomllib.loads(Path(scene_file).read_text()).get("scene", {}).get("kind") == "optima"


def build_store(tmp: Path, name: str) -> Path:
    """Run scene ``name`` of :data:`SCENES` with the pipeline (synchronously) into ``tmp/<name>.zarr``."""
    import pipeline

    path = tmp / f"{name}.toml"
    path.write_text(SCENES[name])
    scene = pipeline.load_scene(path)
    store = tmp / f"{name}.zarr"
    pipeline.run_scene(scene, store, scheduler="synchronous", progress=False)
    return store


def synthetic_store(store: Path, scene_file: Path, *, quick: bool = False) -> Path:
    """A complete store of a shipped scene at its full resolution (``quick``: its ``paper
    --quick`` variant), filled with smooth synthetic values instead of solver output (seconds
    instead of hours): the pipeline's own skeleton and reductions, so the report sees exactly
    the real layout and sizes (the default storage chunks, not the tests' chunk per block)."""
    import os

    saved = os.environ.pop("TWOLINK_PIPELINE_CHUNK_BYTES", None)
    try:
        return _synthetic_store(store, scene_file, quick=quick)
    finally:
        if saved is not None:
            os.environ["TWOLINK_PIPELINE_CHUNK_BYTES"] = saved


def _synthetic_store(store: Path, scene_file: Path, *, quick: bool = False) -> Path:
    import warnings

    import numpy as np
    import zarr

    import pipeline
    from pipeline import _reduce, _store
    from pipeline._grid import scene_chunks

    if quick:
        from pipeline.__main__ import quick_variant

        scene = quick_variant(scene_file)
    else:
        scene = pipeline.load_scene(scene_file)
    if is_optima_scene(scene_file):
        return synthetic_optima_store(store, scene)
    if getattr(scene, "kind", "grid") != "grid":
        return synthetic_study_store(store, scene)
    _store.create_skeleton(store, scene, scene_chunks(scene))
    mesh = np.meshgrid(*[np.linspace(0.0, 1.0, a.size) for a in scene.axes], indexing="ij", sparse=True)
    base = sum(np.sin(2.0 + 1.3 * k * m) for k, m in enumerate(mesh, start=1))
    data = {}
    for i, q in enumerate(scene.outputs):
        dtype, _ = _store.output_dtype(q)
        v = (base * (1 + 0.1 * i)) if dtype.kind == "f" else np.full(scene.shape, 3)
        if q == "error_estimate":
            v = 1e-6 * (1.5 + np.sin(base))
        data[q] = np.broadcast_to(v, scene.shape).astype(dtype)
    status = np.zeros(scene.shape, dtype=np.int8)
    status.flat[:: 997] = 6  # a few failures, NaN like the solver's
    for q in scene.quantities:
        data[q] = np.where(status == 0, data[q], np.nan)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        g = zarr.open_group(str(store), mode="r+", zarr_format=3)
        for q, v in data.items():
            g[q][...] = v
        g["status"][...] = status
        for r in scene.reductions:
            arrays, _ = _reduce.grid_reduction(scene, r, data)
            for name, v in arrays.items():
                g[name][...] = v
                if r.polish:
                    g[name.replace(r.name, r.name + "_polished", 1)][...] = v
            if r.polish:
                g[f"{r.name}_polished_status"][...] = 0
                g[f"{r.name}_polished_evaluations"][...] = 7
                if f"{r.name}_polished_uncertainty" in g:  # the polish record (issue 44)
                    g[f"{r.name}_polished_uncertainty"][...] = 1e-5
                    g[f"{r.name}_polished_{r.over[-1]}_edge"][...] = 1
        if scene.series is not None:
            tau = np.arange(scene.series.n_tau) / scene.series.n_tau
            g["series_u"][...] = np.sin(2 * np.pi * tau)[None, :] * np.ones((len(scene.series.points), 1))
            g["series_status"][...] = 0
    _store.set_state(store, chunks_complete=True, reductions_complete=True, series_complete=True)
    return store


def synthetic_study_store(store: Path, scene) -> Path:
    """A complete study store (accuracy, stiffness) of ``scene`` with synthetic values: the
    pipeline's own skeleton, errors decreasing with rtol and grid size, a few failures."""
    import warnings

    import numpy as np
    import zarr

    from pipeline import _store, _study

    _study.create_study_skeleton(store, scene, 64)
    rng = np.random.default_rng(0)
    spec = _study.study_arrays(scene)
    dims = _study.result_dims(scene)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        g = zarr.open_group(str(store), mode="r+", zarr_format=3)
        for name, (adims, dtype, _, _) in spec.items():
            shape = tuple(dims[d] for d in adims)
            if name.endswith("status"):
                v = np.zeros(shape)
                if name == "status":
                    v.flat[::7] = 6
            elif name in ("check_method", "used_method"):
                v = np.zeros(shape)
            elif dtype.kind == "i":
                v = np.full(shape, 3)
            else:
                level = np.arange(shape[-1])[(None,) * (len(shape) - 1)] if len(shape) > 1 else 0
                v = 10.0 ** (-2.0 - level - rng.random(shape))
            g[name][...] = v.astype(dtype)
    mark = zarr.open_array(store=str(store), path="pipeline_state/chunk_done", mode="r+")
    mark[...] = 1
    _store.set_state(store, chunks_complete=True)


def synthetic_optima_store(store: Path, scene) -> Path:
    """An optima store at the scene's full size with synthetic optima: the pipeline's skeleton
    and its own distinct-optima reduction over smooth random series."""
    import warnings

    import numpy as np
    import zarr

    from pipeline import _optima, _store

    _optima.create_optima_skeleton(store, scene)
    rng = np.random.default_rng(0)
    shape = scene.shape
    kmax = np.asarray(scene.max_wavenumbers)[None, :, None, None]
    n_c = scene.n_coefficients
    k_largest = max(scene.max_wavenumbers)
    coefficients = np.zeros(shape + (n_c,))
    coefficients[..., 0] = rng.uniform(0.3, 1.2, shape)
    for k in range(1, k_largest + 1):
        on = k <= kmax
        coefficients[..., k] = np.where(on, rng.normal(0, 0.5 / k, shape), 0.0)
        coefficients[..., k_largest + k] = np.where(on & (k > 1), rng.normal(0, 0.5 / k, shape), 0.0)
    ratio = np.log2(np.asarray(scene.anisotropy_ratios))[:, None, None, None]
    rel = -(0.1 + 0.02 * np.abs(ratio) + 0.01 * kmax) * rng.uniform(0.7, 1.0, shape)
    status = np.zeros(shape, dtype=np.int8)
    status.flat[::7] = _optima.STOP_CODES["max_iterations"]
    data = {"status": status, "U": np.sign(rel), "efficiency": 4 * rel, "relative_efficiency": rel,
            "scaled_period": 2.0 + np.abs(ratio) * rng.uniform(0.9, 1.1, shape),
            "gradient_norm": np.full(shape, 1e-8), "period_at_bound": np.zeros(shape, np.int8),
            "coefficients": coefficients}
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        g = zarr.open_group(str(store), mode="r+", zarr_format=3)
        for name, v in data.items():
            g[name][...] = v
        g["ill_conditioned"][...] = (status != 0).astype(np.int8)
        g["seconds"][...] = rng.uniform(0.1, 5.0, shape)
        for name, v in _optima.reduce_optima(scene, data).items():
            g[name][...] = v
    _store.set_state(store, chunks_complete=True, reductions_complete=True)
    return store


# ---------------------------------------------------------------------------
# Headless browser, driven over the DevTools protocol on a pipe (no extra packages)
# ---------------------------------------------------------------------------


def chromium() -> str | None:
    for name in ("chromium", "chromium-browser"):
        path = shutil.which(name)
        if path:
            return path
    return None


class Browser:
    """One headless chromium at a given window size, driven through ``--remote-debugging-pipe``
    (the DevTools protocol as NUL-terminated JSON on file descriptors 3 and 4).

    ``open(url)`` navigates and returns the wall seconds until the page marks itself ready
    (``<html data-ready>``) together with the page's own figure (ms since navigation start);
    ``evaluate(js)`` returns a JSON value (promises awaited)."""

    def __init__(self, width: int = 1280, height: int = 800, timeout: float = 180.0):
        self.timeout = timeout
        self._tmp = tempfile.TemporaryDirectory()
        cmd_r, self._cmd_w = os.pipe()
        self._out_r, out_w = os.pipe()

        def child():
            a, b = os.dup(cmd_r), os.dup(out_w)
            os.dup2(a, 3)
            os.dup2(b, 4)
            os.set_inheritable(3, True)
            os.set_inheritable(4, True)

        profile = Path(self._tmp.name) / "profile"
        self.proc = subprocess.Popen(
            [chromium(), "--headless", "--no-sandbox", "--disable-gpu", "--no-first-run", "--disable-quic",
             "--disable-background-networking", "--disable-component-update", "--disable-sync",
             "--disable-dev-shm-usage", "--remote-debugging-pipe", f"--user-data-dir={profile}",
             f"--window-size={width},{height}", "about:blank"],
            preexec_fn=child, close_fds=False, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
            env=dict(os.environ, HOME=str(profile)))
        os.close(cmd_r)
        os.close(out_w)
        self._buf, self._id = b"", 0
        targets = self.call("Target.getTargets")["targetInfos"]
        page = next(t for t in targets if t["type"] == "page")
        self.session = self.call("Target.attachToTarget", {"targetId": page["targetId"], "flatten": True})["sessionId"]
        self.call("Page.enable", session=True)
        self.call("Emulation.setDeviceMetricsOverride",
                  {"width": width, "height": height, "deviceScaleFactor": 1, "mobile": False}, session=True)

    def call(self, method: str, params: dict | None = None, session: bool = False) -> dict:
        import select
        import time

        self._id += 1
        msg = {"id": self._id, "method": method, "params": params or {}}
        if session:
            msg["sessionId"] = self.session
        os.write(self._cmd_w, json.dumps(msg).encode() + b"\0")
        deadline = time.monotonic() + self.timeout
        while True:
            while b"\0" in self._buf:
                raw, self._buf = self._buf.split(b"\0", 1)
                reply = json.loads(raw)
                if reply.get("id") == self._id:
                    if "error" in reply:
                        raise RuntimeError(f"{method}: {reply['error']}")
                    return reply.get("result", {})
            left = deadline - time.monotonic()
            if left <= 0 or not select.select([self._out_r], [], [], left)[0]:
                raise TimeoutError(f"chromium did not answer {method} within {self.timeout} s")
            chunk = os.read(self._out_r, 1 << 20)
            if not chunk:
                raise RuntimeError("chromium closed the pipe")
            self._buf += chunk

    def evaluate(self, expression: str):
        r = self.call("Runtime.evaluate", {"expression": expression, "returnByValue": True, "awaitPromise": True},
                      session=True)
        if "exceptionDetails" in r:
            raise RuntimeError(f"page error: {r['exceptionDetails']}")
        return r["result"].get("value")

    def open(self, path: Path) -> tuple[float, float]:
        """Navigate to ``path``; (wall seconds until data-ready, the page's own ms figure)."""
        import time

        t0 = time.perf_counter()
        self.call("Page.navigate", {"url": Path(path).resolve().as_uri()}, session=True)
        while True:
            ready = self.evaluate("document.documentElement && document.documentElement.getAttribute('data-ready')")
            if ready:
                return time.perf_counter() - t0, float(ready)
            if time.perf_counter() - t0 > self.timeout:
                raise TimeoutError(f"{path} never marked itself ready")
            time.sleep(0.02)

    def close(self):
        try:
            self.call("Browser.close")
            self.proc.wait(10)
        except Exception:
            self.proc.kill()
        finally:
            for fd in (self._cmd_w, self._out_r):
                try:
                    os.close(fd)
                except OSError:
                    pass
            self._tmp.cleanup()

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()


#: Runs before anything else in the page: records uncaught errors, rejected promises and console.error.
_HOOK = """<script>
window.__errors = [];
window.addEventListener('error', function (e) {
  window.__errors.push('error: ' + (e.message || (e.target && (e.target.src || e.target.href)) || e.type));
}, true);
window.addEventListener('unhandledrejection', function (e) { window.__errors.push('rejection: ' + e.reason); });
(function () { var ce = console.error; console.error = function () {
  window.__errors.push('console.error: ' + Array.prototype.join.call(arguments, ' ')); ce.apply(console, arguments); }; })();
</script>"""

#: After every figure is drawn: per plot div its traces, data points and animation frames.
_PLOTS = """(function () {
  var finite = function (a) {
    if (!a || a.length === undefined) return 0;
    var n = 0;
    for (var i = 0; i < a.length; i++) {
      var v = a[i];
      if (v !== null && typeof v === 'object' && v.length !== undefined) n += finite(v);
      else if (typeof v === 'number' && isFinite(v)) n += 1;
    }
    return n;
  };
  var plots = [];
  document.querySelectorAll('.plotly-graph-div').forEach(function (gd) {
    var n = 0, traces = (gd._fullData || []);
    traces.forEach(function (t) { n += finite(t.z || t.y || []); });
    plots.push({id: gd.id, traces: traces.length, points: n,
                rendered: !!gd._fullLayout && !!gd.querySelector('.main-svg'),
                frames: (gd._transitionData && gd._transitionData._frames) ? gd._transitionData._frames.length : 0,
                sliders: (gd.layout && gd.layout.sliders) ? gd.layout.sliders.length : 0,
                buttons: (gd.layout && gd.layout.updatemenus) ? gd.layout.updatemenus.length : 0});
  });
  return plots;
})()"""

#: Tables wider than their section: every <details> opened first; a table passes when it fits
#: its container or sits in a box that scrolls horizontally and is no wider than its section.
TABLE_WIDTHS = """(function () {
  document.querySelectorAll('details').forEach(function (d) { d.open = true; });
  var bad = [], n = 0;
  document.querySelectorAll('table').forEach(function (t) {
    n += 1;
    var box = t.parentElement, scrolls = false;
    for (var e = t.parentElement; e && e.tagName !== 'SECTION'; e = e.parentElement) {
      var ox = getComputedStyle(e).overflowX;
      if (ox === 'auto' || ox === 'scroll') { scrolls = true; box = e; break; }
    }
    var section = t.closest('section') || document.body;
    var fits = t.scrollWidth <= t.parentElement.clientWidth + 1;
    var boxed = scrolls && box.getBoundingClientRect().width <= section.clientWidth + 1;
    if (!(fits || boxed)) bad.push({section: section.id, width: t.scrollWidth, container: t.parentElement.clientWidth,
                                    head: (t.rows[0] ? t.rows[0].textContent : '').slice(0, 80)});
  });
  var wide = [];
  document.querySelectorAll('section').forEach(function (s) {
    if (s.scrollWidth > s.clientWidth + 1) wide.push({section: s.id, width: s.scrollWidth, client: s.clientWidth});
  });
  return {tables: n, bad: bad, wide_sections: wide, page: document.documentElement.scrollWidth,
          viewport: window.innerWidth};
})()"""


def _split_pages(text: str, parts: int) -> list[str]:
    """``parts`` copies of the page, sections dealt round-robin between them (every section in
    exactly one copy), so several browsers can draw a large report in parallel."""
    pieces = re.split(r"(<section class='(?:scene|figure)' id='[^']*'>.*?</section>)", text, flags=re.S)
    pages = []
    for k in range(parts):
        count, keep = 0, []
        for piece in pieces:
            if re.match(r"<section class='(?:scene|figure)'", piece):
                if count % parts == k:
                    keep.append(piece)
                count += 1
            else:
                keep.append(piece)
        pages.append("".join(keep))
    return pages


def with_hook(index: Path) -> str:
    text = index.read_text(encoding="utf-8")
    head = text.index("<head>") + len("<head>")
    return text[:head] + _HOOK + text[head:]


def probe(index: Path, timeout: float = 240.0, parts: int | None = None) -> dict:
    """Open ``index`` (copies with the error hook injected, beside it) in headless chromium, draw
    every figure (``window.twolinkDrawAll()``) and return ``{"plotly": version, "errors": [...],
    "plots": [{id, traces, points, rendered, frames, ...}]}``.

    The page is split by section into ``parts`` pages drawn concurrently (default: one per CPU,
    at most 4); the results are merged."""
    from concurrent.futures import ThreadPoolExecutor

    parts = parts or max(1, min(4, os.cpu_count() or 1))
    pages = []
    for k, body in enumerate(_split_pages(with_hook(index), parts)):
        page = index.with_name(f"_probe{k}.html")
        page.write_text(body, encoding="utf-8")
        pages.append(page)

    def one(page):
        with Browser(timeout=timeout) as b:
            b.open(page)
            b.evaluate("window.twolinkDrawAll()")
            return {"plotly": b.evaluate("typeof Plotly === 'undefined' ? null : Plotly.version"),
                    "errors": b.evaluate("window.__errors"), "plots": b.evaluate(_PLOTS)}

    try:
        with ThreadPoolExecutor(len(pages)) as pool:
            results = list(pool.map(one, pages))
    finally:
        for page in pages:
            page.unlink(missing_ok=True)
    merged = {"plotly": None, "errors": [], "plots": []}
    for r in results:
        merged["plotly"] = merged["plotly"] or r["plotly"]
        merged["errors"] += r["errors"]
        merged["plots"] += r["plots"]
    return merged


def page_ready(index: Path, width: int = 1280, repeats: int = 1) -> dict:
    """Open ``index`` as a reader would (1280 px wide) and measure: wall seconds until the page
    marks itself ready, the page's own figure, how many figures are drawn then, and the table
    layout (:data:`TABLE_WIDTHS`). The fastest of ``repeats`` openings (a fresh browser each)."""
    best = None
    for _ in range(repeats):
        with Browser(width=width) as b:
            wall, page_ms = b.open(index)
            drawn = b.evaluate("document.querySelectorAll('[data-drawn]').length")
            total = b.evaluate("document.querySelectorAll('div.lazy-plot').length")
            layout = b.evaluate(TABLE_WIDTHS)
        r = {"wall_seconds": wall, "page_ms": page_ms, "drawn": drawn, "figures": total, "layout": layout}
        if best is None or r["wall_seconds"] < best["wall_seconds"]:
            best = r
    return best
