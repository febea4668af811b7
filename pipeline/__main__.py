"""Command line: ``python -m pipeline run SCENE.toml``, ``estimate SCENE.toml...`` and ``paper``.

Exit codes (every error is one line on stderr): 0 done; 1 the run failed part-way (an I/O
error such as a full disk, a worker process killed from outside; the chunks done are kept,
the same command resumes); 2 bad scene
file or arguments, or a dask scheduler that does not answer (nothing written); 3 store refused
(a different scene or a Zarr store the pipeline did not write is there: ``--overwrite``
replaces it; it is not a Zarr store; it cannot be written there; another run holds it;
nothing written); 130 interrupted by Ctrl-C, 143 by SIGTERM (the chunks done are kept, the
same command resumes).
"""

from __future__ import annotations

import argparse
import os
import re
import signal
import sys
import threading
import time
from concurrent.futures.process import BrokenProcessPool
from contextlib import contextmanager
from pathlib import Path

import workflows as _workflows
from solver._version import VersionAction

from ._grid_scene import Scene
from ._registry import kind_of, load_scene, parse_scene
from ._run import kept_chunks, resumable_record, run_scene, warm_up_kernels
from ._store import read_provenance_once
from ._scene import SceneError, read_scene_file
from ._schedule import DISTRIBUTED_PREFIXES, LOCAL_SCHEDULERS, SchedulerUnavailable, Session
from ._store import StoreBusy, StoreMismatch, unwritable_reason

EXIT_FAILED = 1
EXIT_BAD_SCENE = 2
EXIT_REFUSED = 3
EXIT_INTERRUPTED = 130  # 128 + SIGINT, as a shell reports a process ended by Ctrl-C
EXIT_TERMINATED = 143  # 128 + SIGTERM

#: Shipped scenes in the order ``paper`` runs them (fourier_optima_edge exists for a cause
#: check of the reproduction audit, reports/claims.toml; opt_all_params_panel for the stated
#: parameters of figure OptAllParamsMotions, issue 44).
PAPER_SCENES = ("quick", "harmonic_grid", "harmonic_diagonals", "harmonic_optimum", "duty_cycle",
                "linear_two_phase", "exponent_sets", "power_law", "opt_all_params_panel", "fourier_optima", "force_laws",
                "fourier_optima_edge", "accuracy", "stiffness")
#: The shipped scene files: package data of :mod:`workflows`, found wherever it is installed.
WORKFLOWS = _workflows.DIRECTORY


class Terminated(BaseException):
    """SIGTERM, raised in the driver like Ctrl-C's KeyboardInterrupt (not an error: the
    workers are ended at once, ``Scheduler.close(kill=True)``)."""


class _Parser(argparse.ArgumentParser):
    """argparse, its errors on one line (the usage is ``--help``'s), exit code 2."""

    def error(self, message):
        self.exit(EXIT_BAD_SCENE, f"{self.prog}: error: {message} (see {self.prog} --help)\n")


def _scheduler(value: str) -> str:
    if value in LOCAL_SCHEDULERS or value.startswith(DISTRIBUTED_PREFIXES):
        return value
    raise argparse.ArgumentTypeError(f"must be processes, threads, synchronous or the address of a dask "
                                     f"scheduler ({', '.join(p + 'host:port' for p in DISTRIBUTED_PREFIXES)}), "
                                     f"got {value!r}")


def _count(value: str) -> int:
    try:
        n = int(value)
    except ValueError:
        raise argparse.ArgumentTypeError(f"must be a whole number >= 1, got {value!r}") from None
    if n < 1:
        raise argparse.ArgumentTypeError(f"must be >= 1, got {n}")
    return n


def _seconds(value: str) -> float:
    try:
        x = float(value)
    except ValueError:
        raise argparse.ArgumentTypeError(f"must be a number of seconds, got {value!r}") from None
    if not x >= 0:
        raise argparse.ArgumentTypeError(f"must be >= 0, got {value}")
    return x


def _parser() -> argparse.ArgumentParser:
    ap = _Parser(prog="python -m pipeline", description=__doc__.splitlines()[0])
    ap.add_argument("--version", action=VersionAction)
    sub = ap.add_subparsers(dest="command", required=True)
    run = sub.add_parser("run", help="compute one scene into its Zarr store (resumes an interrupted run)")
    run.add_argument("scene", help="scene TOML file (e.g. my_scene.toml) or a shipped scene's name (e.g. quick)")
    est = sub.add_parser("estimate", help="time a probe of each scene (grid, optima, study; polishing "
                                          "included) and print its projected run time")
    est.add_argument("scenes", nargs="+", help="scene TOML files or shipped scenes' names")
    est.add_argument("--workers", type=_count, default=None, help="parallel workers assumed (default: all cores)")
    est.add_argument("--probe", type=_count, default=8,
                     help="chunks of each scene solved and timed at most (default 8; at least one of each "
                          "cost class, e.g. each Kmax of an optima scene)")
    est.add_argument("--probe-seconds", type=_seconds, default=10.0,
                     help="no further chunk of a scene is probed once its probe took this many CPU seconds "
                          "(default 10)")
    paper = sub.add_parser("paper", help="run every shipped scene, print the total time, build the report")
    paper.add_argument("--quick", action="store_true",
                       help="every figure's scene at reduced resolution (num / 4, step x 2), without the two "
                            "studies (accuracy, stiffness); stores under OUT/quick/")
    paper.add_argument("--out", default="out", help="directory of the stores (default out/)")
    paper.add_argument("--workflows", type=Path, default=None, metavar="DIR",
                       help="folder of the scene files <name>.toml (default: the shipped scenes, installed "
                            "with the package)")
    for p in (run, paper):
        if p is run:
            p.add_argument("--store", help="Zarr store (default out/<scene>.zarr)")
        p.add_argument("--scheduler", type=_scheduler, default=None,
                       help="processes (default), threads, synchronous, or tcp://host:port of a dask cluster")
        p.add_argument("--workers", type=_count, default=None,
                       help="local worker count, for processes and threads (default: all cores)")
        p.add_argument("--overwrite", action="store_true", help="replace a store that would be refused (another scene, engine or chunk layout); a store of this scene resumes")
        p.add_argument("--no-progress", action="store_true", help="no progress bar")
    return ap


#: ``paper --quick`` leaves the studies out: they time solvers for minutes and show no figure of
#: the paper (``python -m pipeline run workflows/accuracy.toml`` runs one alone).
QUICK_SCENES = tuple(name for name in PAPER_SCENES if name not in ("accuracy", "stiffness"))
_AXIS_NUM = re.compile(r"(\{[^{}\n]*\bnum\s*=\s*)(\d+)")  # num of an inline axis table
_LINE_NUM = re.compile(r"^(\s*num\s*=\s*)(\d+)", re.MULTILINE)  # a table's num (optima: starts)
_STEP = re.compile(r"\bstep\s*=\s*([0-9.]+)")


def quick_variant(path) -> "Scene":
    """The scene at ``path`` at reduced resolution, for ``paper --quick``: an axis given by
    ``num`` points keeps a quarter of them, at least 3 (so a maximum can lie inside), a ``num``
    on its own line (an optima scene's starts) a quarter, at least 4, and every ``step`` doubles.
    The reduced scene hashes differently, so its stores live apart from the full ones."""
    text = read_scene_file(path)
    text = _AXIS_NUM.sub(lambda m: f"{m.group(1)}{max(3, int(m.group(2)) // 4)}", text)
    text = _LINE_NUM.sub(lambda m: f"{m.group(1)}{max(4, int(m.group(2)) // 4)}", text)
    text = _STEP.sub(lambda m: f"step = {2 * float(m.group(1))!r}", text)
    scene = parse_scene(text, f"{path} (quick variant)")
    # a scene kind may reduce further (optima: its [quick] table)
    return scene.quick_variant() if hasattr(scene, "quick_variant") else scene


def _error(message) -> None:
    print(f"error: {' '.join(str(message).split())}", file=sys.stderr, flush=True)


def _run_one(scene, store, args, session=None) -> int:
    """One scene's run; every refusal or failure one line on stderr and its exit code."""
    try:
        summary = run_scene(scene, store, scheduler=args.scheduler, workers=args.workers,
                            overwrite=args.overwrite, progress=not args.no_progress, session=session)
    except (StoreMismatch, StoreBusy) as exc:
        _error(exc)
        return EXIT_REFUSED
    except SchedulerUnavailable as exc:
        _error(exc)
        return EXIT_BAD_SCENE
    except (KeyboardInterrupt, Terminated) as exc:
        _quiet_after_interrupt()
        # a progress bar's line is left open on a terminal: the message starts on a line of its own
        end = "\n" if sys.stderr.isatty() and not args.no_progress else ""
        what = "interrupted" if isinstance(exc, KeyboardInterrupt) else "terminated (SIGTERM)"
        print(f"{end}{kept_chunks(scene, store).line(what)}", file=sys.stderr, flush=True)
        return EXIT_INTERRUPTED if isinstance(exc, KeyboardInterrupt) else EXIT_TERMINATED
    except OSError as exc:  # a full disk, a store removed under the run: what is done is kept
        where = f"{exc.filename}: " if exc.filename else ""
        _error(f"{where}{exc.strerror or exc}; {kept_chunks(scene, store).summary()}")
        return EXIT_FAILED
    except BrokenProcessPool:  # a worker killed from outside (the OOM killer, kill -9)
        _error(f"{scene.name}: a worker process died (killed from outside, e.g. out of memory); "
               f"{kept_chunks(scene, store).summary()}")
        return EXIT_FAILED
    if summary.timing:
        print(summary.timing_line(), flush=True)  # where the time went; the summary line last
    print(summary.line(), flush=True)
    return 0


def _estimate(args) -> int:
    from ._estimate import estimate_scene
    from ._schedule import usable_cores

    workers = args.workers or usable_cores()
    scenes = []
    for path in args.scenes:
        try:
            scenes.append(load_scene(_workflows.scene_path(path)))
        except SceneError as exc:
            _error(exc)
            return EXIT_BAD_SCENE
    cores = min(workers, usable_cores())
    total, probe = 0.0, 0.0
    for scene in scenes:
        est = estimate_scene(scene, max_chunks=args.probe, budget_seconds=args.probe_seconds)
        wall = est.wall_seconds(cores)
        total += wall
        probe += est.probe_seconds
        chunks = est.parts[0]
        print(f"{scene.name:20s} {est.points:>9d} {est.point_unit:13s} ~{wall / 60:7.1f} min on {workers} workers"
              f"  ({scene.kind}: {chunks.probed} of {chunks.count} chunks timed, {chunks.probe_seconds:.1f} CPU-s, "
              f"{chunks.points / max(chunks.core_seconds, 1e-9):,.1f} {est.point_unit}/s per core)", flush=True)
        for part in est.parts[1:]:
            line = (f"{part.probed} of {part.count} {part.unit} timed, {part.probe_seconds:.1f} CPU-s, "
                    f"~{max(part.core_seconds / cores, part.longest_seconds) / 60:.1f} min" if part.probed
                    else f"{part.count} {part.unit}, none probed (no valid point in the probed chunks)")
            print(f"{'':20s}   + {part.name}: {line}", flush=True)
    print(f"{'total':20s} {sum(s.n_points for s in scenes):>9d} {'':13s} ~{total / 60:7.1f} min on {workers} workers "
          f"(projected from a timed probe of each scene: its chunks and polished cells solved here on one core, "
          f"{probe:.0f} CPU-s; solving on free cores only: start-up, writes and scheduling add a few per cent, "
          "a loaded machine more)", flush=True)
    return 0


def _quiet_after_interrupt() -> None:
    """After Ctrl-C or SIGTERM the one line says it all: a zarr write the interrupt left
    pending in its event loop is expected debris, not news ("Task was destroyed but it is
    pending!" from asyncio's logger as the interpreter exits, or "coroutine ... was never
    awaited" where the interrupt fell between a zarr call making its coroutine and running it)."""
    import logging
    import warnings

    logging.getLogger("asyncio").setLevel(logging.CRITICAL)
    warnings.filterwarnings("ignore", message=r"coroutine .* was never awaited", category=RuntimeWarning)


@contextmanager
def _sigterm_raises():
    """SIGTERM raises :class:`Terminated` in this (main) thread for the block, so that a run
    ends like after Ctrl-C: its workers ended, the chunks kept counted on one line."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return

    def handler(signum, frame):
        raise Terminated()

    previous = signal.signal(signal.SIGTERM, handler)
    try:
        yield
    finally:
        signal.signal(signal.SIGTERM, previous)


def _writable_folder(out: Path) -> bool:
    """Whether the stores can be written under ``out`` (created if absent): a file made and
    removed there; else one line, False, and nothing left (a folder created here removed)."""
    import tempfile

    made = [p for p in (out, *out.parents) if not os.path.lexists(p)]
    try:
        out.mkdir(parents=True, exist_ok=True)
        with tempfile.TemporaryFile(dir=out):
            pass
        return True
    except OSError as exc:
        for folder in made:  # deepest first
            try:
                folder.rmdir()
            except OSError:
                pass
        _error(f"--out {out}: cannot write there: {unwritable_reason(out / 'x', exc)}; choose another --out")
        return False


def _check_workers(args, scheduler: str) -> bool:
    """``--workers`` is a local pool's size: refused (one line) with another scheduler."""
    if args.workers is not None and scheduler not in ("processes", "threads"):
        _error(f"--workers: sets the size of a local pool (processes, threads), not of --scheduler {scheduler} "
               f"({'the cluster has its own workers' if scheduler.startswith(DISTRIBUTED_PREFIXES) else 'one task at a time'}); "
               "leave it out")
        return False
    return True


def main(argv=None) -> int:
    args = _parser().parse_args(argv)
    with _sigterm_raises():
        try:
            return _main(args)
        except (KeyboardInterrupt, Terminated) as exc:  # outside a run (estimate, the paper's set-up)
            _quiet_after_interrupt()
            interrupted = isinstance(exc, KeyboardInterrupt)
            print(f"{'interrupted' if interrupted else 'terminated (SIGTERM)'}: {args.command} stopped; rerun the "
                  "same command to resume", file=sys.stderr, flush=True)
            return EXIT_INTERRUPTED if interrupted else EXIT_TERMINATED


def _main(args) -> int:
    if args.command == "run":
        try:
            scene = load_scene(_workflows.scene_path(args.scene))
        except SceneError as exc:
            _error(exc)
            return EXIT_BAD_SCENE
        if not _check_workers(args, args.scheduler or scene.execution.scheduler):
            return EXIT_BAD_SCENE
        return _run_one(scene, args.store, args)
    if args.command == "estimate":
        return _estimate(args)
    names = QUICK_SCENES if args.quick else PAPER_SCENES
    out = Path(args.out) / "quick" if args.quick else Path(args.out)
    folder = args.workflows or WORKFLOWS
    if not folder.is_dir():
        _error(f"--workflows: no such folder: {folder}")
        return EXIT_BAD_SCENE
    if not _check_workers(args, args.scheduler or "processes"):
        return EXIT_BAD_SCENE
    # Validate every scene before running any, so a bad file costs nothing.
    scenes = []
    for name in names:
        try:
            scenes.append((quick_variant if args.quick else load_scene)(folder / f"{name}.toml"))
        except SceneError as exc:
            _error(exc)
            return EXIT_BAD_SCENE
    # ... and every store, so that a refused one stops the paper before its first scene runs
    stores = [out / f"{name}.zarr" for name in names]
    for scene, store in zip(scenes, stores):
        try:
            resumable_record(scene, store, args.overwrite)
        except StoreMismatch as exc:
            _error(exc)
            return EXIT_REFUSED
    t0 = time.perf_counter()
    kernel_sets = tuple(dict.fromkeys(k for scene in scenes for k in kind_of(scene).kernel_sets(scene)))
    # One pool of workers for every scene: each worker imports the solver and loads its kernels once.
    with Session(args.scheduler or "processes", args.workers, kernel_sets) as session:
        try:
            session.connect()  # a cluster that does not answer: refused before anything is written
        except SchedulerUnavailable as exc:
            _error(exc)
            return EXIT_BAD_SCENE
        if not _writable_folder(out):
            return EXIT_REFUSED
        # Compile the solver's kernels once, here, for every scene; the workers load them from the cache.
        warm_up_kernels(kernel_sets)
        # the workers start (imports, kernels) once, before the first scene: a cost of the run,
        # not of whichever scene comes first; so do this process's provenance reads (library
        # versions, git commit: ~65 ms once per process), made while the workers start
        session.start()
        read_provenance_once()
        started = session.wait_ready()
        if started["workers"]:
            print(f"paper: {started['workers']} worker processes started in {started['wall_seconds']:.1f} s "
                  f"(imports and the solver's kernels: {started['worker_seconds']:.1f} worker-s), once for "
                  "every scene", flush=True)
        for name, scene, store in zip(names, scenes, stores):
            rc = _run_one(scene, store, args, session)
            if rc in (EXIT_INTERRUPTED, EXIT_TERMINATED):
                session.close(kill=True)  # its workers ended now, not after their running tasks
            if rc:
                return rc
    print(f"paper: {len(names)} scenes, total wall {time.perf_counter() - t0:.1f} s", flush=True)
    from reports import build_report  # the report reads every store under --out

    try:
        index = build_report(sorted(out.glob("*.zarr")), out / "report")
    except OSError as exc:
        _error(f"{exc.filename or out / 'report'}: cannot write the report: {exc.strerror or exc}")
        return EXIT_REFUSED
    print(f"paper: report at {index}", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
