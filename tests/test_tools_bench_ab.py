"""``python -m solver.tools.bench_ab``: the paired A/B of the engine call between two checkouts
(here an A/A against this checkout), its summary arithmetic, and bad arguments refused by name."""

import json
from pathlib import Path

import numpy as np
import pytest

from solver.tools import bench_ab

ROOT = str(Path(__file__).resolve().parent.parent)


def test_paired_summary_reads_a_side_twice_as_slow_as_ratio_two():
    wall_b = np.array([0.5, 0.7, 0.6, 0.9])
    s = bench_ab.paired_summary(2.0 * wall_b, wall_b, 2.0 * wall_b, wall_b)
    assert s["speed_ratio"] == pytest.approx(2.0) and s["paired_speed_ratio"] == pytest.approx(2.0)
    assert s["paired_ci95"] == pytest.approx([2.0, 2.0]) and s["cpu_ratio"] == pytest.approx(2.0)
    # negative control: b slower reads below 1, and the interval holds the paired median
    s = bench_ab.paired_summary(wall_b, 1.25 * wall_b, wall_b, 1.25 * wall_b)
    assert s["paired_speed_ratio"] == pytest.approx(0.8)
    assert s["paired_ci95"][0] <= s["paired_speed_ratio"] <= s["paired_ci95"][1]


def test_an_a_a_run_alternates_the_two_sides_and_ends_with_json(capsys):
    assert bench_ab.main([ROOT, "--points", "6", "--rounds", "2", "--threads", "1"]) == 0
    lines = capsys.readouterr().out.strip().splitlines()
    out = json.loads(lines[-1])
    assert out["points"] == 6 and out["rounds"] == 2
    for rtol in ("0.0001", "1e-07"):
        row = out[f"rtol_{rtol}"]
        assert row["calls"] == 4  # 2 rounds of a b b a / b a a b: 4 calls a side
        assert row["failures_a"] == row["failures_b"]
        assert row["speed_ratio"] > 0 and row["paired_ci95"][0] <= row["paired_ci95"][1]
    assert sum(line.startswith("rtol ") for line in lines) == 2


@pytest.mark.parametrize("argv, named", [
    (["/no/such/checkout"], "other"),
    ([ROOT, "--rounds", "0"], "--rounds"),
    ([ROOT, "--points", "0"], "--points"),
    ([ROOT, "--threads", "0"], "--threads"),
])
def test_bench_ab_refuses_bad_arguments_by_name(capsys, argv, named):
    assert bench_ab.main(argv) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and named in err[0]
