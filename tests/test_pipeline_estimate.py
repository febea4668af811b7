"""``python -m pipeline estimate`` projects every kind of scene, the polish included, from a timed
probe (issue 45 item 6: on d799bf7 it projected the grid points only: 3.1 min for a 12-16 min
paper)."""

from __future__ import annotations

import re

import pytest

from pipeline import load_scene, parse_scene
from pipeline_cases import cli, small_scene_text, write_scene

_TINY_OPTIMA = """
[scene]
kind = "optima"
name = "tiny_optima"

[axes]
anisotropy_ratio = { values = [0.0625, 16.0] }
max_wavenumber = [1, 2]
p = [0.0]

[starts]
num = 4
seed = 3

[optimizer]
max_iterations = 30

[keep]
best = 3
n_tau = 32

[execution]
starts_per_task = 2
"""


def test_estimate_projects_every_kind_and_the_polish(tmp_path):
    """Issue 45 item 6: on d799bf7 ``estimate`` projected the grid points only ("optima runs (no
    grid probe; see the scene file)", studies and polishing left out).  Now a grid scene with
    a polished reduction, an optima scene and a study each get a projection from a timed probe,
    the polish its own line."""
    from test_study import TINY as TINY_STUDY

    grid = write_scene(tmp_path, small_scene_text(polish=True))
    optima = write_scene(tmp_path, _TINY_OPTIMA, "optima.toml")
    study = write_scene(tmp_path, TINY_STUDY, "study.toml")
    proc = cli("estimate", grid, optima, study, "--workers", "2", "--probe", "2")
    assert proc.returncode == 0, proc.stderr
    out = proc.stdout
    assert "no grid probe" not in out
    for name, kind in (("small", "grid"), ("tiny_optima", "optima"), ("tiny_study", "stiffness")):
        line = next(line for line in out.splitlines() if line.startswith(name))
        assert re.search(r"~\s*\d+\.\d min on 2 workers", line) and f"({kind}: " in line, out
    assert re.search(r"\+ polish best_efficiency: \d of 4 cells timed", out), out
    assert "timed probe" in out.splitlines()[-1]


def test_estimate_counts_the_scenes_units_and_scales_the_probe(tmp_path):
    """The projection's arithmetic, with a clock that ticks 1 s per reading (so every timed
    unit "takes" 1 s): the chunks projected are the store's chunks (8), each class's mean
    times its count; the polish's cells are the cells the run polishes (2 x 2 = 4: the kept
    ratio x period), a batch's time over its cells; the optima's Kmax classes each probed
    first.  Counts, not timings."""
    from pipeline._estimate import estimate_scene

    ticks = iter(range(10_000))
    est = estimate_scene(load_scene(write_scene(tmp_path, small_scene_text(polish=True))), max_chunks=3, budget_seconds=1e9, max_cells=2,
                         clock=lambda: float(next(ticks)))
    chunks, polish = est.parts
    assert (chunks.count, chunks.probed, chunks.core_seconds) == (8, 3, 8.0)
    assert chunks.points == 64
    assert polish.name == "polish best_efficiency" and (polish.count, polish.probed) == (4, 2)
    assert polish.core_seconds == pytest.approx(4 * 1.0 / 2)
    assert est.wall_seconds(2) == pytest.approx(8.0 / 2 + max(2.0 / 2, 0.5))

    ticks = iter(range(10_000))
    optima = parse_scene(_TINY_OPTIMA, str(tmp_path / "o.toml"))
    est = estimate_scene(optima, max_chunks=1, budget_seconds=0.0, clock=lambda: float(next(ticks)))
    (part,) = est.parts
    # 2 ratios x 2 Kmax x 2 chunks of 2 starts: 8 chunks; one per Kmax class timed although
    # max_chunks is 1 and the budget 0
    assert (part.count, part.probed, part.core_seconds, part.points) == (8, 2, 8.0, 16)


def test_spread_order_visits_every_index_spread_first():
    from pipeline._estimate import spread_order

    for n in (1, 2, 3, 7, 8, 100):
        order = spread_order(n)
        assert sorted(order) == list(range(n))
    assert spread_order(8)[:3] == [4, 2, 6]
    assert spread_order(100)[0] == 50
