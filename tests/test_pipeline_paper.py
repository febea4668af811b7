"""``python -m pipeline paper``: the scene list, the first-run compile message, and a run of the
command over tiny scenes (the report included)."""

from __future__ import annotations

import pytest

import solver
from pipeline import __main__ as cli_main
from pipeline._run import warm_up_kernels
from pipeline_cases import small_scene_text


def test_quick_paper_keeps_every_figure_and_leaves_out_only_the_studies():
    scenes = {name: cli_main.load_scene(cli_main.WORKFLOWS / f"{name}.toml") for name in cli_main.PAPER_SCENES}
    left_out = set(cli_main.PAPER_SCENES) - set(cli_main.QUICK_SCENES)
    assert left_out == {name for name, s in scenes.items() if s.kind in ("accuracy", "stiffness")} != set()
    assert all(scenes[name].figure for name in cli_main.QUICK_SCENES)  # each shows a figure of the paper


def test_quick_variant_keeps_three_points_per_axis_and_four_starts(tmp_path):
    scene = cli_main.quick_variant(cli_main.WORKFLOWS / "power_law.toml")
    assert scene.axis("A0").size == scene.axis("A1_ratio").size == 3  # num = 5 -> 3, not 1
    # the polish of a quick run: loose tolerance, a quarter of the cap (issue 44), hashed apart
    full = cli_main.load_scene(cli_main.WORKFLOWS / "power_law.toml")
    (r,), (rf,) = scene.reductions, full.reductions
    assert (r.polish_tolerance, r.polish_max_evaluations) == (1e-2, rf.polish_max_evaluations // 4)
    assert scene.science["reductions"][0]["polish_tolerance"] == 1e-2
    optima = cli_main.quick_variant(cli_main.WORKFLOWS / "fourier_optima.toml")
    assert optima.n_starts == 4  # num = 12 starts -> 12 // 4 = 3 -> at least 4


class _Echo:
    def __init__(self):
        self.text = ""

    def __call__(self, *parts, end="\n", file=None, flush=False):
        self.text += " ".join(map(str, parts)) + end


@pytest.mark.parametrize("populated, compiled, expected", [
    (False, 80, "compiling the solver's kernels (first run only) ... 48 s\n"),
    (True, 0, ""),
    (True, 12, "compiled 12 solver kernels for gradient (first use) in 48 s\n"),
])
def test_warm_up_says_when_it_compiles(monkeypatch, populated, compiled, expected):
    monkeypatch.setattr(solver, "kernel_cache", lambda: solver._warmup.KernelCache("/cache", populated))
    monkeypatch.setattr(solver, "warm_up", lambda sets: solver._warmup.WarmUp(tuple(sets), 48.2, compiled))
    echo = _Echo()
    warm_up_kernels(("gradient",), echo)
    assert echo.text == expected


def test_solver_warm_up_is_idempotent_and_checks_set_names():
    with pytest.raises(ValueError, match="kernel set 'nope': must be one of periodic, march"):
        solver.warm_up(("periodic", "nope"))
    solver.warm_up(("periodic",))
    again = solver.warm_up(("periodic",))
    assert again.kernel_sets == () and again.compiled == 0
    cache = solver.kernel_cache()
    assert cache.populated and cache.directory  # the first call compiled or loaded from here


def test_paper_quick_runs_the_listed_scenes_then_builds_the_report(tmp_path, monkeypatch, capsys):
    workflows = tmp_path / "workflows"
    workflows.mkdir()
    for name in ("first", "second"):
        text = small_scene_text().replace('name = "small"', f'name = "{name}"')
        (workflows / f"{name}.toml").write_text(text)
    monkeypatch.setattr(cli_main, "WORKFLOWS", workflows)
    monkeypatch.setattr(cli_main, "QUICK_SCENES", ("first", "second"))
    out = tmp_path / "out"
    rc = cli_main.main(["paper", "--quick", "--out", str(out), "--scheduler", "synchronous", "--no-progress"])
    stdout = capsys.readouterr().out
    assert rc == 0
    assert (out / "quick" / "first.zarr").is_dir() and (out / "quick" / "second.zarr").is_dir()
    assert (out / "quick" / "report" / "index.html").is_file()
    assert "paper: 2 scenes" in stdout and "paper: report at" in stdout
    # quick variant: num = 4 per axis -> 3, step 1 -> 2 (one scaled period): 2 x 1 x 3 x 3 points
    assert "first: 18 points" in stdout


def test_paper_with_a_bad_scene_runs_nothing(tmp_path, monkeypatch, capsys):
    workflows = tmp_path / "workflows"
    workflows.mkdir()
    (workflows / "good.toml").write_text(small_scene_text().replace('name = "small"', 'name = "good"'))
    (workflows / "bad.toml").write_text(small_scene_text().replace("rtol = 0.001", "rtol = 2.0"))
    monkeypatch.setattr(cli_main, "WORKFLOWS", workflows)
    monkeypatch.setattr(cli_main, "PAPER_SCENES", ("good", "bad"))
    rc = cli_main.main(["paper", "--out", str(tmp_path / "out"), "--scheduler", "synchronous"])
    assert rc == cli_main.EXIT_BAD_SCENE
    err = capsys.readouterr().err
    assert err.startswith("error: ") and "solver.rtol: must be in (0, 0.1], got 2" in err and err.count("\n") == 1
    assert not (tmp_path / "out").exists()


@pytest.mark.parametrize("populated", [False, True])
def test_a_pool_worker_starts_on_an_empty_and_on_a_populated_kernel_cache(tmp_path, monkeypatch, populated):
    """Regression (3a636d2): with numba's cache empty (a fresh checkout) every worker of the
    processes pool read a field KernelCache does not have, and the run died with
    BrokenProcessPool.  The empty cache must take the compile lock beside the cache directory
    and warm up; a populated one warms up without it."""
    import numba

    from pipeline import _schedule

    cache_dir = tmp_path / "cache"
    cache_dir.mkdir()
    warmed = []
    monkeypatch.setenv("NUMBA_NUM_THREADS", str(numba.config.NUMBA_NUM_THREADS))
    monkeypatch.setattr(solver, "kernel_cache", lambda: solver._warmup.KernelCache(str(cache_dir), populated))
    monkeypatch.setattr(solver, "warm_up", lambda sets: warmed.append(tuple(sets)))
    threads = numba.get_num_threads()
    _schedule._start_worker(threads, ("periodic",))
    assert warmed == [("periodic",)]
    assert (tmp_path / ".twolink-compile.lock").exists() == (not populated)
    assert numba.get_num_threads() == threads


def test_a_shipped_scene_is_named_or_given_as_a_file(tmp_path, monkeypatch):
    """``pipeline run quick`` from any directory reads the installed workflows/quick.toml; a file
    argument stays a file (a local file of a shipped scene's name wins), an unknown name is left to
    the parser, which refuses it by name."""
    import workflows

    monkeypatch.chdir(tmp_path)
    assert workflows.scene_path("quick") == str(workflows.DIRECTORY / "quick.toml")
    assert workflows.scene_path("no_such_scene") == "no_such_scene"
    assert workflows.scene_path("mine.toml") == "mine.toml"
    (tmp_path / "quick").write_text("")
    assert workflows.scene_path("quick") == "quick"  # an existing local path is never replaced


def test_run_refuses_an_unknown_scene_name_in_one_line(capsys):
    from pipeline.__main__ import main

    assert main(["run", "no_such_scene"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "no_such_scene" in err[0]
