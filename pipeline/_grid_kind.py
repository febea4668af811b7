"""Scene kind "grid" (the default): a grid of parameter points, its series and its reductions.

Tasks receive only picklable arguments (the frozen scene, indices) and return what they
computed; the driver writes the store (``_store.ChunkWriter``, ``write_arrays``), so they run
unchanged on the local schedulers and on a dask.distributed cluster, whose workers never open
the store.  Steps after the chunks: u(tau) at the scene's series points (one
task), then every reduction of the stored grid, whose polishing fans out again.
"""

from __future__ import annotations

import time
from pathlib import Path

import numpy as np

from ._grid import (chunk_region, chunk_sweeps, chunks_per_task, region_parameters,
                    scene_chunks, solve_points)
from ._grid_scene import Scene, parse_grid_scene
from ._kind import RunContext, SceneKind, Step, tasks_by_count
from ._reduce import grid_reduction, polish_starts
from .polish import polish_cells
from ._schedule import Progress, Task, compute, take_start_seconds
from ._store import ChunkWrite, SolvedChunk, create_skeleton, read_arrays, reduction_arrays, write_arrays

#: points one task aims at (about 0.5-2 s of one core's solving at rtol 1e-4)
TASK_POINTS = 1024

__all__ = ["GRID", "GridKind", "compute_series", "reduce_grid", "solve_chunk", "write_polish_records"]


def solve_chunk(scene: Scene, chunks: tuple[int, ...], index: tuple[int, ...]) -> SolvedChunk:
    """Solve every point of block ``index`` of the layout ``chunks``: its outputs, unwritten (the
    driver writes them: ``_store.ChunkWriter``)."""
    region = chunk_region(index, scene.shape, chunks)
    params = region_parameters(scene, region)
    rshape = tuple(sl.stop - sl.start for sl in region)
    t0 = time.perf_counter()
    if scene.sweeps:
        # warm starts along snake-ordered sweeps inside the chunk (``_grid.chunk_sweeps``)
        order, runs = chunk_sweeps(rshape)
        swept = solve_points(scene.family, {k: v[order] for k, v in params.items()}, scene.outputs,
                             method=scene.method, rtol=scene.rtol, sweeps=runs)
        values = {}
        for k, v in swept.items():
            values[k] = np.empty_like(v)
            values[k][order] = v
    else:
        values = solve_points(scene.family, params, scene.outputs, method=scene.method, rtol=scene.rtol)
    seconds = time.perf_counter() - t0
    values = {k: np.asarray(v).reshape(rshape) for k, v in values.items()}
    return SolvedChunk(writes=(ChunkWrite(region, tuple(index), tuple(chunks), scene.shape, values),),
                       points=int(np.prod(rshape)), failures=int(np.count_nonzero(values["status"] != 0)),
                       seconds=seconds)


def compute_series(scene: Scene) -> dict:
    """Solve the scene's series points: u(tau), resampled to uniform nodes tau_k = k/n_tau by
    periodic linear interpolation of the solver's final grid, unwritten.  Returns ``values``
    ({"series_u", "series_status"}: the driver writes them), the number of ``failures`` and the
    task's timing."""
    t0, c0 = time.perf_counter(), time.process_time()
    s = scene.series
    params = {d: np.array([dict(p)[d] for p in s.points], dtype=np.float64) for d in scene.dims}
    for k, v in scene.fixed:
        params[k] = np.full(len(s.points), v)
    out = solve_points(scene.family, params, (), method=scene.method, rtol=scene.rtol, series=True)
    tau = np.arange(s.n_tau) / s.n_tau
    seconds = time.perf_counter() - t0
    u = np.full((len(s.points), s.n_tau), np.nan)
    for i, (ui, ti) in enumerate(zip(out["u"], out["tau"])):
        if out["status"][i] == 0 and ui.size:
            u[i] = np.interp(tau, ti, ui, period=1.0)
    return {"values": {"series_u": u, "series_status": out["status"]}, "failures": int(np.count_nonzero(out["status"] != 0)), "seconds": seconds,
            "task_seconds": time.perf_counter() - t0, "task_cpu_seconds": time.process_time() - c0,
            **take_start_seconds()}


def timed_polish(scene: Scene, r, cells: list[dict]) -> tuple[list[dict], dict]:
    """``pipeline.polish.polish_cells`` in a task, with the task's timing (all of it solving:
    each evaluation is a solver call)."""
    t0, c0 = time.perf_counter(), time.process_time()
    records = polish_cells(scene, r, cells)
    seconds = time.perf_counter() - t0
    return records, {"seconds": seconds, "task_seconds": seconds, "task_cpu_seconds": time.process_time() - c0,
                     **take_start_seconds()}


#: polish tasks per worker (a cell's polish calls the solver point by point, sequentially:
#: more, smaller tasks balance the workers)
POLISH_TASKS_PER_WORKER = 4


def write_polish_records(r, rshape: tuple[int, ...], spec: dict, cells: list[dict], records: list[dict]) -> dict:
    """The ``{r}_polished*`` arrays (``_store.reduction_arrays``) from one record per cell."""
    base = f"{r.name}_polished"
    pol = {name: np.full(rshape, fill, dtype=dtype) for name, (dtype, fill, _) in spec.items()
           if name.startswith(base)}
    for cell, rec in zip(cells, records):
        pos = cell["pos"]
        pol[f"{base}_status"][pos] = rec["status"]
        pol[f"{base}_evaluations"][pos] = rec["evaluations"]
        pol[f"{base}_uncertainty"][pos] = rec["uncertainty"]
        for a in r.over:
            pol[f"{base}_{a}_edge"][pos] = rec["edges"][a]
        if rec["values"] is None:
            continue  # failed: the value and arg-max stay NaN
        v = rec["values"][r.quantity]
        pol[base][pos] = abs(v) if r.statistic == "absmax" else v
        if r.statistic == "absmax":
            pol[f"{base}_signed"][pos] = v
        for a in r.over:
            pol[f"{base}_{a}"][pos] = rec["params"][a]
        for q in r.report:
            if q != r.quantity:
                pol[f"{base}_{q}"][pos] = rec["values"][q]
    return pol


def reduce_grid(run: RunContext) -> list[dict]:
    """Compute every reduction of the scene from the stored grid and write its arrays; a polished
    reduction's cells (each from its best distinct grid basins, ``_reduce.polish_starts``) are
    polished in tasks (batches of cells).  The polish tasks' timings."""
    scene, store, sched = run.scene, run.store, run.scheduler
    timings = []
    for r in scene.reductions:
        names = {r.quantity, *r.report}
        data = read_arrays(store, sorted(names))
        arrays, _ = grid_reduction(scene, r, data)
        _, rshape, spec = reduction_arrays(scene, r)
        out = dict(arrays)
        if r.polish:
            cells = polish_starts(scene, r, data)
            # a grid cell's subsets stay in one task, in order (pipeline.polish.polish_cells)
            groups: dict = {}
            for i, c in enumerate(cells):
                groups.setdefault(c["group"], []).append(i)
            members = list(groups.values())
            n_tasks = max(1, min(len(members), POLISH_TASKS_PER_WORKER * run.n_workers))
            batches = [[i for g in members[t::n_tasks] for i in g] for t in range(n_tasks)] if cells else []
            tasks = [Task(f"pipeline-polish-{r.name}-{j}", timed_polish,
                          (scene, r, [{k: cells[i][k] for k in ("starts", "subset", "group")} for i in b]))
                     for j, b in enumerate(batches)]
            bar = Progress(len(tasks), len(cells) / max(1, len(tasks)), f"polish {r.name}", run.progress,
                           unit="tasks", rate_unit="optima/s")
            results = compute(tasks, sched, bar) if tasks else []
            timings += [t for _, t in results]
            ordered_cells, records = [], []
            for b, (res, _) in zip(batches, results):
                ordered_cells += [cells[i] for i in b]
                records += res
            out.update(write_polish_records(r, rshape, spec, ordered_cells, records))
        write_arrays(store, out)
    return timings


def series_step(run: RunContext) -> list[dict]:
    """u(tau) at the scene's series points, in one task, written by the driver; its timing."""
    task = Task("pipeline-series", compute_series, (run.scene,))
    results = compute([task], run.scheduler,
                      Progress(1, len(run.scene.series.points), f"{run.scene.name} series", run.progress))
    for r in results:
        write_arrays(run.store, r.pop("values"))
    return results


class GridKind(SceneKind):
    """The parameter grid (``_grid_scene.Scene``): chunks of grid points, then series and reductions."""

    names = ("grid",)
    solve_chunk = staticmethod(solve_chunk)

    def parse(self, doc, ctx, text):
        return parse_grid_scene(doc, ctx, text)

    def block_layout(self, scene) -> tuple[int, ...]:
        """``_grid.scene_chunks``: from the grid's shape and ``[execution] points_per_chunk``."""
        return scene_chunks(scene)

    def create_skeleton(self, run: RunContext) -> None:
        create_skeleton(run.store, run.scene, self.block_layout(run.scene))

    def chunks_per_task(self, run: RunContext, chunks: tuple[int, ...], pending: list) -> int:
        """Chunks of about ``[execution] points_per_task`` points per task, else
        ``TASK_POINTS`` points but at least ``_kind.TASKS_PER_WORKER`` tasks per worker
        (``_kind.tasks_by_count``): from counts alone, no timing probe (it cost the driver
        a kernel load and a solve before any work fanned out; docs/validation.md).  Only the
        grouping of chunks into tasks depends on it; the chunks, and every stored value, do not."""
        scene = run.scene
        per_chunk = int(np.prod(chunks))
        if scene.execution.points_per_task is not None:
            return chunks_per_task(scene.execution.points_per_task, per_chunk)
        return tasks_by_count(per_chunk, TASK_POINTS, len(pending), run.n_workers)

    def steps(self, scene) -> tuple[Step, ...]:
        steps = []
        if scene.series is not None:
            steps.append(Step("series", "series_complete", series_step, after_chunks=False))
        if scene.reductions:
            steps.append(Step("reductions", "reductions_complete", reduce_grid))
        return tuple(steps)

    def failures(self, store: Path, scene) -> int:
        """Grid points whose solve did not converge (status != 0)."""
        return int(np.count_nonzero(read_arrays(store, ["status"])["status"] != 0))

    def kernel_sets(self, scene) -> tuple[str, ...]:
        return (scene.method,)


GRID = GridKind()
