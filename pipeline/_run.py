"""The driver: lock, skeleton, fan-out of chunk tasks, reductions, summary."""

from __future__ import annotations

import os
import sys
import time
import warnings
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ._grid import calibrate_points_per_task, chunk_grid, chunk_shape
from ._reduce import grid_reduction, objective, polish_cells
from ._scene import Scene
from ._store import (ATTRS_KEY, StoreMismatch, create_skeleton, open_existing, read_done, record_run,
                     reduction_arrays, remove_partials, run_lock, set_state)
from ._tasks import compute_chunk, compute_series

__all__ = ["RunSummary", "Session", "run_scene", "default_store"]


@dataclass(frozen=True)
class RunSummary:
    """What one run did. ``computed_points`` is 0 for an idempotent rerun."""

    scene: str
    store: str
    points: int
    computed_points: int
    computed_chunks: int
    total_chunks: int
    failures: int
    wall_seconds: float
    solve_seconds: float
    reductions_computed: bool
    series_computed: bool = False

    @property
    def solves_per_second(self) -> float:
        return self.computed_points / self.solve_seconds if self.solve_seconds > 0 else 0.0

    def line(self) -> str:
        if self.computed_chunks == 0 and not self.reductions_computed and not self.series_computed:
            return (f"{self.scene}: nothing to do, all {self.total_chunks} chunks and reductions already done "
                    f"({self.points} points, {self.failures} failures) in {self.store}")
        return (f"{self.scene}: {self.points} points ({self.computed_points} computed now in "
                f"{self.computed_chunks}/{self.total_chunks} chunks), {self.failures} failures, "
                f"wall {self.wall_seconds:.1f} s, {self.solves_per_second:.0f} solves/s -> {self.store}")


def default_store(scene: Scene) -> Path:
    """``[execution] store`` of the scene, else out/<name>.zarr."""
    store = getattr(scene.execution, "store", None)
    return Path(store) if store else Path("out") / f"{scene.name}.zarr"


class _Progress:
    """A one-line text progress bar on stderr (a line per 10% when stderr is not a terminal)."""

    def __init__(self, total: int, points_per_chunk: float, label: str, enabled: bool = True, unit: str = "chunks",
                 rate_unit: str = "solves/s"):
        self.total, self.ppc, self.label, self.unit, self.rate_unit = total, points_per_chunk, label, unit, rate_unit
        self.done = 0
        self.t0 = time.perf_counter()
        self.enabled = enabled and total > 0
        self.tty = sys.stderr.isatty()
        self.last_decile = -1

    def update(self, n: int = 1):
        self.done += n
        if not self.enabled:
            return
        frac = self.done / self.total
        el = time.perf_counter() - self.t0
        rate = self.done * self.ppc / el if el > 0 else 0.0
        eta = el * (1 - frac) / frac if frac > 0 else float("nan")
        bar = "#" * int(30 * frac)
        msg = (f"{self.label} [{bar:<30}] {100 * frac:5.1f}% {self.done}/{self.total} {self.unit} "
               f"{rate:,.1f} {self.rate_unit}  elapsed {el:.0f}s  eta {eta:.0f}s")
        if self.tty:
            sys.stderr.write("\r" + msg + ("\n" if self.done == self.total else ""))
            sys.stderr.flush()
        elif int(10 * frac) > self.last_decile:
            self.last_decile = int(10 * frac)
            print(msg, file=sys.stderr, flush=True)


class _Scheduler:
    """Where tasks run. One process pool serves the whole run (chunks and polishing), so each
    worker process imports (and JIT-compiles) the solver once."""

    def __init__(self, name: str, workers: int | None):
        self.name, self.workers = name, workers
        self._pool = None

    def pool(self):
        if self._pool is None:
            import multiprocessing
            from concurrent.futures import ProcessPoolExecutor

            self._pool = ProcessPoolExecutor(self.workers or os.cpu_count() or 1,
                                             mp_context=multiprocessing.get_context("spawn"))
        return self._pool

    def close(self):
        if self._pool is not None:
            self._pool.shutdown(wait=True, cancel_futures=True)
            self._pool = None

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()


class _Borrowed:
    """A session's scheduler, used without closing it."""

    def __init__(self, sched: _Scheduler):
        self.sched = sched

    def __enter__(self):
        return self.sched

    def __exit__(self, *exc):
        return None


#: A scheduler (and its process pool) shared by several runs; use as a context manager.
Session = _Scheduler


@dataclass(frozen=True)
class RunContext:
    """Where and on what one scene run computes (``scene_run``)."""

    store: Path
    scheduler: str
    n_workers: int
    sched: object  # _Scheduler (own pool) or the session's


@contextmanager
def scene_run(scene, store, scheduler, workers, session):
    """Resolve the store path and the scheduler of a run, hold the store's lock and a
    scheduler (the ``session``'s pool when it matches) for its duration."""
    store = Path(store) if store is not None else default_store(scene)
    scheduler = scheduler or scene.execution.scheduler
    workers = workers or scene.execution.workers
    n_workers = workers or (os.cpu_count() or 1 if scheduler in ("processes", "threads") else 1)
    own = session is None or session.name != scheduler or session.workers != workers
    with run_lock(store), (_Scheduler(scheduler, workers) if own else _Borrowed(session)) as sched:
        yield RunContext(store, scheduler, n_workers, sched)


def _compute(tasks, sched: _Scheduler, progress: _Progress):
    """Run delayed ``tasks`` on ``sched``; returns their results in order."""
    import dask

    scheduler, workers = sched.name, sched.workers

    if scheduler.startswith(("tcp://", "inproc://", "tls://", "ucx://")):
        from distributed import Client, as_completed

        with Client(scheduler, set_as_default=False) as client:
            futures = client.compute(tasks)
            index = {f.key: i for i, f in enumerate(futures)}
            results = [None] * len(futures)
            for fut in as_completed(futures, loop=client.loop):
                results[index[fut.key]] = fut.result()
                progress.update()
            return results
    from dask.callbacks import Callback

    class _CB(Callback):
        def _posttask(self, key, result, dsk, state, worker_id):
            if isinstance(key, str) and key.startswith("pipeline-"):
                progress.update()

    kwargs = {"scheduler": scheduler}
    if scheduler == "threads":
        kwargs["num_workers"] = workers or os.cpu_count() or 1
    if scheduler == "processes":
        kwargs["pool"] = sched.pool()
    with _CB():
        return list(dask.compute(*tasks, **kwargs))


def _load(store: Path, names) -> dict[str, np.ndarray]:
    import zarr

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return {n: zarr.open_array(store=str(store), path=n, mode="r")[...] for n in names}


def _write(store: Path, arrays: dict[str, np.ndarray]) -> None:
    import zarr

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        for n, v in arrays.items():
            a = zarr.open_array(store=str(store), path=n, mode="r+")
            a[...] = np.asarray(v).astype(a.dtype)


def _reductions(scene: Scene, store: Path, sched: _Scheduler, progress_enabled: bool) -> None:
    """Compute every reduction of the scene from the stored grid and write its arrays."""
    import dask

    for r in scene.reductions:
        names = {r.quantity, *r.report}
        data = _load(store, sorted(names))
        arrays, flat = grid_reduction(scene, r, data)
        _, rshape, spec = reduction_arrays(scene, r)
        out = {k: v for k, v in arrays.items()}
        if r.polish:
            kept = [a for a in scene.axes if a.name not in r.over]
            over_shape = tuple(scene.axis(a).size for a in r.over)
            cells, where = [], []
            for pos in np.ndindex(*rshape):
                k = int(flat[pos])
                if k < 0:
                    continue
                params = dict(scene.fixed)
                for a, i in zip(kept, pos):
                    params[a.name] = float(a.values[i])
                for a, i in zip(r.over, np.unravel_index(k, over_shape)):
                    params[a] = float(scene.axis(a).values[i])
                subset = pos[-1] if r.subsets is not None else None
                value = float(objective(r.statistic, np.array([arrays[r.name][pos]]))[0])
                cells.append({"params": params, "subset": subset, "value": value})
                where.append(pos)
            # Batches of cells per task, so a task takes seconds.
            # compass batches all cells of a task into each solver call: one task per worker;
            # the scipy methods call the solver point by point: smaller tasks balance better.
            per_worker = 1 if r.polish_method == "compass" else 4
            n_tasks = max(1, min(len(cells), per_worker * (sched.workers or os.cpu_count() or 1)))
            batches = [list(range(i, len(cells), n_tasks)) for i in range(n_tasks)] if cells else []
            tasks = [dask.delayed(polish_cells, pure=False)(scene, r, [cells[i] for i in b],
                                                           dask_key_name=f"pipeline-polish-{r.name}-{j}")
                     for j, b in enumerate(batches)]
            bar = _Progress(len(tasks), len(cells) / max(1, len(tasks)), f"polish {r.name}", progress_enabled,
                            unit="tasks", rate_unit="optima/s")
            results = _compute(tasks, sched, bar) if tasks else []
            pol = {name: np.full(rshape, fill, dtype=dtype) for name, (dtype, fill, _) in spec.items()
                   if name.startswith(f"{r.name}_polished")}
            base = f"{r.name}_polished"
            for b, res in zip(batches, results):
                for i, rec in zip(b, res):
                    pos = where[i]
                    v = rec["values"][r.quantity]
                    pol[base][pos] = abs(v) if r.statistic == "absmax" else v
                    if r.statistic == "absmax":
                        pol[f"{base}_signed"][pos] = v
                    for a in r.over:
                        pol[f"{base}_{a}"][pos] = rec["params"][a]
                    for q in r.report:
                        if q != r.quantity:
                            pol[f"{base}_{q}"][pos] = rec["values"][q]
                    pol[f"{base}_status"][pos] = rec["status"]
                    pol[f"{base}_evaluations"][pos] = rec["evaluations"]
            out.update(pol)
        _write(store, out)


def run_scene(scene: Scene, store: str | Path | None = None, *, scheduler: str | None = None,
              workers: int | None = None, overwrite: bool = False, progress: bool = True,
              echo=print, session: "Session | None" = None) -> RunSummary:
    """Run ``scene`` into ``store``, resuming whatever an earlier run left undone.

    Raises
    ------
    StoreMismatch
        The store holds a different scene (and ``overwrite`` is false), or is not a Zarr store.
    StoreBusy
        Another run holds the store's lock.

    ``session`` (a :class:`Session`) lets several runs share one pool of worker processes, so
    each worker imports and JIT-compiles the solver once (``python -m pipeline paper``).
    """
    if getattr(scene, "kind", "grid") == "optima":
        from ._optima import run_optima_scene

        return run_optima_scene(scene, store, scheduler=scheduler, workers=workers,
                                overwrite=overwrite, progress=progress, echo=echo, session=session)
    if getattr(scene, "kind", "grid") in ("accuracy", "stiffness"):  # studies: pipeline._study
        from ._study import run_study

        return run_study(scene, store, scheduler=scheduler, workers=workers, overwrite=overwrite,
                         progress=progress, echo=echo, session=session)
    t_start = time.perf_counter()
    with scene_run(scene, store, scheduler, workers, session) as run:
        store, scheduler, n_workers, sched = run.store, run.scheduler, run.n_workers, run.sched
        meta = open_existing(store)
        if meta is not None:
            old = meta["provenance"]["scene_hash"]
            if old != scene.hash:
                if not overwrite:
                    raise StoreMismatch(
                        f"{store}: built from a different scene ({meta['provenance']['scene_file']}, hash "
                        f"{old[:12]}) than {scene.path} (hash {scene.hash[:12]}); rerun with --overwrite to "
                        "replace it, or choose another --store")
                meta = None
            elif overwrite:
                meta = None
        if meta is None:
            target = scene.execution.points_per_task
            if target is None:
                target, rate = calibrate_points_per_task(scene, n_workers)
                if progress:
                    echo(f"{scene.name}: probe {rate:,.0f} solves/s per worker -> {target} points per task",
                         file=sys.stderr)
            chunks = chunk_shape(scene.shape, target)
            create_skeleton(store, scene, chunks)
            meta = open_existing(store)
        else:
            chunks = tuple(meta["layout"]["chunks"])
            remove_partials(store)
        grid = chunk_grid(scene.shape, chunks)
        done = read_done(store)
        pending = [tuple(int(i) for i in idx) for idx in zip(*np.nonzero(~done))]
        total_chunks = int(np.prod(grid))

        import dask

        computed_points = 0
        solve_seconds = 0.0
        t_solve = time.perf_counter()
        if pending:
            tasks = [dask.delayed(compute_chunk, pure=False)(str(store), scene, chunks, idx,
                                                            dask_key_name="pipeline-chunk-" + "-".join(map(str, idx)))
                     for idx in pending]
            bar = _Progress(len(tasks), scene.n_points / total_chunks, scene.name, progress)
            results = _compute(tasks, sched, bar)
            computed_points = sum(r["points"] for r in results)
            solve_seconds = time.perf_counter() - t_solve
            set_state(store, chunks_complete=True, reductions_complete=False)
        elif not meta["state"].get("chunks_complete"):
            set_state(store, chunks_complete=True)
        series_computed = False
        if scene.series is not None and not meta["state"].get("series_complete"):
            task = dask.delayed(compute_series, pure=False)(str(store), scene, dask_key_name="pipeline-series")
            _compute([task], sched, _Progress(1, len(scene.series.points), f"{scene.name} series", progress))
            set_state(store, series_complete=True)
            series_computed = True
        reductions_computed = False
        if scene.reductions and (pending or not meta["state"].get("reductions_complete")):
            _reductions(scene, store, sched, progress)
            reductions_computed = True
        failures = int(np.count_nonzero(_load(store, ["status"])["status"] != 0))
        if pending or reductions_computed or series_computed or not meta["state"].get("reductions_complete"):
            set_state(store, reductions_complete=True)
            import datetime as _dt

            record_run(store, {
                "finished": _dt.datetime.now(_dt.timezone.utc).isoformat(timespec="seconds"),
                "wall_seconds": round(time.perf_counter() - t_start, 3),
                "solve_seconds": round(solve_seconds, 3), "computed_points": computed_points,
                "computed_chunks": len(pending), "total_chunks": total_chunks, "failures": failures,
                "scheduler": scheduler, "workers": n_workers})
            _consolidate(store)
    return RunSummary(scene=scene.name, store=str(store), points=scene.n_points, computed_points=computed_points,
                      computed_chunks=len(pending), total_chunks=total_chunks, failures=failures,
                      wall_seconds=time.perf_counter() - t_start, solve_seconds=solve_seconds,
                      reductions_computed=reductions_computed, series_computed=series_computed)


def _consolidate(store: Path) -> None:
    import zarr

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        zarr.consolidate_metadata(str(store), zarr_format=3)


def store_meta(store: Path) -> dict:
    import zarr

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return dict(zarr.open_group(str(store), mode="r", use_consolidated=False).attrs)[ATTRS_KEY]
