"""Convergence shown, not assumed (issue 44, item 2): on >= 20 cells of the shipped scenes a
second method (``pipeline.compare_polish``: a dense local grid around the polished arg-max and
Nelder-Mead from another start, sharing no optimiser run with the polish) finds nothing better
than the polished maximum by more than the scene's ``polish_tolerance`` (relative); a polish
truncated to 4 solves per start fails the same check.

The cells are whole cells of the shipped scenes (every subset of the reduction, the scene's
polish settings), small ones: power_law's shapes are held to two laws each so that a cell's
grid is 700 points, not 4,375.  Measured values: docs/validation.md, "Polish agreement".
"""

from __future__ import annotations

import numpy as np
import pytest

from pipeline.__main__ import WORKFLOWS
from pipeline._registry import load_scene
from pipeline.compare_polish import agreement, cell_scene, polish_cell, solve_grid

#: (scene, reduction, {kept axis: value}); with the subsets of each reduction, 30 cells
CELLS = [
    ("linear_two_phase", "best_efficiency", {"anisotropy_ratio": 2.0 ** -8, "scaled_period": 2.0 ** 3}),
    ("linear_two_phase", "best_efficiency", {"anisotropy_ratio": 2.0 ** -4, "scaled_period": 1.0}),
    ("linear_two_phase", "best_efficiency", {"anisotropy_ratio": 2.0 ** 2, "scaled_period": 2.0 ** 2}),
    ("linear_two_phase", "best_efficiency", {"anisotropy_ratio": 2.0 ** 8, "scaled_period": 2.0 ** -3}),
    ("linear_two_phase", "fastest", {"anisotropy_ratio": 2.0 ** -6, "scaled_period": 2.0 ** -1}),
    ("linear_two_phase", "fastest", {"anisotropy_ratio": 1.0, "scaled_period": 2.0 ** 2}),
    ("linear_two_phase", "fastest", {"anisotropy_ratio": 2.0 ** 6, "scaled_period": 2.0 ** 1}),
    ("power_law", "best_efficiency", {"anisotropy_ratio": 2.0 ** -4, "scaled_period": 2.0 ** 1,
                                      "closing_shape": ("linear", "up:3"), "opening_shape": ("down:3", "linear")}),
    ("power_law", "best_efficiency", {"anisotropy_ratio": 2.0 ** 8, "scaled_period": 2.0 ** -1,
                                      "closing_shape": ("linear", "up:10"), "opening_shape": ("down:10", "linear")}),
    ("duty_cycle", "best_relative_efficiency", {"anisotropy_ratio": 0.125, "scaled_period": 2.0 ** -1}),
]


def _cell(scene_name, reduction, where):
    from pipeline._scene import Axis, parse_shape

    scene = load_scene(WORKFLOWS / f"{scene_name}.toml")
    r = next(x for x in scene.reductions if x.name == reduction)
    values = {k: v for k, v in where.items() if not isinstance(v, tuple)}
    scene = cell_scene(scene, **values)
    shapes = {k: v for k, v in where.items() if isinstance(v, tuple)}
    if shapes:  # hold the shape axes to a few laws (a smaller grid; the polish is per shape pair)
        from dataclasses import replace

        axes = tuple(Axis(a.name, tuple(sorted(parse_shape(None, s, a.name) for s in shapes[a.name])), a.spacing)
                     if a.name in shapes else a for a in scene.axes)
        scene = replace(scene, axes=axes)
    return scene, r, solve_grid(scene, [r.quantity, *r.report])


@pytest.fixture(scope="module")
def cells():
    return [_cell(*c) for c in CELLS]


@pytest.fixture(scope="module")
def polished(cells):
    return [(scene, r, polish_cell(scene, r, data)) for scene, r, data in cells]


def test_polish_agrees_with_a_second_method_on_twenty_cells(polished):
    rows = [agreement(scene, r, cell, rec) for scene, r, out in polished for cell, rec in out]
    assert len(rows) >= 20
    bad = [(a.cell, a.polished, a.second, a.relative, a.status) for a in rows if not a.agrees]
    worst = max(a.relative for a in rows)
    print(f"{len(rows)} cells; worst relative excess of the second method {worst:.2g}; "
          f"status counts {np.bincount([a.status for a in rows]).tolist()}")
    assert not bad, bad


def test_a_truncated_polish_fails_the_same_check(cells):
    """Negative control: every start capped at 4 solves (status 1 wherever a start was cut short)."""
    rows = []
    for scene, r, data in cells[:4]:
        for cell, rec in polish_cell(scene, r, data, max_evaluations=4):
            rows.append(agreement(scene, r, cell, rec))
    failed = sum(not a.agrees for a in rows)
    print(f"truncated polish: {failed} of {len(rows)} cells fail the agreement check")
    assert failed > 0


def test_compare_polish_cli_passes_a_polish_and_fails_a_truncated_one(tmp_path, capsys):
    """``python -m pipeline.compare_polish`` on the small harmonic scene: every cell agrees; with
    ``--truncate 1`` (the grid point itself) it says fail; a bad argument is one line, exit 2."""
    import json

    from pipeline.compare_polish import main
    from pipeline_cases import small_scene_text, write_scene

    scene = write_scene(tmp_path, small_scene_text(polish=True))
    assert main([str(scene), "--cells", "4"]) == 0
    ok = json.loads(capsys.readouterr().out.strip().splitlines()[-1])
    assert (ok["cells"], ok["verdict"]) == (4, "pass")
    assert main([str(scene), "--cells", "4", "--truncate", "1"]) == 0
    bad = json.loads(capsys.readouterr().out.strip().splitlines()[-1])
    assert bad["verdict"] == "fail" and bad["differ"] >= 1
    with pytest.raises(SystemExit) as exc:
        main([str(scene), "--cells", "x"])
    assert exc.value.code == 2 and len(capsys.readouterr().err.strip().splitlines()) == 1
