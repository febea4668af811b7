"""A finished run's wall time projected to more workers, from its stores' own records.

``python -m pipeline.projection OUT [--workers 16]``: OUT is a ``paper --out`` folder (every
``*.zarr`` under it) or one store.  A projection, not a measurement: it says what a machine
with more cores would take if each task ran as fast as it did here (no memory-bandwidth or
file-system effects; the 16-core machine issue 34 measured had a slow sandboxed file system).

Model, per store (its run record's ``timing``, ``_run.time_budget``):
- serial: the driver's phases outside the tasks (setup, plan, record, ...), and the part of
  the reductions and series phases in which the workers waited for the driver (their "idle
  or scheduling" worker-seconds / workers);
- work: worker-seconds inside tasks (solving, the rest of the task), which more workers share
  (the driver writes the chunks meanwhile);
- T(n) = serial + the makespan of the work on n workers.  Grid chunks are many and alike:
  work / n.  An optima or study store's tasks are few and unequal (per-start times are
  heavy-tailed): their durations are rebuilt from the stored per-start ``seconds`` (optima:
  ``starts_per_task`` consecutive starts of a cell) or per-point ``*seconds`` (studies: the
  layout's points per block), scaled so they sum to the work, and scheduled longest first
  (LPT, Graham 1969: within 4/3 of the optimal makespan).
The start of the worker pool (``paper``: once, before the first scene) is not included.

Last line: one JSON object with ``workers``, ``measured_seconds`` (the runs' walls summed),
``t1_seconds``, ``tn_seconds``, ``speedup`` and ``scenes`` (per store: ``measured_seconds``,
``serial_seconds``, ``work_worker_seconds``, ``tasks`` (None for grid chunks), ``longest_task_seconds``,
``t1_seconds``, ``tn_seconds``, ``speedup``).
"""
from __future__ import annotations

import argparse
import heapq
import json
import sys
from pathlib import Path

import numpy as np

from ._store import read_arrays, store_meta

__all__ = ["lpt_makespan", "project_store", "main"]

#: phases during which the tasks run (the rest of a run record's phases are the driver's)
TASK_PHASES = ("chunks", "reductions", "series")
#: not-solving parts spent inside tasks (they scale with the workers)
IN_TASKS = ("in tasks, besides solving",)


def lpt_makespan(tasks, workers: int) -> float:
    """Makespan of ``tasks`` (durations) on ``workers`` machines, longest first (LPT)."""
    loads = [0.0] * max(1, int(workers))
    for t in sorted((float(t) for t in tasks), reverse=True):
        heapq.heappush(loads, heapq.heappop(loads) + t)
    return max(loads)


def _task_durations(store: Path, meta: dict) -> list[float] | None:
    """Relative durations of an optima or study store's tasks, or None (grid chunks)."""
    kind = meta.get("kind", "grid")
    layout = meta.get("layout", {})
    if kind == "grid":
        return None
    if kind == "optima":  # (ratio, Kmax, p, start): a task is ``chunks[-1]`` starts of one cell
        sec = np.nan_to_num(read_arrays(store, ["seconds"])["seconds"])
        per_task = max(1, int(layout.get("blocks", layout["chunks"])[-1]))
        flat = sec.reshape(-1, sec.shape[-1])
        return [float(flat[i, j:j + per_task].sum()) for i in range(flat.shape[0])
                for j in range(0, flat.shape[1], per_task)]
    # a study: a task is ``chunks[0]`` points, each with every timed solve of the point
    n_points, per_task = int(layout["shape"][0]), max(1, int(layout.get("blocks", layout["chunks"])[0]))
    timed = sorted(p.name for p in store.iterdir()
                   if p.name.endswith("seconds") and (p / "zarr.json").is_file())
    per = np.zeros(n_points)
    for a in read_arrays(store, timed).values():
        if a.ndim >= 1 and a.shape[0] == n_points:
            per += np.nan_to_num(a).reshape(n_points, -1).sum(1)
    return [float(per[i:i + per_task].sum()) for i in range(0, n_points, per_task)]
    return None


def project_store(store: Path, workers: int) -> dict:
    """The projection of one store's last run to ``workers`` workers (see the module)."""
    meta = store_meta(store)
    timing = meta["run"]["timing"]
    ran_on = int(timing["workers"])
    phases = timing["phases_wall_seconds"]
    parts = timing["not_solving_worker_seconds"]
    serial = sum(v for k, v in phases.items() if k not in TASK_PHASES)
    serial += sum(v for k, v in parts.items()
                  if k.startswith(("reductions:", "series:"))) / max(ran_on, 1)
    work = timing["solve_worker_seconds"] + sum(parts.get(k, 0.0) for k in IN_TASKS)
    tasks = _task_durations(store, meta)
    if tasks and sum(tasks) > 0:
        scale = work / sum(tasks)
        tasks = [t * scale for t in tasks]
        span = lpt_makespan(tasks, workers)
        longest = max(tasks)
    else:
        tasks, span, longest = None, work / workers, None
    t1, tn = serial + work, serial + span
    return {"store": store.name, "measured_seconds": timing["wall_seconds"], "measured_workers": ran_on,
            "serial_seconds": round(serial, 3), "work_worker_seconds": round(work, 3),
            "tasks": None if tasks is None else len(tasks),
            "longest_task_seconds": None if longest is None else round(longest, 3),
            "t1_seconds": round(t1, 3), "tn_seconds": round(tn, 3), "speedup": round(t1 / tn, 2) if tn else None}


def _stores(path: Path) -> list[Path]:
    if (path / "zarr.json").is_file():
        return [path]
    return sorted(p for p in path.glob("*.zarr") if (p / "zarr.json").is_file())


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(prog="python -m pipeline.projection", description=__doc__.split("\n\n")[0])
    parser.add_argument("out", help="a `paper --out` folder or one store")
    parser.add_argument("--workers", type=int, default=16)
    args = parser.parse_args(argv)
    if args.workers < 1:
        print(f"error: --workers: must be >= 1, got {args.workers}", file=sys.stderr)
        return 2
    stores = _stores(Path(args.out))
    if not stores:
        print(f"error: out: no stores under {args.out}", file=sys.stderr)
        return 2
    rows = []
    for store in stores:
        try:
            rows.append(project_store(store, args.workers))
        except (KeyError, TypeError):
            print(f"{store.name}: no run record with timings (not run by this pipeline): left out", flush=True)
            continue
        r = rows[-1]
        tasks = "grid chunks" if r["tasks"] is None else f"{r['tasks']} tasks, longest {r['longest_task_seconds']:.1f} s"
        print(f"{r['store']:28s} measured {r['measured_seconds']:8.1f} s on {r['measured_workers']}; serial "
              f"{r['serial_seconds']:5.2f} s, work {r['work_worker_seconds']:8.1f} worker-s ({tasks}); T1 "
              f"{r['t1_seconds']:8.1f} s, T{args.workers} {r['tn_seconds']:7.1f} s, {r['speedup']:5.1f}x", flush=True)
    t1 = sum(r["t1_seconds"] for r in rows)
    tn = sum(r["tn_seconds"] for r in rows)
    measured = sum(r["measured_seconds"] for r in rows)
    print(f"all {len(rows)} stores: measured {measured:.1f} s; projected T1 {t1:.1f} s, T{args.workers} {tn:.1f} s "
          f"({t1 / tn:.1f}x) -- a projection, not a measurement", flush=True)
    print(json.dumps({"workers": args.workers, "measured_seconds": round(measured, 3), "t1_seconds": round(t1, 3),
                      "tn_seconds": round(tn, 3), "speedup": round(t1 / tn, 2) if tn else None, "scenes": rows}))
    return 0


if __name__ == "__main__":
    sys.exit(main())
