"""A user's mistakes with ``python -m pipeline`` (issue 45: "a run of the same 33 mistakes gives one
line and the documented exit code each"), each run through the command line in a subprocess.

Each gives exactly one line on stderr, no traceback, the exit code documented in
``pipeline/__main__.py`` (2 bad scene or argument, 3 store refused, 130 / 143 interrupted), the
words named, and, where it is refused, nothing written: every file under the test's folder as
it was before the command.  The list is kept with the report's in /work/notes/mistakes.md
(numbers there, with what d799bf7 did).  On d799bf7 (issue 45's main) 24 of the 37 failed: 9
gave a traceback (--workers with a cluster, an http:// scheduler, the unreachable scheduler
after 30 s, a store under a file or in /proc, Ctrl-C, ``estimate --probe 0``, ``paper --out``
under a file, ``paper`` with the unreachable scheduler), 3 another outcome (the xarray store
deleted and replaced, exit 0; --workers with synchronous accepted, exit 0; SIGTERM: killed,
no line, its workers left running), 6 argparse's usage on several lines, 5 a lock file left
beside a refused store (nothing written did not hold), and the locked store's second refusal
read "pid ? on ? since ?".
"""

from __future__ import annotations

import contextlib
import os
import re
import signal
import socket
import sys
from dataclasses import dataclass
from pathlib import Path
from typing import Callable

import pytest

from pipeline import load_scene
from pipeline._grid_kind import GRID
from pipeline._store import create_skeleton, run_lock
from pipeline_cases import cli, downgrade_to_format_1, small_scene_text, write_scene
from runtime_helpers import SLOW_WRITES, children, kill_all, start_driver, wait_for_chunks, wait_gone


@dataclass(frozen=True)
class Mistake:
    """One mistake: ``make(tmp, stack)`` writes what it needs under ``tmp`` (context managers on
    ``stack``, e.g. another run's lock) and returns the command's arguments; the command must
    exit with ``code`` and one line on stderr matching ``pattern`` (a regular expression), as
    often as ``repeat`` says, and, where ``untouched``, leave every file under ``tmp`` as it was.
    The line must begin with ``pattern``. ``signal``: sent while the run computes ("SIGINT" to its process group, as a terminal's
    Ctrl-C; "SIGTERM" to the driver alone)."""

    name: str
    code: int
    pattern: str
    make: Callable
    untouched: bool = True
    repeat: int = 1
    signal: str | None = None
    needs: str | None = None  # "not root", "/proc"


def _scene(tmp: Path, text: str | None = None, name: str = "small.toml") -> Path:
    return write_scene(tmp, text if text is not None else small_scene_text(), name)


def _run(tmp, *extra, store="s.zarr"):
    return ["run", _scene(tmp), "--store", tmp / store, "--no-progress", *extra]


def _closed_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def _xarray_store(tmp, stack):
    import numpy as np
    import xarray as xr

    xr.Dataset({"t": (("x",), np.arange(3.0))}).to_zarr(str(tmp / "s.zarr"), zarr_format=3, consolidated=False)
    return _run(tmp)


def _folder_of_files(tmp, stack):
    (tmp / "s.zarr").mkdir()
    (tmp / "s.zarr" / "notes.txt").write_text("keep")
    return _run(tmp, "--overwrite")


def _other_scene_store(tmp, stack):
    other = load_scene(_scene(tmp, small_scene_text(rtol=5e-4), "other.toml"))
    create_skeleton(tmp / "s.zarr", other, GRID.block_layout(other))
    return _run(tmp)


def _format_1_store(tmp, stack):
    scene = load_scene(_scene(tmp))
    create_skeleton(tmp / "s.zarr", scene, GRID.block_layout(scene))
    downgrade_to_format_1(tmp / "s.zarr")
    return _run(tmp)


def _other_layout_store(tmp, stack):
    scene = load_scene(_scene(tmp))
    create_skeleton(tmp / "s.zarr", scene, (1, 1, 4, 4))
    return _run(tmp)


def _locked_store(tmp, stack):
    stack.enter_context(run_lock(tmp / "s.zarr"))
    return _run(tmp)


def _read_only_folder(tmp, stack):
    (tmp / "ro").mkdir()
    (tmp / "ro").chmod(0o555)
    stack.callback((tmp / "ro").chmod, 0o755)
    return _run(tmp, store="ro/s.zarr")


def _signalled(tmp, stack):
    return ["run", _scene(tmp, small_scene_text(polish=True)), "--store", tmp / "s.zarr", "--scheduler", "processes",
            "--workers", "2", "--no-progress"]


def _file(tmp, name="notes.txt"):
    (tmp / name).write_text("keep")
    return tmp / name


ONE_LINE_USAGE = r"python -m pipeline( \w+)?: error: .* \(see python -m pipeline( \w+)? --help\)"
KEPT = r"{}: [0-8] of 8 chunks kept; rerun the same command to resume"
WORKERS = r"(python -m pipeline \w+: )?error: (argument )?--workers: must be >= 1"

MISTAKES = [
    Mistake("no subcommand", 2, ONE_LINE_USAGE, lambda t, s: []),
    Mistake("unknown subcommand", 2, ONE_LINE_USAGE + "", lambda t, s: ["runn", _scene(t)]),
    Mistake("unknown option", 2, ONE_LINE_USAGE, lambda t, s: ["run", _scene(t), "--output", t / "s.zarr"]),
    Mistake("two scenes to run", 2, ONE_LINE_USAGE, lambda t, s: ["run", _scene(t), _scene(t, name="b.toml")]),
    Mistake("scene file missing", 2, r"error: .*nothere\.toml.*No such file",
            lambda t, s: ["run", t / "nothere.toml"]),
    Mistake("unknown shipped scene", 2, r"error: quik: .*cannot read", lambda t, s: ["run", "quik"]),
    Mistake("scene path is a folder", 2, r"error: .*scenes.*", lambda t, s: ["run", (t / "scenes").mkdir() or t / "scenes"]),
    Mistake("scene file not TOML", 2, r"error: .*broken\.toml",
            lambda t, s: ["run", _scene(t, "[scene\nname = 1", "broken.toml")]),
    Mistake("unknown scene key", 2, r"error: .*rtoll",
            lambda t, s: ["run", _scene(t, small_scene_text().replace("rtol =", "rtoll ="))]),
    Mistake("bad scene value", 2, r"error: .*rtol",
            lambda t, s: ["run", _scene(t, small_scene_text(rtol=-1.0))]),
    Mistake("unknown scene kind", 2, r"error: .*scene\.kind",
            lambda t, s: ["run", _scene(t, small_scene_text().replace('[scene]\n', '[scene]\nkind = "optimum"\n'))]),
    Mistake("--workers 0", 2, WORKERS, lambda t, s: _run(t, "--workers", "0")),
    Mistake("--workers -2", 2, WORKERS, lambda t, s: _run(t, "--workers", "-2")),
    Mistake("--workers two", 2, ONE_LINE_USAGE, lambda t, s: _run(t, "--workers", "two")),
    Mistake("--workers with synchronous", 2, r"error: --workers: .*synchronous",
            lambda t, s: _run(t, "--workers", "2", "--scheduler", "synchronous")),
    Mistake("--workers with a cluster", 2, r"error: --workers: .*tcp://",
            lambda t, s: _run(t, "--workers", "2", "--scheduler", f"tcp://127.0.0.1:{_closed_port()}")),
    Mistake("unknown scheduler", 2, ONE_LINE_USAGE, lambda t, s: _run(t, "--scheduler", "multiprocess")),
    Mistake("unsupported scheduler address", 2, ONE_LINE_USAGE,
            lambda t, s: _run(t, "--scheduler", "http://127.0.0.1:8786")),
    Mistake("unreachable scheduler", 2, r"error: --scheduler tcp://127\.0\.0\.1:\d+: no dask scheduler answers",
            lambda t, s: _run(t, "--scheduler", f"tcp://127.0.0.1:{_closed_port()}")),
    Mistake("store written by xarray", 3, r"error: .*s\.zarr: a Zarr store the pipeline did not write.*--overwrite",
            _xarray_store),
    Mistake("store a folder of other files, --overwrite", 3, r"error: .*s\.zarr: .*not a Zarr store", _folder_of_files),
    Mistake("store a regular file", 3, r"error: .*notes\.txt: .*not a Zarr store",
            lambda t, s: _run(t, store=_file(t).name)),
    Mistake("store under a regular file", 3, r"error: .*notes\.txt/s\.zarr: cannot create .*notes\.txt is a file, not a folder",
            lambda t, s: _run(t, store=f"{_file(t).name}/s.zarr")),
    Mistake("store where nothing can be created", 3, r"error: /proc/twolink-\w+/s\.zarr: cannot create",
            lambda t, s: _run(t, store=f"/proc/twolink-{os.getpid()}/s.zarr"), needs="/proc"),
    Mistake("store in a read-only folder", 3, r"error: .*ro/s\.zarr: cannot create .*Permission denied",
            _read_only_folder, needs="not root"),
    Mistake("store of another scene", 3, r"error: .*s\.zarr: built from a different scene.*--overwrite",
            _other_scene_store),
    Mistake("store locked by another run, twice", 3, rf"error: .*s\.zarr: another run is using this store "
                                                     rf"\(pid {os.getpid()} on .+ since \d{{4}}-.*\)",
            _locked_store, repeat=2),
    Mistake("store of format 1", 3, r"error: .*s\.zarr: store format version 1.*--overwrite", _format_1_store),
    Mistake("store of another chunk layout", 3, r"error: .*s\.zarr: its blocks \(1 x 1 x 4 x 4\).*--overwrite",
            _other_layout_store),
    Mistake("Ctrl-C", 130, KEPT.format("interrupted"), _signalled, untouched=False, signal="SIGINT"),
    Mistake("SIGTERM", 143, KEPT.format(r"terminated \(SIGTERM\)"), _signalled, untouched=False, signal="SIGTERM"),
    Mistake("estimate a missing scene", 2, r"error: .*nothere\.toml", lambda t, s: ["estimate", t / "nothere.toml"]),
    Mistake("estimate --probe 0", 2, ONE_LINE_USAGE, lambda t, s: ["estimate", _scene(t), "--probe", "0"]),
    Mistake("paper --workflows not a folder", 2, r"error: --workflows: no such folder",
            lambda t, s: ["paper", "--workflows", t / "nothere", "--out", t / "out"]),
    Mistake("paper --out under a regular file", 3, r"error: --out .*notes\.txt/out: cannot write there",
            lambda t, s: ["paper", "--out", _file(t) / "out", "--no-progress"]),
    Mistake("paper with an unreachable scheduler", 2, r"error: --scheduler tcp://127\.0\.0\.1:\d+: no dask",
            lambda t, s: ["paper", "--out", t / "out", "--scheduler", f"tcp://127.0.0.1:{_closed_port()}"]),
    Mistake("paper --workers 0", 2, WORKERS, lambda t, s: ["paper", "--out", t / "out", "--workers", "0"]),
]


def _snapshot(tmp: Path) -> dict[str, bytes | None]:
    return {str(p.relative_to(tmp)): (p.read_bytes() if p.is_file() else None) for p in sorted(tmp.rglob("*"))}


def _signal_run(argv, sig: str, tmp: Path):
    """The run started, signalled once it has chunks done; (exit code, stderr), after checking
    that every process it started is gone."""
    proc = start_driver(*argv, env_extra=SLOW_WRITES)
    started = []
    try:
        wait_for_chunks(tmp / "s.zarr", proc)
        started = children(proc.pid)
        if sig == "SIGINT":
            os.killpg(proc.pid, signal.SIGINT)
        else:
            os.kill(proc.pid, signal.SIGTERM)
        _, err = proc.communicate(timeout=60)
        assert wait_gone(started, timeout=10.0) == [], "worker processes outlived their driver"
        return proc.returncode, err
    finally:
        if proc.poll() is None:
            os.killpg(proc.pid, signal.SIGKILL)
            proc.wait(timeout=30)
        kill_all(started)


@pytest.mark.parametrize("mistake", MISTAKES, ids=[m.name for m in MISTAKES])
def test_a_mistake_gives_one_line_and_its_exit_code(mistake, tmp_path):
    if mistake.needs == "not root" and os.geteuid() == 0:
        pytest.skip("root writes into a read-only folder (its other OSErrors: the /proc and file cases)")
    if mistake.needs == "/proc" and not sys.platform.startswith("linux"):
        pytest.skip("no /proc")
    with contextlib.ExitStack() as stack:
        argv = mistake.make(tmp_path, stack)
        before = _snapshot(tmp_path)
        for _ in range(mistake.repeat):
            if mistake.signal:
                code, err = _signal_run(argv, mistake.signal, tmp_path)
            else:
                proc = cli(*argv, timeout=300)
                code, err = proc.returncode, proc.stderr
            lines = err.strip().splitlines()
            assert "Traceback" not in err, err
            assert code == mistake.code, (code, err)
            assert len(lines) == 1, err
            assert re.match(mistake.pattern, lines[0]), lines[0]
        if mistake.untouched:
            assert _snapshot(tmp_path) == before  # nothing written, nothing removed


def test_the_list_has_the_issues_thirty_three():
    """The issue tried 33 mistakes; this list has at least as many, each named once."""
    assert len(MISTAKES) >= 33 and len({m.name for m in MISTAKES}) == len(MISTAKES)
