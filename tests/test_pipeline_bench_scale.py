"""``python -m pipeline.bench_scale``: one run, the pipeline beside the engine alone, one JSON line;
bad arguments refused by name (exit 2)."""

import json
from pathlib import Path

import pytest

from pipeline import bench_scale

SMOKE = str(Path(__file__).resolve().parent.parent / ".ci" / "smoke.toml")


def test_bench_scale_times_the_pipeline_beside_the_engine_and_ends_with_json(capsys):
    assert bench_scale.main([SMOKE, "--workers", "1", "--engine", "cold"]) == 0
    lines = capsys.readouterr().out.strip().splitlines()
    out = json.loads(lines[-1])
    assert out["points"] == 64 and [r["workers"] for r in out["rows"]] == [1]
    row = out["rows"][0]
    assert row["solves_per_s"] == pytest.approx(64 / row["wall_seconds"], rel=1e-2)
    assert row["ratio_to_engine_cold"] == pytest.approx(row["solves_per_s"] / row["engine_cold_solves_per_s"], abs=6e-4)  # rounded to 3 digits
    assert row["speedup"] == 1.0 and 0.0 < row["parallel_efficiency"] <= 1.0
    assert out["projection"]["workers"] == 16


@pytest.mark.parametrize("argv, named", [
    (["--workers", "0"], "--workers"),
    (["--workers", "one"], "--workers"),
    (["--engine", "warm"], "--engine"),
    (["no/such/scene.toml"], "no/such/scene.toml"),
])
def test_bench_scale_refuses_bad_arguments_by_name(capsys, argv, named):
    args = argv if argv[0].endswith(".toml") else [SMOKE, *argv]
    assert bench_scale.main(args) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and named in err[0]
