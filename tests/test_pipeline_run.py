"""End-to-end runs of a small scene with the real solver.

Resume after SIGKILL, idempotent rerun, refusal of a changed scene and of a concurrent run,
a dask.distributed cluster giving the local scheduler's values, labelled xarray access, and the
stored reductions against a brute-force numpy maximum.
"""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from pipeline import RunContext, StoreBusy, StoreMismatch, load_scene, parse_scene, run_scene
from pipeline.__main__ import main
from pipeline._schedule import Scheduler
from pipeline._store import lock_path, run_lock
from solver.periodic import engine_options
from pipeline_cases import REPO, assert_stores_equal, cli, read_store, small_scene_text, write_scene


@pytest.fixture(scope="module")
def reference(tmp_path_factory):
    """The small scene run once, uninterrupted, on the synchronous scheduler."""
    tmp = tmp_path_factory.mktemp("reference")
    path = write_scene(tmp, small_scene_text(polish=True))
    scene = load_scene(path)
    store = tmp / "small.zarr"
    summary = run_scene(scene, store, scheduler="synchronous", progress=False)
    return scene, store, summary


def _chunk_files(store: Path, array: str) -> set[str]:
    root = store / array / "c"
    return {str(p.relative_to(root)) for p in root.rglob("*") if p.is_file() and not p.name.endswith(".partial")} \
        if root.exists() else set()


def test_first_run_computes_everything(reference):
    scene, store, summary = reference
    assert summary.computed_points == scene.n_points == 64
    assert summary.computed_chunks == summary.total_chunks == 8
    status = read_store(store)["status"]
    assert summary.failures == np.count_nonzero(status != 0)
    assert (status != -1).all()
    assert "64 points" in summary.line() and "solves/s" in summary.line() and "failures" in summary.line()


def test_the_run_record_says_where_the_time_went(reference):
    """Issue 34: the run record's ``timing`` splits wall x workers into solving and named parts
    that add up to it (within the clock's rounding), and the summary prints the same figures."""
    from pipeline._store import store_meta

    scene, store, summary = reference
    t = store_meta(store)["run"]["timing"]
    budget = t["wall_seconds"] * t["workers"]
    parts = t["not_solving_worker_seconds"]
    assert 0 < t["solve_worker_seconds"] <= budget and 0 < t["efficiency"] <= 1
    assert abs(t["solve_worker_seconds"] + sum(parts.values()) - budget) <= 0.05 * budget + 0.01, t
    assert {"setup", "chunks: idle or scheduling", "reductions: idle or scheduling"} <= set(parts) | {
        k for k, v in t["phases_wall_seconds"].items()}
    assert {"setup", "plan", "chunks", "series", "reductions", "record"} <= set(t["phases_wall_seconds"])
    line = summary.timing_line()
    assert line.startswith("small: time: wall") and f"{100 * t['efficiency']:.0f} %" in line


def test_workers_times_threads_is_the_cores():
    """Issue 34: each of N worker processes runs cores // N numba threads (at least 1): N
    processes of all-core thread pools oversubscribed the cores (docs/validation.md)."""
    from pipeline._schedule import threads_per_worker

    assert [threads_per_worker(w, 16) for w in (1, 2, 4, 16, 32)] == [16, 8, 4, 1, 1]
    assert [threads_per_worker(w, 2) for w in (1, 2, 3)] == [2, 1, 1]
    with Scheduler("processes", 2) as sched:
        sched.start()
        threads = {sched.pool().submit(_numba_threads).result() for _ in range(4)}
    assert threads == {threads_per_worker(2)}


_THREADS_SCRIPT = """
import os, sys
os.environ.pop("NUMBA_NUM_THREADS", None)
import numba  # imported before the worker's setting, as a spawned worker imports the driver's __main__
from numba.core import config
from pipeline._schedule import set_numba_threads_env
want = config.NUMBA_DEFAULT_NUM_THREADS + 1  # differs from the default on any machine
if sys.argv[1] == "fixed":
    set_numba_threads_env(want)
else:
    os.environ["NUMBA_NUM_THREADS"] = str(want)  # what the worker did before
numba.get_num_threads()  # the pool launches (a single-point kernel's thread count read)

@numba.njit
def f(x):
    return x + 1

try:
    f(1)  # a compilation: numba reloads its config
    print("ok", numba.config.NUMBA_NUM_THREADS == want)
except RuntimeError as exc:
    print("raised", exc)
"""


@pytest.mark.parametrize("mode, expected", [("fixed", "ok True"), ("env only", "raised")])
def test_a_worker_that_imported_numba_early_can_compile_after_its_pool_starts(mode, expected):
    """A spawned worker imports numba before its initializer (``python -m pipeline`` is its
    ``__main__``); setting NUMBA_NUM_THREADS then, the first compilation after the pool launched
    raised, and a first run from a fresh checkout (empty kernel cache) died in every worker.
    ``set_numba_threads_env`` reloads numba's config first; the "env only" case is the negative
    control (the old initializer's sequence, which must raise)."""
    env = {k: v for k, v in os.environ.items() if k != "NUMBA_NUM_THREADS"}
    env["PYTHONPATH"] = os.pathsep.join([str(REPO), env.get("PYTHONPATH", "")])
    out = subprocess.run([sys.executable, "-c", _THREADS_SCRIPT, mode], capture_output=True,
                         text=True, env=env, cwd=str(REPO), timeout=300)
    assert out.stdout.strip().startswith(expected), (out.stdout, out.stderr[-2000:])


def _numba_threads() -> int:
    import numba

    return numba.get_num_threads()


def test_xarray_opens_store_with_labels(reference):
    xr = pytest.importorskip("xarray")
    scene, store, _ = reference
    ds = xr.open_zarr(store)
    assert ds["scaled_efficiency"].dims == ("anisotropy_ratio", "scaled_period", "A0", "A1_ratio")
    np.testing.assert_allclose(ds["A0"].values, np.linspace(0.4, 1.5, 4))
    np.testing.assert_allclose(ds["scaled_period"].values, [1.0, 2.0])
    assert ds["best_efficiency"].dims == ("anisotropy_ratio", "scaled_period")
    assert ds["fastest"].dims == ("anisotropy_ratio",)
    from pipeline import decode_attrs, read_record

    # CF flags as stored; their sentences through the one reader of attributes
    assert ds["status"].attrs["flag_meanings"].split()[:2] == ["not_computed_yet", "converged"]
    assert list(ds["status"].attrs["flag_values"][:2]) == [-1, 0]
    meanings = decode_attrs(ds["status"].attrs)["flag_meanings"]
    assert meanings["0"].startswith("converged") and "-1" in meanings
    record = read_record(ds.attrs)
    prov = record["provenance"]
    assert prov["scene_hash"] == scene.hash and prov["scene"]["name"] == "small"
    assert "zarr" in prov["library_versions"] and prov["created"]
    assert prov["engine_options"] == engine_options()  # the defaults, by field
    assert record["format_version"] == 3
    run = record["run"]
    assert run["computed_points"] == 64 and run["wall_seconds"] > 0 and run["runs"] == 1
    # Label-based selection works.
    one = ds["scaled_efficiency"].sel(anisotropy_ratio=16.0, scaled_period=2.0).values
    assert one.shape == (4, 4)
    # Outputs the scene did not ask for are not stored.
    assert "scaled_power" not in ds and "U" not in ds


def test_series_stored_at_the_requested_points_only(reference):
    xr = pytest.importorskip("xarray")
    _, store, _ = reference
    ds = xr.open_zarr(store)
    assert ds["series_u"].dims == ("series_point", "series_tau") and ds["series_u"].shape == (2, 64)
    np.testing.assert_allclose(ds["series_tau"].values, np.arange(64) / 64)
    assert (ds["series_status"].values == 0).all()
    import solver
    tau = np.arange(64) / 64
    for k, (i, j, a, b) in enumerate([(1, 1, 0, 3), (0, 0, 3, 0)]):
        assert ds["series_A0"].values[k] == ds["A0"].values[a]
        # The mean of u over a period is T U: the grid's scaled speed times the scaled period
        # (mu_n mu_s = 1).
        speed = ds["scaled_speed"].values[i, j, a, b] * ds["scaled_period"].values[j]
        np.testing.assert_allclose(ds["series_u"].values[k].mean(), speed, rtol=2e-2, atol=1e-4)
        # sample by sample: the solver's own u(tau) at that point, periodic-interpolated at k/64
        A0, ratio = ds["A0"].values[a], ds["A1_ratio"].values[b]
        physics = solver.Physics.from_scaled(ds["anisotropy_ratio"].values[i],
                                             ds["scaled_period"].values[j], p=0.0, delta=1e-5)
        res = solver.solve_periodic(solver.Harmonic(A0, ratio * A0), physics, rtol=1e-3,
                                    return_series=True)
        expected = np.interp(tau, res.tau[0], res.u[0], period=1.0)
        np.testing.assert_allclose(ds["series_u"].values[k], expected, rtol=1e-12, atol=0)


def test_reductions_equal_brute_force_numpy(reference):
    scene, store, _ = reference
    v = read_store(store)
    q = v["scaled_efficiency"]  # (ratio, period, A0, A1_ratio)
    A0, A1r = v["A0"], v["A1_ratio"]
    for i in range(2):
        for j in range(2):
            block = np.abs(q[i, j])
            k = np.nanargmax(block)
            a, b = np.unravel_index(k, block.shape)
            assert v["best_efficiency"][i, j] == np.nanmax(block)
            assert v["best_efficiency_signed"][i, j] == q[i, j, a, b]
            assert v["best_efficiency_A0"][i, j] == A0[a]
            assert v["best_efficiency_A1_ratio"][i, j] == A1r[b]
            assert v["best_efficiency_relative_efficiency"][i, j] == v["relative_efficiency"][i, j, a, b]
            # Polished: never below the grid optimum, inside the axes' ranges.
            assert v["best_efficiency_polished"][i, j] >= v["best_efficiency"][i, j] * (1 - 1e-3)
            assert A0.min() <= v["best_efficiency_polished_A0"][i, j] <= A0.max()
            assert A1r.min() <= v["best_efficiency_polished_A1_ratio"][i, j] <= A1r.max()
            # converged (pipeline.polish): the scene's cap (200 per start) is far above what
            # Powell needs on this 2-d box; at most 3 starts
            assert v["best_efficiency_polished_status"][i, j] == 0
            assert 1 <= v["best_efficiency_polished_evaluations"][i, j] <= 3 * 200
            assert 0 <= v["best_efficiency_polished_uncertainty"][i, j] < 1e-2
            for name, axis in (("A0", A0), ("A1_ratio", A1r)):
                x, edge = v[f"best_efficiency_polished_{name}"][i, j], v[f"best_efficiency_polished_{name}_edge"][i, j]
                assert edge == (-1 if np.isclose(x, axis.min()) else 1 if np.isclose(x, axis.max()) else 0)
    s = v["scaled_speed"]
    for i in range(2):
        assert v["fastest"][i] == np.nanmax(s[i])
        t, a, b = np.unravel_index(np.nanargmax(s[i]), s[i].shape)
        assert (v["fastest_scaled_period"][i], v["fastest_A0"][i], v["fastest_A1_ratio"][i]) == \
            (v["scaled_period"][t], A0[a], A1r[b])


def test_idempotent_rerun_computes_nothing(reference, capsys):
    scene, store, _ = reference
    before = {p: p.stat().st_mtime_ns for p in store.rglob("*") if p.is_file()}
    summary = run_scene(scene, store, scheduler="synchronous", progress=False)
    assert summary.computed_chunks == 0 and summary.computed_points == 0
    assert not summary.reductions_computed
    assert "nothing to do" in summary.line()
    after = {p: p.stat().st_mtime_ns for p in store.rglob("*") if p.is_file()}
    assert after == before  # not one file rewritten


def test_changed_scene_is_refused(reference, tmp_path, capsys):
    scene, store, _ = reference
    changed = write_scene(tmp_path, small_scene_text(rtol=5e-4, polish=True), "changed.toml")
    with pytest.raises(StoreMismatch, match="different scene.*--overwrite"):
        run_scene(load_scene(changed), store, scheduler="synchronous", progress=False)
    assert main(["run", str(changed), "--store", str(store), "--no-progress"]) == 3
    assert "--overwrite" in capsys.readouterr().err
    assert read_store(store)["status"].shape == (2, 2, 4, 4)  # untouched


def test_overwrite_replaces_store(tmp_path):
    path = write_scene(tmp_path, small_scene_text())
    store = tmp_path / "s.zarr"
    run_scene(load_scene(path), store, scheduler="threads", workers=2, progress=False)
    other = write_scene(tmp_path, small_scene_text(rtol=5e-4), "other.toml")
    summary = run_scene(load_scene(other), store, scheduler="threads", workers=2, overwrite=True, progress=False)
    assert summary.computed_chunks == summary.total_chunks
    from pipeline._store import store_meta

    assert store_meta(store)["provenance"]["scene_hash"] == load_scene(other).hash


def test_overwrite_resumes_a_store_of_the_same_scene(reference):
    """--overwrite replaces only a store that would be refused: a complete store of the same
    scene and engine is left as it is (``paper --overwrite`` after a change to one scene
    recomputes that scene only). The control, a different scene, is test_overwrite_replaces_store."""
    scene, store, _ = reference
    before = {p: p.stat().st_mtime_ns for p in store.rglob("*") if p.is_file()}
    summary = run_scene(scene, store, scheduler="synchronous", overwrite=True, progress=False)
    assert summary.computed_chunks == 0 and summary.computed_points == 0
    assert {p: p.stat().st_mtime_ns for p in store.rglob("*") if p.is_file()} == before


def test_not_a_zarr_store_is_refused(tmp_path):
    path = write_scene(tmp_path, small_scene_text())
    victim = tmp_path / "precious"
    victim.mkdir()
    (victim / "notes.txt").write_text("keep me")
    with pytest.raises(StoreMismatch, match="not a Zarr store"):
        run_scene(load_scene(path), victim, scheduler="synchronous", overwrite=True, progress=False)
    assert (victim / "notes.txt").read_text() == "keep me"


def test_a_grid_store_exports_to_netcdf(reference, tmp_path):
    """Issue 34: a grid store exports as it is, ``xarray.open_zarr(store).to_netcdf(path)``, and
    through ``pipeline.to_netcdf`` (CF flags, JSON provenance); each reads back equal; its
    outputs carry ``units``."""
    import xarray as xr

    from pipeline_cases import assert_exports_to_netcdf

    scene, store, _ = reference
    assert_exports_to_netcdf(store, tmp_path)
    with xr.open_dataset(tmp_path / "export.nc") as back:
        assert all(back[name].attrs.get("units") == "1" for name in scene.outputs)
        # pipeline.to_netcdf gives CF's flag_values the variable's type
        assert back["status"].attrs["flag_values"].dtype == np.int8


def test_the_netcdf_checks_can_fail(reference, tmp_path):
    """Negative controls of ``assert_exports_to_netcdf``'s checks: an attribute of a dict (or
    bool, or None, or list of words) type, and a variable of a type netCDF 3 lacks, are found
    by ``netcdf_problems`` (and netCDF's writer refuses the dict); a value or an attribute
    changed in the file read back fails ``assert_same_dataset``."""
    import warnings

    import xarray as xr

    from pipeline_cases import assert_same_dataset, netcdf_problems

    _, store, _ = reference
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        raw = xr.open_zarr(str(store), zarr_format=3, consolidated=False).load()
    assert netcdf_problems(raw) == []
    for bad in ({"a": 1}, True, None, ["a", "b"], []):
        spoilt = raw.copy()
        spoilt["status"].attrs = {**raw["status"].attrs, "extra": bad}
        problems = netcdf_problems(spoilt)
        assert len(problems) == 1 and problems[0].startswith("status.attrs['extra']: "), (bad, problems)
    spoilt = raw.copy()
    spoilt.attrs = {"pipeline": {"format_version": 2}}  # the record as format 1 stored it
    assert netcdf_problems(spoilt) == ["attrs['pipeline']: a dict"]
    with pytest.raises(TypeError):
        spoilt.to_netcdf(tmp_path / "dict.nc")
    for dtype in (np.uint8, np.int64, bool):
        spoilt = raw.copy()
        spoilt["status"] = spoilt["status"].astype(dtype)
        assert netcdf_problems(spoilt) == [f"status: dtype {np.dtype(dtype)}"]
    raw.to_netcdf(tmp_path / "raw.nc")
    with xr.open_dataset(tmp_path / "raw.nc") as back:
        back = back.load()
    assert_same_dataset(raw, back)
    changed = back.copy(deep=True)
    changed["scaled_efficiency"][0, 0, 0, 0] += 1e-12
    with pytest.raises(AssertionError):
        assert_same_dataset(raw, changed)
    changed = back.copy()
    changed.attrs = {"pipeline": back.attrs["pipeline"].replace('"format_version": 3', '"format_version": 4')}
    with pytest.raises(AssertionError):
        assert_same_dataset(raw, changed)
    changed = back.copy()
    changed["status"].attrs = {**back["status"].attrs, "flag_descriptions": "[]"}
    with pytest.raises(AssertionError):
        assert_same_dataset(raw, changed)


def test_a_store_of_format_1_is_read_by_the_reports_refused_for_resuming_and_rebuilt(reference, tmp_path, capsys):
    """A store written before issue 34 (format 1: nested attributes) opens in the reports with
    the same record (but its version), attributes and arrays as the same store in format 3; the
    pipeline refuses to resume it in one line naming --overwrite (exit 3, the store untouched),
    and ``--overwrite`` rebuilds it, equal to the reference."""
    import shutil

    from pipeline_cases import downgrade_to_format_1
    from reports._read import open_scene_store

    scene, store, _ = reference
    old = tmp_path / "old.zarr"
    shutil.copytree(store, old)
    downgrade_to_format_1(old)
    new_view, old_view = open_scene_store(store), open_scene_store(old)
    assert old_view.meta["format_version"] == 1
    assert {**old_view.meta, "format_version": 3} == new_view.meta
    assert {**old_view.ds.attrs, "pipeline": old_view.meta | {"format_version": 3}} == new_view.ds.attrs
    assert sorted(old_view.ds.variables) == sorted(new_view.ds.variables)
    for name in new_view.ds.variables:
        assert old_view.ds[name].attrs == new_view.ds[name].attrs, name
        np.testing.assert_array_equal(old_view.array(name), new_view.array(name), err_msg=name)
    assert isinstance(new_view.ds["status"].attrs["flag_meanings"], dict)
    before = read_store(old)
    with pytest.raises(StoreMismatch, match="format version 1.*--overwrite"):
        run_scene(scene, old, scheduler="synchronous", progress=False)
    path = write_scene(tmp_path, small_scene_text(polish=True))
    assert main(["run", str(path), "--store", str(old), "--no-progress"]) == 3
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and str(old) in err[0] and "--overwrite" in err[0]
    after = read_store(old)
    assert sorted(after) == sorted(before)
    for k in after:
        np.testing.assert_array_equal(after[k], before[k], err_msg=k)
    summary = run_scene(scene, old, scheduler="synchronous", overwrite=True, progress=False)
    assert summary.computed_chunks == summary.total_chunks
    assert_stores_equal(old, store)
    assert open_scene_store(old).meta["format_version"] == 3


def test_a_store_of_format_2_is_read_by_the_reports_and_refused_for_resuming_by_name(reference, tmp_path, capsys):
    """A store of format 2 (before issue 46: a chunk file per block, ``layout.chunks`` the
    blocks, no ``layout.blocks``) opens in the reports through zarr's public API with the
    reference's arrays; the pipeline refuses to resume it in one line naming format 2 and
    --overwrite, exit 3, the store untouched."""
    import shutil

    from pipeline._attrs import ATTRS_KEY, read_record, record_text
    from reports._read import open_scene_store

    scene, store, _ = reference
    old = tmp_path / "old.zarr"
    shutil.copytree(store, old)
    meta = read_record(__import__("json").loads((old / "zarr.json").read_text())["attributes"])
    layout = {k: v for k, v in meta["layout"].items() if k != "blocks"} | {"chunks": meta["layout"]["blocks"]}
    with __import__("warnings").catch_warnings():
        __import__("warnings").simplefilter("ignore")
        import zarr

        zarr.open_group(str(old), mode="r+").attrs[ATTRS_KEY] = record_text({**meta, "format_version": 2,
                                                                              "layout": layout})
        zarr.consolidate_metadata(str(old), zarr_format=3)
    view = open_scene_store(old)
    assert view.meta["format_version"] == 2
    for name in ("scaled_efficiency", "status"):
        np.testing.assert_array_equal(view.array(name), open_scene_store(store).array(name), err_msg=name)
    before = read_store(old)
    path = write_scene(tmp_path, small_scene_text(polish=True))
    assert main(["run", str(path), "--store", str(old), "--no-progress"]) == 3
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "format version 2" in err[0] and "--overwrite" in err[0], err
    after = read_store(old)
    for k in after:
        np.testing.assert_array_equal(after[k], before[k], err_msg=k)


def test_concurrent_run_is_refused_and_stale_lock_taken_over(tmp_path, capsys):
    path = write_scene(tmp_path, small_scene_text())
    store = tmp_path / "s.zarr"
    with run_lock(store):
        with pytest.raises(StoreBusy, match=f"pid {os.getpid()}"):
            run_scene(load_scene(path), store, scheduler="synchronous", progress=False)
        assert main(["run", str(path), "--store", str(store), "--no-progress"]) == 3
        assert "another run is using this store" in capsys.readouterr().err
    assert not store.exists()  # refused before anything was written
    # A lock file left by a dead process (no flock held) is stale and taken over.
    lock_path(store).write_text('{"pid": 999999, "host": "gone", "since": "yesterday"}')
    summary = run_scene(load_scene(path), store, scheduler="synchronous", progress=False)
    assert summary.computed_chunks == 8


def test_sigkill_mid_run_then_resume_matches_uninterrupted(reference, tmp_path):
    _, ref_store, _ = reference
    path = write_scene(tmp_path, small_scene_text(polish=True))
    store = tmp_path / "killed.zarr"
    args = ("run", path, "--store", store, "--scheduler", "processes", "--workers", "2", "--no-progress")
    env = dict(os.environ, PYTHONPATH=str(REPO) + os.pathsep + os.environ.get("PYTHONPATH", ""),
               TWOLINK_PIPELINE_MARKER_DELAY="0.4")
    proc = subprocess.Popen([sys.executable, "-m", "pipeline", *map(str, args)], cwd=REPO, env=env,
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, start_new_session=True)
    half_written = set()
    try:
        deadline = time.monotonic() + 240
        while time.monotonic() < deadline and proc.poll() is None:
            done = _chunk_files(store, "pipeline_state/chunk_done")
            data = _chunk_files(store, "status")
            half_written = data - done
            if done and half_written:
                break  # at least one chunk done and one written without its marker: pull the plug
            time.sleep(0.005)
        assert proc.poll() is None, f"run ended before it could be killed: {proc.communicate()}"
        os.killpg(proc.pid, signal.SIGKILL)  # driver and its workers: like a power cut
    finally:
        proc.wait(timeout=30)
    assert proc.returncode == -signal.SIGKILL
    done_before = _chunk_files(store, "pipeline_state/chunk_done")
    assert 0 < len(done_before) < 8 and half_written
    # Same command again: only the unfinished chunks are computed.
    resumed = cli(*args)
    assert resumed.returncode == 0, resumed.stderr
    timing, line = resumed.stdout.strip().splitlines()[-2:]
    assert timing.startswith("small: time: wall") and "x 2 workers" in timing and "efficiency" in timing
    assert f"({64 - 8 * len(done_before)} computed now in {8 - len(done_before)}/8 chunks)" in line, line
    assert not list(store.rglob("*.partial"))
    assert_stores_equal(store, ref_store)
    # And once more: nothing to do.
    again = cli(*args)
    assert again.returncode == 0 and "nothing to do" in again.stdout


def test_one_pool_serves_several_scenes(reference, tmp_path):
    """Issue 34: runs sharing a ``Session`` (``paper``) use one pool: its workers start (imports,
    kernels) once, reported by the first run only; the stores equal the synchronous one."""
    from pipeline import Session
    from pipeline._store import store_meta

    scene, ref_store, _ = reference
    with Session("processes", 2, ("periodic",)) as session:
        stores = [tmp_path / f"{i}.zarr" for i in range(2)]
        workers = []
        for store in stores:
            run_scene(scene, store, session=session, progress=False)
            workers.append(set(session._pool._processes))  # the pool's worker processes (pids)
    # One pool: the same two processes ran both scenes (a second pool would have new pids).
    assert len(workers[0]) == 2 and workers[1] == workers[0], workers
    starts = [store_meta(s)["run"]["timing"]["not_solving_worker_seconds"].get("worker start-up", 0.0)
              for s in stores]
    # A worker's start-up is reported once, with its first task: the first run's first task has it.
    # (Which run a worker's first task falls in is the scheduler's choice: on an idle machine one
    # worker can take all of a small scene's tasks, and the other reports its start in the second.)
    assert starts[0] > 0, starts
    for store in stores:
        assert_stores_equal(store, ref_store)


def test_a_session_started_before_its_runs_reports_no_start_up_in_them(reference, tmp_path):
    """Issue 34: ``Session.wait_ready`` (``paper``) waits until every worker has started (imports,
    kernels) and returns that start-up, so no run's budget carries it; negative control: without
    it the first run's record has the workers' start-up (the test above)."""
    from pipeline import Session
    from pipeline._store import store_meta

    scene, ref_store, _ = reference
    with Session("processes", 2, ("periodic",)) as session:
        started = session.wait_ready()
        assert started["workers"] == 2 and started["worker_seconds"] > 0, started
        assert started["wall_seconds"] > 0
        assert session.wait_ready()["worker_seconds"] == 0.0  # taken once
        run_scene(scene, tmp_path / "s.zarr", session=session, progress=False)
    parts = store_meta(tmp_path / "s.zarr")["run"]["timing"]["not_solving_worker_seconds"]
    assert parts.get("worker start-up", 0.0) == 0.0, parts
    assert_stores_equal(tmp_path / "s.zarr", ref_store)
    assert Scheduler("threads", 2).wait_ready() == {"workers": 0, "wall_seconds": 0.0,
                                                    "worker_seconds": 0.0, "worker_cpu_seconds": 0.0}


def test_distributed_local_cluster_matches_local_scheduler(reference, tmp_path):
    distributed = pytest.importorskip("distributed")
    _, ref_store, _ = reference
    path = write_scene(tmp_path, small_scene_text(polish=True))
    store = tmp_path / "dist.zarr"
    with distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=False,
                                  dashboard_address=None) as cluster:
        summary = run_scene(load_scene(path), store, scheduler=cluster.scheduler_address, progress=False)
    assert summary.computed_chunks == 8
    assert_stores_equal(store, ref_store)


def test_task_size_is_calibrated_by_a_probe(tmp_path):
    from pipeline._grid import MAX_POINTS_PER_TASK, MIN_POINTS_PER_TASK, calibrate_points_per_task

    text = small_scene_text().replace("points_per_task = 8\n", "")
    scene = load_scene(write_scene(tmp_path, text))
    assert scene.execution.points_per_task is None
    target, rate = calibrate_points_per_task(scene, workers=2, n_probe=8)
    assert rate > 0
    # Small scene: capped so that every worker gets several tasks.
    assert MIN_POINTS_PER_TASK <= target <= max(MIN_POINTS_PER_TASK, -(-64 // 8)) <= MAX_POINTS_PER_TASK
    proc = cli("estimate", write_scene(tmp_path, text, "e.toml"), "--probe", "4", "--workers", "2")
    assert proc.returncode == 0, proc.stderr
    assert "small" in proc.stdout and "total" in proc.stdout


def test_stores_do_not_depend_on_the_task_grouping(tmp_path, monkeypatch):
    """Issue 29, issue 34: one scene run with one chunk per task and with four gives equal
    stores, every array (data and pipeline_state) included; the grouping comes from counts
    (``_grid_kind.TASK_POINTS``, ``_kind.TASKS_PER_WORKER``), never from a timing probe."""
    import pipeline._grid as grid
    import pipeline._kind as kind_module
    import pipeline._grid_kind as grid_kind
    from pipeline._store import store_meta

    def no_probe(*args, **kwargs):
        raise AssertionError("task sizes must not come from a timing probe")

    monkeypatch.setattr(grid, "calibrate_points_per_task", no_probe)
    # 16 chunks of 4 points (1 x 1 x 1 x 4); no points_per_task: counts group them into tasks.
    text = small_scene_text().replace("points_per_chunk = 8\npoints_per_task = 8\n", "points_per_chunk = 4\n")
    scene = load_scene(write_scene(tmp_path, text))
    stores, groupings = [], []
    for task_points in (4, 16):
        monkeypatch.setattr(grid_kind, "TASK_POINTS", task_points)
        monkeypatch.setattr(kind_module, "TASKS_PER_WORKER", 1)
        with Scheduler("synchronous", None) as sched:
            ctx = RunContext(scene, tmp_path / "x.zarr", sched, 1, False, print)
            groupings.append(grid_kind.GRID.chunks_per_task(ctx, (1, 1, 1, 4), [(0,)] * 16))
        store = tmp_path / f"tasks{task_points}.zarr"
        summary = run_scene(scene, store, scheduler="synchronous", progress=False)
        assert summary.computed_chunks == summary.total_chunks == 16
        stores.append(store)
    assert groupings == [1, 4]
    assert store_meta(stores[0])["layout"] == store_meta(stores[1])["layout"]
    assert read_store(stores[0])["pipeline_state/chunk_done"].shape == (2, 2, 4, 1)
    assert_stores_equal(stores[0], stores[1])


def test_tasks_are_sized_by_counts():
    """Without ``points_per_task``: ``TASK_POINTS`` points per task, but at least
    ``TASKS_PER_WORKER`` tasks per worker where the chunks allow (harmonic_grid's 144 chunks of
    256 points: 4 chunks per task on 2 workers, 1 on 16); with it, as many chunks as fit."""
    import pipeline._grid_kind as grid_kind

    scene = load_scene(REPO / "workflows" / "harmonic_grid.toml")
    chunks = (1, 1, 4, 64)
    pending = [(0,)] * 144

    def per_task(workers, s=scene):
        with Scheduler("synchronous", None) as sched:
            return grid_kind.GRID.chunks_per_task(RunContext(s, Path("x.zarr"), sched, workers, False, print),
                                              chunks, pending)

    from pipeline._kind import TASKS_PER_WORKER

    assert grid_kind.TASK_POINTS // 256 == 4 and TASKS_PER_WORKER == 16
    assert [per_task(w) for w in (1, 2, 4, 16)] == [4, 4, 2, 1]
    given = parse_scene(scene.text.replace("[solver]", "[execution]\npoints_per_task = 2048\n\n[solver]"), "g.toml")
    assert per_task(16, given) == 8
    # optima: 16 starts per task, >= 16 tasks per worker (fourier_optima: 432 chunks of 4 starts)
    from pipeline._optima import OPTIMA

    optima = load_scene(REPO / "workflows" / "fourier_optima.toml")
    with Scheduler("synchronous", None) as sched:
        counts = [OPTIMA.chunks_per_task(RunContext(optima, Path("x.zarr"), sched, w, False, print), (1, 1, 1, 4),
                                         [(0,)] * 432) for w in (1, 2, 16)]
    assert counts == [4, 4, 1]


def test_store_of_another_chunk_layout_is_refused_until_complete(reference, tmp_path, capsys):
    """A store whose blocks are not the scene's layout (an older pipeline chose them by a
    timing probe) is refused while chunks remain to compute, with a one-line error naming
    --overwrite; a complete one is left as it is."""
    from pipeline._store import create_skeleton

    scene, ref_store, _ = reference
    path = write_scene(tmp_path, small_scene_text(polish=True))
    store = tmp_path / "old.zarr"
    create_skeleton(store, scene, (1, 1, 4, 4))  # as the probe of an older pipeline might have chosen
    with pytest.raises(StoreMismatch, match=r"blocks \(1 x 1 x 4 x 4\) are not this scene's block layout "
                                            r"\(1 x 1 x 2 x 4\).*--overwrite"):
        run_scene(load_scene(path), store, scheduler="synchronous", progress=False)
    assert main(["run", str(path), "--store", str(store), "--no-progress"]) == 3
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "--overwrite" in err and "block layout" in err
    assert (read_store(store)["status"] == -1).all()  # untouched
    # --overwrite starts that store over in the scene's layout (same scene: replaced, not resumed)
    summary = run_scene(load_scene(path), store, scheduler="synchronous", overwrite=True, progress=False)
    assert summary.computed_chunks == summary.total_chunks
    from pipeline._store import store_meta

    assert tuple(store_meta(store)["layout"]["blocks"]) == (1, 1, 2, 4)
    # The layout of a scene without sweeps changed under a complete store (points_per_chunk is
    # then not hashed): nothing is left to compute in the old layout, so the store is accepted
    # as it is.  (With sweeps the layout is hashed: such a store is another scene's.)
    cold = small_scene_text(polish=True).replace("sweeps = true", "sweeps = false")
    cold_store = tmp_path / "cold.zarr"
    run_scene(load_scene(write_scene(tmp_path, cold, "cold.toml")), cold_store, scheduler="synchronous",
              progress=False)
    other = write_scene(tmp_path, cold.replace("points_per_chunk = 8", "points_per_chunk = 16"), "other.toml")
    summary = run_scene(load_scene(other), cold_store, scheduler="synchronous", progress=False)
    assert summary.computed_chunks == 0 and "nothing to do" in summary.line()
    swept_other = write_scene(tmp_path, small_scene_text(polish=True).replace("points_per_chunk = 8",
                                                                              "points_per_chunk = 16"), "swept.toml")
    with pytest.raises(StoreMismatch):
        run_scene(load_scene(swept_other), ref_store, scheduler="synchronous", progress=False)


def test_run_killed_during_reductions_recomputes_only_reductions(reference, tmp_path):
    import shutil

    import zarr

    from pipeline._store import set_state

    scene, ref_store, _ = reference
    store = tmp_path / "copy.zarr"
    shutil.copytree(ref_store, store)
    # As left by a run killed after its last chunk but before its reductions were written.
    set_state(store, reductions_complete=False)
    zarr.open_array(str(store), path="best_efficiency", mode="r+")[...] = np.nan
    summary = run_scene(scene, store, scheduler="synchronous", progress=False)
    assert summary.computed_chunks == 0 and summary.reductions_computed
    assert_stores_equal(store, ref_store)
