"""``python -m pipeline.projection``: a finished run's stores projected to more workers.

LPT's makespan against brute force (Graham's 4/3 bound, and never below the optimum), the
projection of real stores (a grid and an optima store: projected to the workers they ran on,
within the run's own measured wall; more workers never slower), and bad arguments by name."""

import itertools
import json

import numpy as np
import pytest

import report_helpers as rh
from pipeline import projection


def _optimal_makespan(tasks, workers):
    best = float("inf")
    for assign in itertools.product(range(workers), repeat=len(tasks)):
        loads = np.zeros(workers)
        np.add.at(loads, list(assign), tasks)
        best = min(best, loads.max())
    return best


def test_lpt_is_within_graham_bound_of_the_optimum():
    assert projection.lpt_makespan([5, 4, 3, 3, 3], 2) == 10  # LPT's textbook miss (optimum 9)
    rng = np.random.default_rng(0)
    for _ in range(40):
        tasks = list(rng.pareto(1.5, rng.integers(1, 7)) + 0.1)
        w = int(rng.integers(1, 4))
        lpt, opt = projection.lpt_makespan(tasks, w), _optimal_makespan(tasks, w)
        assert opt - 1e-12 <= lpt <= (4 / 3 - 1 / (3 * w)) * opt + 1e-12, (tasks, w, lpt, opt)


@pytest.mark.parametrize("scene", ["tiny_plane", "tiny_optima"])
def test_a_store_projects_to_its_own_run_and_more_workers_are_not_slower(tmp_path, scene):
    store = rh.build_store(tmp_path, scene)
    own = projection.project_store(store, 1)
    measured = own["measured_seconds"]
    assert own["measured_workers"] >= 1
    # on the workers it ran on, the model (serial + task work) is at most the wall measured
    same = projection.project_store(store, own["measured_workers"])
    assert 0 < same["tn_seconds"] <= measured * 1.05 + 0.05, (same, measured)
    more = projection.project_store(store, 64)
    assert more["tn_seconds"] <= same["tn_seconds"] <= own["t1_seconds"]
    assert (more["tasks"] is None) == (scene == "tiny_plane")
    if more["tasks"] is not None:  # tasks' makespan: never below the longest task
        assert more["tn_seconds"] >= more["serial_seconds"] + more["longest_task_seconds"] - 1e-3


def test_the_command_ends_with_json_and_refuses_bad_arguments(tmp_path, capsys):
    store = rh.build_store(tmp_path, "tiny_plane")
    assert projection.main([str(tmp_path), "--workers", "16"]) == 0
    out = json.loads(capsys.readouterr().out.strip().splitlines()[-1])
    assert out["workers"] == 16 and [s["store"] for s in out["scenes"]] == [store.name]
    for argv, named in ((["--workers", "0"], "--workers"), ([], "out")):
        args = [str(tmp_path), *argv] if argv else [str(tmp_path / "nothing_here")]
        assert projection.main(args) == 2
        err = capsys.readouterr().err.strip().splitlines()
        assert len(err) == 1 and named in err[0]
