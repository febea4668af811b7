"""Strong scaling of the pipeline against the engine alone, measured in one run.

``python -m pipeline.bench_scale [SCENE.toml] [--workers 1,2,4] [--engine cold,swept] [--repeats 1]``

What is measured, in one sitting, for each worker count w (default 1, 2, 4, ... up to every
core, and every core):

1. The pipeline: the whole command ``python -m pipeline run SCENE --workers w`` into a fresh
   throwaway store (a temporary directory, removed after), as a user runs it: solves/s =
   points / wall, with the run record's ``timing`` (solving summed over the workers, parallel
   efficiency = solving / (wall x w), the largest parts not solving).
2. The engine alone on the same points in this process, numba on w threads: ``cold``, one
   ``solver.solve_periodic`` call over every point of the grid (what issue 34 measured as the
   engine's speed), and ``swept``, one call over the same points cut into the pipeline's chunk
   sweeps (``_grid.chunk_sweeps``: the same work the pipeline's tasks do).  Kernels are loaded
   before the first timing (``solver.warm_up``).

Per worker count it prints solves/s, the speed-up over one worker, the scaling efficiency
(speed-up / w) and the pipeline's throughput as a fraction of the engine's.  Then a projection
(Amdahl, ``projection``): from the run at the most workers, the part that does not shrink
with the workers (S) and the part that does (P), the wall time on n workers is projected as
S + P / n for n = 16 (``--project``), once from wall times (idle machine) and once from CPU
times (a shared machine); a projection, not a measurement (the per-worker start-up and the
file system of a bigger machine differ).

The last line is one JSON object: ``scene``, ``points``, ``cores``, ``rows`` (one per worker
count: ``workers``, ``wall_seconds``, ``solves_per_s``, ``speedup``, ``scaling_efficiency``,
``parallel_efficiency``, ``cpu_seconds`` (the command's, driver and workers),
``engine_<mode>_solves_per_s``, ``engine_<mode>_cpu_seconds``, ``ratio_to_engine_<mode>``) and
``projection``.  On a shared machine compare the CPU seconds: wall times there measure the load.
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

import workflows

from ._schedule import usable_cores

__all__ = ["main"]

DEFAULT_SCENE = workflows.scene_file("harmonic_grid")


def _worker_counts(cores: int) -> list[int]:
    counts, w = [], 1
    while w < cores:
        counts.append(w)
        w *= 2
    return counts + [cores]


def engine_points(scene, mode: str) -> tuple[dict, np.ndarray | None]:
    """Every point of the grid scene's parameters and the ``sweeps`` offsets of ``mode``:
    None for ``cold``; the pipeline's chunk sweeps, chunk after chunk, for ``swept``."""
    from ._grid import chunk_region, chunk_sweeps, iter_chunks, region_parameters, scene_chunks

    params = region_parameters(scene, tuple(slice(0, n) for n in scene.shape))
    if mode == "cold":
        return params, None
    chunks = scene_chunks(scene)
    flat_index = np.arange(scene.n_points).reshape(scene.shape)
    order, offsets = [], [0]
    for index in iter_chunks(scene.shape, chunks):
        region = chunk_region(index, scene.shape, chunks)
        flat = flat_index[region].ravel()
        o, runs = chunk_sweeps(tuple(s.stop - s.start for s in region))
        order.append(flat[o])
        offsets.extend(offsets[-1] + runs[1:])
    perm = np.concatenate(order)
    return {k: v[perm] for k, v in params.items()}, np.asarray(offsets)


def time_engine(scene, mode: str, threads: int, repeats: int) -> tuple[float, float]:
    """Best wall seconds of ``repeats`` engine calls on every point (``engine_points``), and the
    CPU seconds of that call (this process, all its threads)."""
    import numba

    from ._grid import solve_points

    params, sweeps = engine_points(scene, mode)
    numba.set_num_threads(min(threads, numba.config.NUMBA_NUM_THREADS))
    best = (np.inf, np.inf)
    for _ in range(repeats):
        t0, c0 = time.perf_counter(), time.process_time()
        solve_points(scene.family, params, scene.outputs, method=scene.method, rtol=scene.rtol, sweeps=sweeps)
        best = min(best, (time.perf_counter() - t0, time.process_time() - c0))
    return best


def time_pipeline(scene_path: str, workers: int, directory: Path) -> tuple[float, float, dict]:
    """Wall seconds of the whole ``python -m pipeline run`` on ``workers`` workers into a fresh
    store, its CPU seconds (driver and workers), and the store's run record."""
    import resource

    from ._store import store_meta

    store = directory / f"w{workers}.zarr"
    r0 = resource.getrusage(resource.RUSAGE_CHILDREN)
    t0 = time.perf_counter()
    proc = subprocess.run([sys.executable, "-m", "pipeline", "run", str(scene_path), "--store", str(store),
                           "--workers", str(workers), "--no-progress"], capture_output=True, text=True)
    wall = time.perf_counter() - t0
    r1 = resource.getrusage(resource.RUSAGE_CHILDREN)
    cpu = r1.ru_utime + r1.ru_stime - r0.ru_utime - r0.ru_stime
    if proc.returncode != 0:
        raise RuntimeError(f"pipeline run --workers {workers} failed: {proc.stderr.strip()[-2000:]}")
    return wall, cpu, store_meta(store).get("run", {})


def projection(row: dict, run: dict, n: int) -> dict:
    """Amdahl from one measured run on w workers, two ways.

    From wall times (an idle machine): P = the tasks' seconds summed (solving, and in the
    tasks besides), S = wall - P / w; T(n) = S + P / n.
    From CPU times (what a shared machine still measures): P = the tasks' CPU seconds, S = the
    command's other CPU seconds (the driver's, every phase taken as serial, and one worker's
    start-up: each worker starts in parallel with the others); T(n) = S + P / n.
    """
    timing = run.get("timing") or {}
    w = row["workers"]
    parallel = float(timing.get("solve_worker_seconds", 0.0))
    parallel += sum(v for k, v in timing.get("not_solving_worker_seconds", {}).items()
                    if k in ("in tasks, besides solving",))
    serial = max(0.0, row["wall_seconds"] - parallel / w)
    tasks_cpu = float(timing.get("tasks_cpu_seconds", 0.0))
    start_cpu = float(timing.get("worker_start_cpu_seconds", 0.0))
    other_cpu = max(0.0, row["cpu_seconds"] - tasks_cpu - start_cpu)  # driver, and workers' spawn imports
    serial_cpu = other_cpu + start_cpu / w
    return {"from_workers": w, "workers": n,
            "wall": {"serial_seconds": round(serial, 3), "parallel_worker_seconds": round(parallel, 3),
                     "serial_fraction": round(serial / (serial + parallel), 4) if serial + parallel > 0 else 0.0,
                     "projected_wall_seconds": round(serial + parallel / n, 3)},
            "cpu": {"serial_seconds": round(serial_cpu, 3), "parallel_seconds": round(tasks_cpu, 3),
                    "serial_fraction": round(serial_cpu / (serial_cpu + tasks_cpu), 4) if tasks_cpu > 0 else 0.0,
                    "projected_wall_seconds": round(serial_cpu + tasks_cpu / n, 3),
                    "projected_speedup_1_to_n": round((serial_cpu + tasks_cpu) / (serial_cpu + tasks_cpu / n), 2)}}


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(prog="python -m pipeline.bench_scale", description=__doc__.splitlines()[0])
    ap.add_argument("scene", nargs="?", default=str(DEFAULT_SCENE),
                    help="grid scene: a .toml file or a shipped scene's name (default harmonic_grid)")
    ap.add_argument("--workers", default=None, help="comma-separated worker counts (default 1, 2, 4, ... cores)")
    ap.add_argument("--engine", default="cold,swept", help="engine-alone modes: cold, swept (default both)")
    ap.add_argument("--repeats", type=int, default=1, help="engine calls per mode and count, the best kept")
    ap.add_argument("--project", type=int, default=16, help="worker count of the Amdahl projection (default 16)")
    args = ap.parse_args(argv)

    from ._registry import load_scene
    from ._scene import SceneError

    args.scene = workflows.scene_path(args.scene)
    try:
        scene = load_scene(args.scene)
    except SceneError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    if getattr(scene, "kind", "grid") != "grid":
        print(f"error: scene: {args.scene} is of kind {scene.kind!r}; bench_scale times grid scenes",
              file=sys.stderr)
        return 2
    cores = usable_cores()
    try:
        counts = ([int(w) for w in args.workers.split(",")] if args.workers else _worker_counts(cores))
        if not counts or min(counts) < 1:
            raise ValueError
    except ValueError:
        print(f"error: --workers: must be comma-separated integers >= 1, got {args.workers!r}", file=sys.stderr)
        return 2
    modes = [m.strip() for m in args.engine.split(",") if m.strip()]
    if any(m not in ("cold", "swept") for m in modes):
        print(f"error: --engine: must name cold and/or swept, got {args.engine!r}", file=sys.stderr)
        return 2
    import solver

    solver.warm_up((scene.method,))
    n = scene.n_points
    print(f"bench_scale: {scene.name}, {n} points, {cores} cores; pipeline = the whole `pipeline run` command "
          f"into a fresh store; engine = solve_periodic on the same points in this process", flush=True)
    rows, runs = [], []
    with tempfile.TemporaryDirectory(prefix="bench_scale-") as tmp:
        for w in counts:
            row = {"workers": w}
            for mode in modes:
                seconds, cpu = time_engine(scene, mode, w, args.repeats)
                row[f"engine_{mode}_solves_per_s"] = round(n / seconds, 1)
                row[f"engine_{mode}_cpu_seconds"] = round(cpu, 2)
            wall, cpu, run = time_pipeline(args.scene, w, Path(tmp))
            row["cpu_seconds"] = round(cpu, 2)
            row["tasks_cpu_seconds"] = (run.get("timing") or {}).get("tasks_cpu_seconds")
            timing = run.get("timing") or {}
            row.update(wall_seconds=round(wall, 3), solves_per_s=round(n / wall, 1),
                       parallel_efficiency=timing.get("efficiency"))
            for mode in modes:
                row[f"ratio_to_engine_{mode}"] = round(row["solves_per_s"] / row[f"engine_{mode}_solves_per_s"], 3)
            rows.append(row)
            runs.append(run)
    base = next((r for r in rows if r["workers"] == 1), rows[0])
    for row in rows:
        row["speedup"] = round(row["solves_per_s"] / base["solves_per_s"] * base["workers"], 3)
        row["scaling_efficiency"] = round(row["speedup"] / row["workers"], 3)
        engine = "  ".join(f"engine {m} {row[f'engine_{m}_solves_per_s']:>8,.0f}/s, cpu "
                           f"{row[f'engine_{m}_cpu_seconds']:.1f} s (pipeline {100 * row[f'ratio_to_engine_{m}']:.0f} %)"
                           for m in modes)
        eff = row["parallel_efficiency"]
        print(f"workers {row['workers']:>3d}: pipeline {row['solves_per_s']:>8,.0f} solves/s, wall "
              f"{row['wall_seconds']:7.2f} s, cpu {row['cpu_seconds']:.1f} s, speed-up {row['speedup']:5.2f}, scaling efficiency "
              f"{100 * row['scaling_efficiency']:3.0f} %, solving {100 * (eff or 0):3.0f} % of wall x workers;  "
              f"{engine}", flush=True)
    last = max(range(len(rows)), key=lambda i: rows[i]["workers"])
    proj = projection(rows[last], runs[last], args.project)
    for how, p in (("wall", proj["wall"]), ("cpu", proj["cpu"])):
        print(f"projection from {how} times (Amdahl, not measured): from {proj['from_workers']} workers, serial "
              f"{p['serial_seconds']:.2f} s (fraction {p['serial_fraction']:.3f}) -> "
              f"{p['projected_wall_seconds']:.2f} s on {args.project} workers"
              + (f", {p['projected_speedup_1_to_n']}x over 1" if "projected_speedup_1_to_n" in p else ""), flush=True)
    print(json.dumps({"scene": scene.name, "points": n, "cores": cores, "rows": rows, "projection": proj,
                      "shared_machine_note": "wall times; compare rows of one run only"}))
    return 0


if __name__ == "__main__":
    sys.exit(main())
