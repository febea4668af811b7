"""Command line: ``python -m pipeline run SCENE.toml``, ``estimate SCENE.toml...`` and ``paper``.

Exit codes: 0 done; 2 bad scene file or arguments (nothing written); 3 store refused (a
different scene is stored there, it is not a Zarr store, or another run holds it).
"""

from __future__ import annotations

import argparse
import re
import sys
import time
from pathlib import Path

import workflows as _workflows
from solver._version import VersionAction

from ._grid_scene import Scene
from ._registry import kind_of, load_scene, parse_scene
from ._run import run_scene, warm_up_kernels
from ._store import read_provenance_once
from ._scene import SceneError, read_scene_file
from ._schedule import Session
from ._store import StoreBusy, StoreMismatch

EXIT_BAD_SCENE = 2
EXIT_REFUSED = 3

#: Shipped scenes in the order ``paper`` runs them (the four before the studies exist for
#: cause checks of the reproduction audit, reports/claims.toml).
PAPER_SCENES = ("quick", "harmonic_grid", "harmonic_diagonals", "harmonic_optimum", "duty_cycle",
                "linear_two_phase", "exponent_sets", "power_law", "fourier_optima", "force_laws",
                "linear_two_phase_box", "fourier_optima_edge", "exponent_sets_coarse", "exponent_sets_fine", "accuracy",
                "stiffness")
#: The shipped scene files: package data of :mod:`workflows`, found wherever it is installed.
WORKFLOWS = _workflows.DIRECTORY


def _scheduler(value: str) -> str:
    if value in ("processes", "threads", "synchronous") or "://" in value:
        return value
    raise argparse.ArgumentTypeError(f"must be processes, threads, synchronous or tcp://host:port, got {value!r}")


def _parser() -> argparse.ArgumentParser:
    ap = argparse.ArgumentParser(prog="python -m pipeline", description=__doc__.splitlines()[0])
    ap.add_argument("--version", action=VersionAction)
    sub = ap.add_subparsers(dest="command", required=True)
    run = sub.add_parser("run", help="compute one scene into its Zarr store (resumes an interrupted run)")
    run.add_argument("scene", help="scene TOML file (e.g. my_scene.toml) or a shipped scene's name (e.g. quick)")
    est = sub.add_parser("estimate", help="time a probe of each scene and print its projected run time")
    est.add_argument("scenes", nargs="+", help="scene TOML files or shipped scenes' names")
    est.add_argument("--workers", type=int, default=None, help="parallel workers assumed (default: all cores)")
    est.add_argument("--probe", type=int, default=32, help="points solved per scene (default 32)")
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
        p.add_argument("--workers", type=int, default=None, help="local worker count (default: all cores)")
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


def _run_one(scene, store, args, session=None) -> int:
    try:
        summary = run_scene(scene, store, scheduler=args.scheduler, workers=args.workers,
                            overwrite=args.overwrite, progress=not args.no_progress, session=session)
    except (StoreMismatch, StoreBusy) as exc:
        print(f"error: {exc}", file=sys.stderr)
        return EXIT_REFUSED
    if summary.timing:
        print(summary.timing_line(), flush=True)  # where the time went; the summary line last
    print(summary.line(), flush=True)
    return 0


def _estimate(args) -> int:
    import os

    from ._grid import calibrate_points_per_task

    workers = args.workers or os.cpu_count() or 1
    scenes = []
    for path in args.scenes:
        try:
            scenes.append(load_scene(_workflows.scene_path(path)))
        except SceneError as exc:
            print(f"error: {exc}", file=sys.stderr)
            return EXIT_BAD_SCENE
    total = 0.0
    for scene in scenes:
        if getattr(scene, "kind", "grid") != "grid":
            print(f"{scene.name:20s} {scene.n_points:>9d} {scene.kind} runs (no grid probe; see the scene file)", flush=True)
            continue
        _, rate = calibrate_points_per_task(scene, workers, n_probe=args.probe)
        seconds = scene.n_points / (rate * workers)
        total += seconds
        print(f"{scene.name:20s} {scene.n_points:>9d} points  {rate:>9,.0f} solves/s per worker  "
              f"~{seconds / 60:7.1f} min on {workers} workers (grid only, polishing not included)", flush=True)
    print(f"{'total':20s} {sum(s.n_points for s in scenes):>9d} points  ~{total / 60:.1f} min", flush=True)
    return 0


def main(argv=None) -> int:
    args = _parser().parse_args(argv)
    if args.workers is not None and args.workers < 1:
        print("error: --workers: must be >= 1", file=sys.stderr)
        return EXIT_BAD_SCENE
    if args.command == "run":
        try:
            scene = load_scene(_workflows.scene_path(args.scene))
        except SceneError as exc:
            print(f"error: {exc}", file=sys.stderr)
            return EXIT_BAD_SCENE
        return _run_one(scene, args.store, args)
    if args.command == "estimate":
        return _estimate(args)
    names = QUICK_SCENES if args.quick else PAPER_SCENES
    out = Path(args.out) / "quick" if args.quick else Path(args.out)
    folder = args.workflows or WORKFLOWS
    if not folder.is_dir():
        print(f"error: --workflows: no such folder: {folder}", file=sys.stderr)
        return EXIT_BAD_SCENE
    # Validate every scene before running any, so a bad file costs nothing.
    scenes = []
    for name in names:
        try:
            scenes.append((quick_variant if args.quick else load_scene)(folder / f"{name}.toml"))
        except SceneError as exc:
            print(f"error: {exc}", file=sys.stderr)
            return EXIT_BAD_SCENE
    t0 = time.perf_counter()
    # Compile the solver's kernels once, here, for every scene; the workers load them from the cache.
    kernel_sets = tuple(dict.fromkeys(k for scene in scenes for k in kind_of(scene).kernel_sets(scene)))
    warm_up_kernels(kernel_sets)
    # One pool of workers for every scene: each worker imports the solver and loads its kernels once.
    with Session(args.scheduler or "processes", args.workers, kernel_sets) as session:
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
        for name, scene in zip(names, scenes):
            rc = _run_one(scene, out / f"{name}.zarr", args, session)
            if rc:
                return rc
    print(f"paper: {len(names)} scenes, total wall {time.perf_counter() - t0:.1f} s", flush=True)
    from reports import build_report  # the report reads every store under --out

    index = build_report(sorted(out.glob("*.zarr")), out / "report")
    print(f"paper: report at {index}", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
