"""The reports package's shape: no import cycles among its modules, no private (underscore)
name imported across modules, and one registry choosing the section renderer by scene kind."""

from __future__ import annotations

import ast
import tomllib
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parent.parent
PACKAGE = REPO / "reports"


def _imports() -> dict[str, list[tuple[str, list[str]]]]:
    """{module: [(imported module, names)]} for every relative import, at any depth."""
    out = {}
    for f in sorted(PACKAGE.glob("*.py")):
        mod = f.stem
        found = []
        for node in ast.walk(ast.parse(f.read_text(encoding="utf-8"))):
            if isinstance(node, ast.ImportFrom) and node.level == 1:
                if node.module:
                    found.append((node.module, [a.name for a in node.names]))
                else:  # from . import x
                    found += [(a.name, []) for a in node.names]
        out[mod] = found
    return out


def test_no_private_name_is_imported_across_modules():
    bad = [(mod, target, name) for mod, found in _imports().items() for target, names in found
           for name in names if name.startswith("_")]
    assert not bad, bad


def _cycles(graph: dict[str, set[str]]) -> list[list[str]]:
    cycles, state, stack = [], {}, []

    def visit(n):
        state[n] = "open"
        stack.append(n)
        for m in sorted(graph.get(n, ())):
            if state.get(m) == "open":
                cycles.append(stack[stack.index(m):] + [m])
            elif m not in state:
                visit(m)
        stack.pop()
        state[n] = "done"

    for n in sorted(graph):
        if n not in state:
            visit(n)
    return cycles


def test_no_import_cycles_among_the_modules():
    graph = {mod: {t for t, _ in found} for mod, found in _imports().items()}
    assert _cycles(graph) == []
    # the check itself finds a cycle
    assert _cycles({"a": {"b"}, "b": {"c"}, "c": {"a"}}) == [["a", "b", "c", "a"]]


def test_every_scene_kind_has_a_renderer_in_the_one_registry():
    from reports._kinds import SECTION_RENDERERS

    kinds = {"grid"} | {tomllib.loads(f.read_text()).get("scene", {}).get("kind", "grid")
                        for f in (REPO / "workflows").glob("*.toml")}
    assert kinds <= set(SECTION_RENDERERS)
    # the renderers are chosen only there: no other module dispatches on the kind
    for f in PACKAGE.glob("*.py"):
        if f.stem in ("_kinds", "_paper", "_claim_values"):
            continue
        text = f.read_text(encoding="utf-8")
        assert 'in ("accuracy", "stiffness")' not in text and '== "optima"' not in text, f.name


def test_an_unknown_kind_gets_an_error_box_not_a_crash(tmp_path):
    from reports._kinds import render_view
    from reports._read import SceneStore
    from reports._site import SiteBuilder

    site = SiteBuilder(tmp_path)
    sd = SceneStore(path=tmp_path / "x.zarr", meta={"kind": "mystery", "provenance": {"scene_name": "x"}},
                    ds=None, science={})
    html = render_view(site, sd, "scene-x")
    assert "no report section for scene kind &#x27;mystery&#x27;" in html and site.errors


@pytest.mark.parametrize("module", sorted(p.stem for p in PACKAGE.glob("_*.py") if p.stem != "__init__"))
def test_each_module_imports_on_its_own(module):
    import importlib

    importlib.import_module(f"reports.{module}")


@pytest.mark.parametrize("n, kinds", [(16, ["heatmap", "contour"]), (64, ["contour"]), (3, ["heatmap"])])
def test_coarse_maps_are_heatmaps_with_contour_lines(n, kinds):
    """16 x 16 (harmonic_optimum): the cells as a heatmap with contour lines over them (no
    legend entry); 64 x 64: one contour map coloured as a heatmap; 3 x 3: the cells alone."""
    import numpy as np
    import xarray as xr

    from reports._panels import quantity_maps
    from reports._read import SceneStore

    a0, r = np.linspace(0.1, 1.5, n), np.linspace(0.05, 0.95, n)
    z = np.sin(3 * a0)[:, None] * np.cos(2 * r)[None, :]
    ds = xr.Dataset({"scaled_efficiency": (("A0", "A1_ratio"), z)}, coords={"A0": a0, "A1_ratio": r})
    sd = SceneStore(path=Path("x.zarr"), meta={"layout": {"dims": ["A0", "A1_ratio"]}}, ds=ds,
                    science={"outputs": {"quantities": ["scaled_efficiency"]}})
    import plotly.graph_objects as go

    fig = go.Figure(quantity_maps(sd, "scaled_efficiency"))  # the panels return figure specs (dicts)
    assert [t.type for t in fig.data] == kinds
    for t in fig.data:
        if t.type == "contour" and len(kinds) == 2:
            assert t.contours.coloring == "none" and t.showlegend is False and t.hoverinfo == "skip"
        elif t.type == "contour":
            assert t.contours.coloring == "heatmap"
