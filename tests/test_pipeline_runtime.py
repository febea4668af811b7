"""A user's own work, safe (issue 45): a store the pipeline did not write is never destroyed, the
progress bar moves as tasks finish on every scheduler, worker processes end when their driver
dies by any signal, a refused run leaves the lock holder's record intact, Ctrl-C ends the run on
one line with the chunks kept, and a cluster's workers are counted (``estimate``:
test_pipeline_estimate.py; the mistakes' one-line errors: test_pipeline_mistakes.py).

Each defect's test failed on d799bf7 (the main of issue 45), as its docstring says.
"""

from __future__ import annotations

import json
import os
import re
import signal
import subprocess
import sys
import textwrap
from pathlib import Path

import numpy as np
import pytest

from pipeline import load_scene, run_scene
from pipeline.__main__ import main
from pipeline._schedule import Scheduler, Task, compute
from pipeline._store import STARTED_MARKER, StoreForeign, lock_path, open_existing, run_lock
from pipeline_cases import REPO, assert_stores_equal, cli, small_scene_text, write_scene
from runtime_helpers import (SLOW_WRITES, ProgressTimes, children, finish_after, kill_all, start_driver,
                             wait_for_chunks, wait_gone)


@pytest.fixture(scope="module")
def reference(tmp_path_factory):
    """The small scene run once, uninterrupted, on the synchronous scheduler."""
    tmp = tmp_path_factory.mktemp("reference")
    path = write_scene(tmp, small_scene_text(polish=True))
    store = tmp / "small.zarr"
    run_scene(load_scene(path), store, scheduler="synchronous", progress=False)
    return path, store


def _files(folder: Path) -> dict[str, bytes]:
    return {str(p.relative_to(folder)): p.read_bytes() for p in sorted(folder.rglob("*")) if p.is_file()}


def _xarray_store(path: Path) -> None:
    xr = pytest.importorskip("xarray")
    xr.Dataset({"temperature": (("x",), np.arange(5.0))}, attrs={"title": "my own data"}).to_zarr(
        str(path), zarr_format=3, consolidated=False)


# -- 1. a store the pipeline did not write -----------------------------------------------------


def test_a_zarr_store_written_by_xarray_is_refused_unless_overwrite(tmp_path):
    """Issue 45 item 1: on d799bf7 ``run`` deleted a Zarr store written by xarray and wrote the
    scene there, exit 0, without --overwrite.  Now: exit 3, one line naming the store and
    --overwrite, every file as it was, no lock file left beside it; with --overwrite it is
    replaced (exit 0)."""
    scene = write_scene(tmp_path, small_scene_text())
    store = tmp_path / "plain.zarr"
    _xarray_store(store)
    before = _files(store)
    refused = cli("run", scene, "--store", store, "--scheduler", "synchronous", "--no-progress")
    assert refused.returncode == 3, refused
    lines = refused.stderr.strip().splitlines()
    assert len(lines) == 1 and str(store) in lines[0] and "--overwrite" in lines[0], refused.stderr
    assert "did not write" in lines[0]
    assert _files(store) == before and not lock_path(store).exists()
    replaced = cli("run", scene, "--store", store, "--scheduler", "synchronous", "--no-progress", "--overwrite")
    assert replaced.returncode == 0, replaced.stderr
    assert "64 computed now" in replaced.stdout and "temperature" not in os.listdir(store)


def test_a_folder_of_other_files_is_never_touched(tmp_path):
    """A folder that is no Zarr store (the control of the foreign-store refusal: refused even
    with --overwrite, which would otherwise delete it)."""
    scene = write_scene(tmp_path, small_scene_text())
    folder = tmp_path / "thesis"
    folder.mkdir()
    (folder / "chapter1.tex").write_text("keep me")
    for extra in ((), ("--overwrite",)):
        proc = cli("run", scene, "--store", folder, "--scheduler", "synchronous", "--no-progress", *extra)
        assert proc.returncode == 3 and len(proc.stderr.strip().splitlines()) == 1, proc
        assert "not a Zarr store" in proc.stderr
    assert _files(folder) == {"chapter1.tex": b"keep me"} and not lock_path(folder).exists()


_KILL_SKELETON = textwrap.dedent("""
    import os, signal, sys
    from pathlib import Path
    import zarr
    import pipeline._store as st
    from pipeline import load_scene
    from pipeline._grid_kind import GRID

    point, n = sys.argv[3], int(sys.argv[4])
    calls = {"write": 0}

    def die():
        os.kill(os.getpid(), signal.SIGKILL)

    real_open_group, real_unlink = st.open_group, Path.unlink
    real_create, real_update = zarr.Group.create_array, zarr.Group.update_attributes

    def open_group(store, mode):
        if point == "after the marker":
            die()
        return real_open_group(store, mode)

    def create_array(self, *a, **k):
        calls["write"] += 1
        if point == "amid the files" and calls["write"] > n:
            die()
        return real_create(self, *a, **k)

    def update_attributes(self, attrs):
        if point == "before the record" and st.ATTRS_KEY in attrs:
            die()
        return real_update(self, attrs)

    def unlink(self, *a, **k):
        if point == "before the marker is removed" and self.name == st.STARTED_MARKER:
            die()
        return real_unlink(self, *a, **k)

    st.open_group, Path.unlink = open_group, unlink
    zarr.Group.create_array, zarr.Group.update_attributes = create_array, update_attributes
    scene = load_scene(sys.argv[1])
    st.create_skeleton(Path(sys.argv[2]), scene, GRID.block_layout(scene))
    print("not killed")
""")


@pytest.mark.parametrize("point, n", [("after the marker", 0), ("amid the files", 1), ("amid the files", 30),
                                      ("before the record", 0), ("before the marker is removed", 0)])
def test_a_skeleton_killed_while_created_is_rebuilt_and_not_refused(reference, tmp_path, point, n):
    """Issue 45 item 1's other side: a skeleton of the pipeline's own, its process SIGKILLed at
    any point while creating it, is recognised (the start marker written first) and rebuilt by
    the next run, never refused as foreign; killed after its record, it is complete.  Control:
    the same half-written skeleton without its marker is refused as a store the pipeline did
    not write (the marker is what tells them apart)."""
    path, ref_store = reference
    store = tmp_path / "s.zarr"
    env = dict(os.environ, PYTHONPATH=str(REPO) + os.pathsep + os.environ.get("PYTHONPATH", ""))
    killed = subprocess.run([sys.executable, "-c", _KILL_SKELETON, str(path), str(store), point, str(n)],
                            cwd=REPO, env=env, capture_output=True, text=True)
    assert killed.returncode == -signal.SIGKILL, killed
    assert (store / STARTED_MARKER).is_file()
    meta = open_existing(store)
    if point == "before the marker is removed":
        assert meta is not None and meta["state"]["skeleton_complete"]  # the record is in place
    else:
        assert meta is None  # an interrupted skeleton of ours: rebuilt
        control = tmp_path / "control.zarr"
        subprocess.run(["cp", "-r", str(store), str(control)], check=True)
        (control / STARTED_MARKER).unlink()
        if point == "after the marker":  # killed before the group: nothing but the marker was there
            assert list(control.iterdir()) == []
        else:
            with pytest.raises(StoreForeign):
                open_existing(control)
    summary = run_scene(load_scene(path), store, scheduler="synchronous", progress=False)
    assert summary.computed_chunks == 8 and not (store / STARTED_MARKER).exists()
    assert_stores_equal(store, ref_store)


# -- 2. live progress on every scheduler ---------------------------------------------------------


@pytest.mark.parametrize("name", ["processes", "threads", "synchronous", "distributed"])
def test_progress_moves_as_each_task_finishes(name):
    """Issue 45 item 2: on the default "processes" scheduler d799bf7's ``compute`` waited for the
    first exception or the last task (FIRST_EXCEPTION), so the bar stood still and then printed
    every line at once.  Two tasks, one 0.2 s, one 4 s: the k-th progress update comes within
    2 s of the k-th task's end, on every scheduler (on d799bf7, "processes": the first update
    came ~3.8 s after the first task ended)."""
    tasks = [Task("pipeline-fast", finish_after, (0.2,)), Task("pipeline-slow", finish_after, (4.0,))]
    bar = ProgressTimes()
    if name == "distributed":
        distributed = pytest.importorskip("distributed")
        with distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=False,
                                      dashboard_address=None) as cluster:
            with Scheduler(cluster.scheduler_address, None) as sched:
                ends = compute(tasks, sched, bar)
    else:
        with Scheduler(name, 2) as sched:
            sched.wait_ready()  # both workers up (processes) before the clock matters
            ends = compute(tasks, sched, bar)
    assert len(bar.times) == 2
    for end, update in zip(sorted(ends), sorted(bar.times)):
        assert -0.5 < update - end < 2.0, (name, ends, bar.times)


# -- 3. workers end with their driver; Ctrl-C ----------------------------------------------------


@pytest.mark.parametrize("how", ["SIGKILL of the driver", "Ctrl-C"])
def test_workers_end_with_their_driver_and_the_run_resumes(reference, tmp_path, how):
    """Issue 45 items 3 and 5: on d799bf7, after kill -9 of the driver its worker processes and
    the resource tracker ran on (idle, for good); after Ctrl-C it printed a KeyboardInterrupt
    traceback.  Now every process the driver started is gone within 10 s of the driver's
    SIGKILL (the signal reaches the driver alone), and Ctrl-C (SIGINT to the process group, as a
    terminal sends it) ends the run with exit 130 and one line counting the chunks kept.  The
    same command then resumes to the uninterrupted store."""
    path, ref_store = reference
    # a Ctrl-C reaches a driver whose SIGINT is not ignored from the start (as a background job's
    # is, which it keeps ignoring): a test that set it in this process would leave it ignored
    assert signal.getsignal(signal.SIGINT) is not signal.SIG_IGN
    store = tmp_path / "s.zarr"
    args = ("run", path, "--store", store, "--scheduler", "processes", "--workers", "2", "--no-progress")
    proc = start_driver(*args, env_extra=SLOW_WRITES)
    started = []
    try:
        wait_for_chunks(store, proc)
        started = children(proc.pid)
        assert len(started) >= 3, started  # two workers and multiprocessing's resource tracker
        if how == "Ctrl-C":
            os.killpg(proc.pid, signal.SIGINT)
            _, err = proc.communicate(timeout=60)
            assert proc.returncode == 130, err
            lines = err.strip().splitlines()
            assert len(lines) == 1 and re.fullmatch(
                r"interrupted: [1-8] of 8 chunks kept; rerun the same command to resume", lines[0]), err
        else:
            os.kill(proc.pid, signal.SIGKILL)
            proc.wait(timeout=30)
        assert wait_gone(started, timeout=10.0) == [], f"still running after the driver ended: {started}"
    finally:
        if proc.poll() is None:
            os.killpg(proc.pid, signal.SIGKILL)
            proc.wait(timeout=30)
        kill_all(started)  # orphans (the defect) must not outlive the test
    resumed = cli(*args)
    assert resumed.returncode == 0, resumed.stderr
    assert_stores_equal(store, ref_store)


def test_a_worker_killed_from_outside_ends_the_run_on_one_line(reference, tmp_path):
    """A worker process killed from outside (the OOM killer; here kill -9 of one worker): on
    d799bf7 a BrokenProcessPool traceback; now exit 1 and one line counting the chunks kept,
    the other worker ended too, and the same command resumes to the uninterrupted store."""
    path, ref_store = reference
    store = tmp_path / "s.zarr"
    args = ("run", path, "--store", store, "--scheduler", "processes", "--workers", "2", "--no-progress")
    proc = start_driver(*args, env_extra=SLOW_WRITES)
    started = []
    try:
        wait_for_chunks(store, proc)
        started = children(proc.pid)
        workers = [p for p in started if "resource_tracker" not in Path(f"/proc/{p}/cmdline").read_text()]
        assert len(workers) == 2, started
        os.kill(workers[0], signal.SIGKILL)
        _, err = proc.communicate(timeout=120)
        assert proc.returncode == 1, err
        lines = err.strip().splitlines()
        assert len(lines) == 1 and re.fullmatch(r"error: small: a worker process died \(killed from outside, e\.g\. "
                                                r"out of memory\); [0-8] of 8 chunks kept; rerun the same command "
                                                r"to resume", lines[0]), err
        assert wait_gone(started, timeout=10.0) == []
    finally:
        if proc.poll() is None:
            os.killpg(proc.pid, signal.SIGKILL)
            proc.wait(timeout=30)
        kill_all(started)
    resumed = cli(*args)
    assert resumed.returncode == 0, resumed.stderr
    assert_stores_equal(store, ref_store)


_PARENT = textwrap.dedent("""
    import subprocess, sys, time
    grandchild = subprocess.Popen([sys.executable, "-c", sys.argv[1]])
    print(grandchild.pid, flush=True)
    time.sleep(600)
""")
_WATCHING = textwrap.dedent("""
    import os, sys, time
    from pipeline._schedule import watch_parent
    if sys.argv[1] == "watch":
        watch_parent(os.getppid(), death_signal=False, interval=0.2)
    print("ready", flush=True)
    time.sleep(600)
""")


@pytest.mark.parametrize("watch", [True, False])
def test_the_portable_parent_watch_alone_ends_an_orphan(watch):
    """The fallback of ``_schedule.watch_parent`` (no PR_SET_PDEATHSIG: a pool spawned outside
    the main thread, or not Linux): a process polling its parent's pid exits within a few
    seconds of its parent's SIGKILL.  Control (``watch`` False): the same process without the
    watch lives on as an orphan (the defect of issue 45 item 3)."""
    env = dict(os.environ, PYTHONPATH=str(REPO) + os.pathsep + os.environ.get("PYTHONPATH", ""))
    code = _WATCHING.replace("sys.argv[1]", repr("watch" if watch else "no"))
    parent = subprocess.Popen([sys.executable, "-c", _PARENT, code], cwd=REPO, env=env, stdout=subprocess.PIPE,
                              text=True)
    grandchild = None
    try:
        grandchild = int(parent.stdout.readline())
        assert parent.stdout.readline().strip() == "ready"  # the watch is set
        os.kill(parent.pid, signal.SIGKILL)
        parent.wait(timeout=30)
        left = wait_gone([grandchild], timeout=5.0)
        assert left == ([] if watch else [grandchild])
    finally:
        if parent.poll() is None:
            parent.kill()
        kill_all([grandchild] if grandchild else [])


# -- 4. the lock holder's record -----------------------------------------------------------------


def test_a_refused_run_leaves_the_lock_holders_record(tmp_path, capsys):
    """Issue 45 item 4: on d799bf7 a refused run truncated the lock file as it closed it, so
    every later refusal read "(pid ? on ? since ?)".  Now two refusals in a row both name the
    holder, whose record is still in the file."""
    path = write_scene(tmp_path, small_scene_text())
    store = tmp_path / "s.zarr"
    with run_lock(store) as lock:
        record = lock.read_text()
        for _ in range(2):
            assert main(["run", str(path), "--store", str(store), "--no-progress"]) == 3
            err = capsys.readouterr().err
            assert f"pid {os.getpid()} on " in err and "since ?" not in err, err
        assert lock.read_text() == record and json.loads(record)["pid"] == os.getpid()
    # the holder wrote no store: its lock file, which it created, is gone too (nothing left)
    assert not store.exists() and not lock_path(store).exists()


# -- 5. one line, nothing written: a cluster that does not answer --------------------------------


def test_an_unreachable_scheduler_is_refused_with_nothing_written(tmp_path):
    """Issue 45 item 5: on d799bf7 a ``tcp://`` address where no scheduler listens waited dask's
    30 s, printed a traceback and left an empty store and its lock file.  Now: exit 2, one
    line naming --scheduler, no store and no lock file (within ``CONNECT_SECONDS``, 5 s)."""
    import socket

    with socket.socket() as s:  # a port nothing listens on
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    path = write_scene(tmp_path, small_scene_text())
    store = tmp_path / "s.zarr"
    proc = cli("run", path, "--store", store, "--scheduler", f"tcp://127.0.0.1:{port}", "--no-progress")
    assert proc.returncode == 2, proc
    lines = proc.stderr.strip().splitlines()
    assert len(lines) == 1 and "--scheduler tcp://127.0.0.1" in lines[0], proc.stderr
    assert list(tmp_path.iterdir()) == [path]


# -- 7. a cluster's workers counted --------------------------------------------------------------


def test_the_timing_line_counts_a_clusters_workers(reference, tmp_path):
    """Issue 45 item 7: on d799bf7 a run on a dask.distributed cluster of 2 workers printed
    "x 1 workers ... efficiency 171 %".  Now the cluster's task slots (its workers' threads)
    are counted: 2, and the efficiency is at most 100 %."""
    distributed = pytest.importorskip("distributed")
    path, ref_store = reference
    store = tmp_path / "dist.zarr"
    with distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=False,
                                  dashboard_address=None) as cluster:
        summary = run_scene(load_scene(path), store, scheduler=cluster.scheduler_address, progress=False)
    assert summary.timing["workers"] == 2, summary.timing
    assert " x 2 workers" in summary.timing_line() and summary.timing["efficiency"] <= 1.0
    assert_stores_equal(store, ref_store)
