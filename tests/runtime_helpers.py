"""Helpers of the run-time tests (issue 45): processes by their parent, tasks that report when
they finish, and a driver run in a subprocess that the tests signal."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from pathlib import Path

from pipeline_cases import REPO


#: the environment of a run whose chunk writes each wait 2 s before their done marker (the
#: tests' hook in ``_store.ChunkWriter.write``, in the driver): the small scene's 8 chunks then
#: take 16 s or more, so a signal sent once the first chunk is done reaches a run still
#: computing, on a loaded machine too
SLOW_WRITES = {"TWOLINK_PIPELINE_MARKER_DELAY": "2.0"}


def finish_after(seconds: float) -> float:
    """A task: sleep ``seconds``, then return the wall clock (``time.time``) at its end."""
    time.sleep(seconds)
    return time.time()


class ProgressTimes:
    """A progress bar that records the wall clock of each update (``_schedule.compute`` calls
    ``update()`` once per finished task)."""

    def __init__(self):
        self.times: list[float] = []

    def update(self, n: int = 1):
        self.times += [time.time()] * n


def _stat(pid: int) -> tuple[str, int] | None:
    """(state, parent pid) of process ``pid`` from /proc, None where it is gone."""
    try:
        text = Path(f"/proc/{pid}/stat").read_text()
    except OSError:
        return None
    fields = text[text.rindex(")") + 2:].split()  # after "pid (comm) "
    return fields[0], int(fields[1])


def alive(pid: int) -> bool:
    """Whether ``pid`` runs (a zombie, dead but not yet reaped by its new parent, is gone)."""
    st = _stat(pid)
    return st is not None and st[0] not in ("Z", "X")


def children(pid: int) -> list[int]:
    """Live processes whose parent is ``pid``."""
    out = []
    for entry in os.listdir("/proc"):
        if entry.isdigit():
            st = _stat(int(entry))
            if st is not None and st[1] == pid and st[0] not in ("Z", "X"):
                out.append(int(entry))
    return sorted(out)


def wait_gone(pids, timeout: float) -> list[int]:
    """The pids of ``pids`` still alive after up to ``timeout`` seconds (empty once all are gone)."""
    deadline = time.monotonic() + timeout
    left = [p for p in pids if alive(p)]
    while left and time.monotonic() < deadline:
        time.sleep(0.05)
        left = [p for p in left if alive(p)]
    return left


def kill_all(pids) -> None:
    """SIGKILL every pid of ``pids`` still alive (a test's clean-up)."""
    for p in pids:
        if alive(p):
            try:
                os.kill(p, signal.SIGKILL)
            except OSError:
                pass


def start_driver(*args, env_extra=None) -> subprocess.Popen:
    """``python -m pipeline ARGS`` in a subprocess of its own session (so a test can signal the
    group as a terminal's Ctrl-C does), stdout and stderr piped."""
    env = dict(os.environ)
    env["PYTHONPATH"] = str(REPO) + os.pathsep + env.get("PYTHONPATH", "")
    env.update(env_extra or {})
    return subprocess.Popen([sys.executable, "-m", "pipeline", *map(str, args)], cwd=REPO, env=env,
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, start_new_session=True)


def wait_for_chunks(store: Path, proc: subprocess.Popen, at_least: int = 1, timeout: float = 240) -> int:
    """Wait until ``store`` has ``at_least`` chunks with their done marker while ``proc`` runs;
    the count (the run ended first: AssertionError with its output)."""
    marks = store / "pipeline_state" / "chunk_done" / "c"
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline and proc.poll() is None:
        n = sum(1 for p in marks.rglob("*") if p.is_file() and not p.name.endswith(".partial")) \
            if marks.exists() else 0
        if n >= at_least:
            assert proc.poll() is None, "the run ended before it could be signalled"
            return n
        time.sleep(0.01)
    raise AssertionError(f"the run ended (or timed out) before {at_least} chunks were done: "
                         f"{proc.poll()} {proc.communicate(timeout=30) if proc.poll() is not None else ''}")
