"""The driver: one scene of any kind into its resumable Zarr store.

``run_scene`` is a chain of small named steps over the kind's protocol (``pipeline._kind``)::

    open_run        resolve store and scheduler; refuse, before anything is written, a cluster
                    that does not answer and a store that would be refused; hold the lock
    prepare_store   refuse a store of a different scene, or (re)create the skeleton, or resume
    check_layout    refuse chunks still to compute in a block layout that is not the scene's
    warm_up         compile the solver's kernels once, here, before work fans out
    compute_chunks  tasks of the blocks of the chunks without their done marker; this driver
                    writes each chunk once its blocks are back, syncs it, then marks it done
    finish          the kind's steps whose state flag is unset (series, reductions)
    record          state flags set, run record and consolidated metadata, when anything was
                    computed

Only this driver writes the store: tasks return what they computed (``_store.ChunkWriter``).
"""

from __future__ import annotations

import datetime as dt
import sys
import time
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path

from ._kind import RunContext, SceneKind
from ._registry import kind_of
from ._scene import engine_versions
from ._schedule import Progress, Scheduler, Session, Task, compute, take_start_seconds
from ._store import (FORMAT_VERSION, STATE_FLAGS, ChunkWriter, StoreForeign, StoreMismatch, StoreUnwritable,
                     blocks_in, consolidate, is_complete, open_existing, record_run, remove_partials, run_lock,
                     set_state, store_meta, unwritable_reason)

__all__ = ["KeptChunks", "RunSummary", "Session", "default_store", "kept_chunks", "resumable_record", "run_scene",
           "warm_up_kernels"]


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
    #: where the time went (``time_budget``); None when nothing was computed
    timing: dict | None = None

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

    def timing_line(self, parts: int = 4) -> str:
        """Where the time went: wall, solving summed over the workers, parallel efficiency
        (solving / (wall x workers)) and the ``parts`` largest other parts [worker-seconds]."""
        t = self.timing
        if not t:
            return ""
        other = list(t["not_solving_worker_seconds"].items())[:parts]
        rest = ", ".join(f"{name} {seconds:.1f}" for name, seconds in other)
        return (f"{self.scene}: time: wall {t['wall_seconds']:.1f} s x {t['workers']} workers; solving "
                f"{t['solve_worker_seconds']:.1f} worker-s, efficiency {100 * t['efficiency']:.0f} %; "
                f"not solving (worker-s): {rest}")


def default_store(scene) -> Path:
    """``[execution] store`` of the scene, else out/<name>.zarr."""
    store = getattr(scene.execution, "store", None)
    return Path(store) if store else Path("out") / f"{scene.name}.zarr"


def warm_up_kernels(kernel_sets, echo=print) -> None:
    """Compile (first run) or load the solver's kernels for ``kernel_sets`` in this process,
    saying so when it compiles; a no-op for sets already warm here.

    The driver calls it before work fans out, so worker processes load the kernels from
    numba's on-disk cache instead of each compiling them again.
    """
    import solver

    first = not solver.kernel_cache().populated
    if first:
        echo("compiling the solver's kernels (first run only) ...", end="", file=sys.stderr, flush=True)
    result = solver.warm_up(kernel_sets)
    if first:
        echo(f" {result.seconds:.0f} s", file=sys.stderr, flush=True)
    elif result.compiled:
        echo(f"compiled {result.compiled} solver kernels for {', '.join(result.kernel_sets)} (first use) "
             f"in {result.seconds:.0f} s", file=sys.stderr, flush=True)


@contextmanager
def open_run(scene, store, scheduler, workers, session, progress, echo, overwrite: bool = False):
    """The run's context and the record of the store it resumes (None: a skeleton to build):
    resolved store path and scheduler (the ``session``'s pool when it matches), holding the
    store's lock for the duration.

    Before the lock file or anything else is written, a dask.distributed scheduler must answer
    (``Scheduler.connect``, which also counts its workers) and the store must not be one that
    :func:`resumable_record` or :func:`check_layout` refuses; both are asked again under the
    lock (``prepare_store``, ``run_scene``).
    Left by Ctrl-C (an exception that is not an error), the run's own worker processes are
    ended at once (``Scheduler.close(kill=True)``)."""
    store = Path(store) if store is not None else default_store(scene)
    name = scheduler or scene.execution.scheduler
    workers = workers or scene.execution.workers
    # the session's pool serves every run of its scheduler that asks for no other worker count
    own = session is None or session.name != name or (workers is not None and session.n_workers != workers)
    sched = Scheduler(name, workers, kind_of(scene).kernel_sets(scene)) if own else session
    try:
        sched.connect()  # a cluster that does not answer is refused here, nothing written
        run = RunContext(scene, store, sched, sched.n_workers, progress, echo)
        early = resumable_record(scene, store, overwrite)
        if early is not None and not overwrite:  # (with --overwrite, run_scene replaces it)
            check_layout(run, kind_of(scene), early, kind_of(scene).pending_chunks(store))
        with run_lock(store):
            yield run, early
    except BaseException as exc:
        if own:
            sched.close(kill=not isinstance(exc, Exception))
        raise
    else:
        if own:
            sched.close()


def start_workers(run: RunContext, kind: SceneKind, echo) -> None:
    """Have the kernels ready where the tasks run.  A pool of worker processes is started
    (``Scheduler.start``: each loads the kernels once, the first of them compiling them when
    numba's cache is empty while the others wait); where this process runs the tasks itself
    (synchronous, threads) or they run on a cluster, the kernels are compiled or loaded here."""
    if run.scheduler.name == "processes":
        import solver

        if not solver.kernel_cache().populated:
            echo("compiling the solver's kernels (first run only), in the first worker ...", file=sys.stderr,
                 flush=True)
        run.scheduler.start()
        return
    warm_up_kernels(kind.kernel_sets(run.scene), echo)


def resumable_record(scene, store: Path, overwrite: bool) -> dict | None:
    """The ``pipeline`` record of the store to resume, or None where a skeleton is to be built
    (no store yet, an interrupted skeleton, or, with ``overwrite``, one that would be refused).

    Refused (:class:`StoreMismatch`) unless ``overwrite``: a Zarr store the pipeline did not
    write (:class:`StoreForeign`), a store of another format version, engine or scene.  Refused
    even with ``overwrite``: a path that is not a Zarr store (a file, a folder of other files).
    Writes nothing."""
    try:
        meta = open_existing(store)
    except StoreForeign:
        if not overwrite:
            raise
        return None
    if meta is None:
        return None
    if meta.get("format_version", 1) != FORMAT_VERSION:
        if not overwrite:
            raise StoreMismatch(
                f"{store}: store format version {meta.get('format_version', 1)}, this pipeline writes version "
                f"{FORMAT_VERSION} (chunks of whole blocks); rerun with --overwrite to rebuild it, or "
                "choose another --store (the reports read it as it is)")
        return None  # overwrite: start over
    old = meta["provenance"]["scene_hash"]
    engines, ours = meta["provenance"].get("engines"), engine_versions()
    if engines != ours and not overwrite:
        def label(versions):
            return (", ".join(f"{k} {v}" for k, v in versions.items()) if versions
                    else "an engine before versions were recorded")
        raise StoreMismatch(
            f"{store}: computed by {label(engines)}; this solver is {label(ours)}: results "
            "of two engines are never mixed in one store; rerun with --overwrite to start "
            "over, or choose another --store")
    have, want = meta.get("kind_version"), getattr(scene, "science", {}).get("kind_version")
    if want is not None and have != want and not overwrite:
        # what the per-start values mean changed (e.g. optima's 3: certified optima): name it
        raise StoreMismatch(
            f"{store}: a {meta.get('kind')} store of kind_version {have}; this pipeline writes kind_version "
            f"{want}, whose values mean something else; rerun with --overwrite to start over, or choose "
            "another --store")
    if old != scene.hash and not overwrite:
        raise StoreMismatch(
            f"{store}: built from a different scene ({meta['provenance']['scene_file']}, hash "
            f"{old[:12]}) than {scene.path} (hash {scene.hash[:12]}); rerun with --overwrite to "
            "replace it, or choose another --store")
    if engines != ours or old != scene.hash:
        return None  # overwrite: start over
    return meta


def prepare_store(run: RunContext, kind: SceneKind, overwrite: bool, replace: bool = False) -> dict:
    """The store's ``pipeline`` record, after refusing a store of a different scene, engine or
    store format version, or one the pipeline did not write (replaced instead where
    ``overwrite``: :func:`resumable_record`), creating the skeleton of a new or replaced store
    (``replace``: replaced whatever it holds), or removing the debris of interrupted writes
    from one being resumed. A store of this scene and engine is resumed, ``overwrite`` or not
    (``paper --overwrite`` recomputes only the scenes whose stores would be refused)."""
    store = run.store
    meta = None if replace else resumable_record(run.scene, store, overwrite)
    if meta is None:
        try:
            kind.create_skeleton(run)
        except OSError as exc:  # a folder that refuses the store (read-only, full): one line, not a traceback
            raise StoreUnwritable(f"{store}: cannot write the store: {unwritable_reason(store, exc)}; "
                                  "choose another --store (or --out)") from None
        return open_existing(store)
    remove_partials(store)
    return store_meta(store)


def _shape(chunks) -> str:
    return " x ".join(str(int(c)) for c in chunks)


def check_layout(run: RunContext, kind: SceneKind, meta: dict, pending) -> None:
    """Refuse a store whose blocks are not the scene's (``kind.block_layout``) while chunks
    remain to compute: the store was started by an older pipeline, whose layout came from a
    timing probe, or with another ``[execution] points_per_chunk``.  A store with every chunk
    done is left as it is (nothing is computed in its layout)."""
    want = kind.block_layout(run.scene)
    have = tuple(int(c) for c in meta["layout"]["blocks"])
    if want is None or not pending or tuple(want) == have:
        return
    raise StoreMismatch(
        f"{run.store}: its blocks ({_shape(have)}) are not this scene's block layout ({_shape(want)}), so its "
        f"{len(pending)} unfinished chunks cannot be resumed (a store started by an older pipeline, which chose "
        "chunks by a timing probe, or with another [execution] points_per_chunk); rerun with --overwrite to "
        "start over, or choose another --store")


def run_chunks(solve_chunk, scene, chunks: tuple[int, ...], indices) -> dict:
    """One task: ``solve_chunk`` on each block of ``indices`` (``chunks``: the block layout) in
    turn; the blocks' values go back to the driver, which writes them (``_store.ChunkWriter``).

    Returns ``solved`` [(block index, ``_store.SolvedChunk``)], the sums of the blocks'
    ``points``, ``failures``, ``seconds`` (solving), ``task_seconds`` (the task's wall time),
    ``task_cpu_seconds``, and the worker's start-up on its first task
    (``_schedule.take_start_seconds``).
    """
    t0, c0 = time.perf_counter(), time.process_time()
    total = {"points": 0, "failures": 0, "seconds": 0.0}
    solved = []
    for idx in indices:
        s = solve_chunk(scene, chunks, idx)
        total["points"] += int(s.points)
        total["failures"] += int(s.failures)
        total["seconds"] += float(s.seconds)
        solved.append((tuple(int(i) for i in idx), s))
    return {"solved": solved, **total, "task_seconds": time.perf_counter() - t0,
            "task_cpu_seconds": time.process_time() - c0, **take_start_seconds()}


def compute_chunks(run: RunContext, kind: SceneKind, meta: dict, pending, clock: Clock | None = None
                   ) -> tuple[list[dict], ChunkWriter | None]:
    """The blocks of the ``pending`` storage chunks, in tasks of ``kind.chunks_per_task``
    consecutive blocks (a chunk's blocks together), fanned out on the run's scheduler; each
    chunk written, synced and marked by this driver once its last block is back
    (``_store.ChunkWriter``).  The tasks' results (without their blocks' values), and the
    writer (its seconds)."""
    if not pending:
        return [], None
    layout = meta["layout"]
    shape, blocks, chunks = (tuple(int(n) for n in layout[k]) for k in ("shape", "blocks", "chunks"))
    todo = [b for c in pending for b in blocks_in(c, shape, blocks, chunks)]
    per_task = max(1, int(kind.chunks_per_task(run, blocks, todo)))
    if clock is not None:
        clock.lap("plan")
    groups = [todo[i:i + per_task] for i in range(0, len(todo), per_task)]
    # the longest tasks first (where the kind can tell), so no long task starts last
    costs = [sum(kind.chunk_cost(run.scene, idx) for idx in group) for group in groups]
    groups = [groups[i] for i in sorted(range(len(groups)), key=lambda i: -costs[i])]  # stable
    label = run.scene.kind

    def key(group):
        first = f"pipeline-{label}-" + "-".join(map(str, group[0]))
        return first if len(group) == 1 else f"{first}-and-{len(group) - 1}"

    tasks = [Task(key(group), run_chunks, (kind.solve_chunk, run.scene, blocks, group)) for group in groups]
    writer = ChunkWriter(run.store, layout, pending)

    def write(_, result):
        for idx, solved in result.pop("solved"):
            writer.add(idx, solved)

    bar = Progress(len(tasks), per_task * run.scene.n_points / max(1, _block_count(layout)), run.scene.name,
                   run.progress, unit="tasks" if per_task > 1 else "blocks", rate_unit=kind.rate_unit)
    results = compute(tasks, run.scheduler, bar, on_result=write)
    if writer.missing:
        raise RuntimeError(f"{run.store}: {len(writer.missing)} chunks not whole after their tasks returned")
    if clock is not None:
        clock.lap("chunks")
    return results, writer


def _block_count(layout: dict) -> int:
    count = 1
    for s, b in zip(layout["shape"], layout["blocks"]):
        count *= -(-int(s) // int(b))
    return count


def _chunk_count(meta: dict) -> int:
    count = 1
    for n in meta["layout"]["chunk_grid"]:
        count *= int(n)
    return count


def finish(run: RunContext, kind: SceneKind, state: dict, chunks_computed: bool,
           clock: Clock | None = None) -> tuple[list[str], dict[str, list[dict]]]:
    """Run the kind's steps whose state flag is unset (all that depend on the chunks, after
    chunks were computed); each flag is set once its step is done.  The names of the steps run,
    and per step the timings of the tasks it ran (a step's ``run`` may return a list of them)."""
    if chunks_computed:
        reset = {s.state: False for s in kind.steps(run.scene) if s.after_chunks}
        set_state(run.store, chunks_complete=True, **reset)
        state = {**state, "chunks_complete": True, **reset}
    ran, timings = [], {}
    for step in kind.steps(run.scene):
        if not state.get(step.state):
            timings[step.name] = list(step.run(run) or [])
            set_state(run.store, **{step.state: True})
            ran.append(step.name)
            if clock is not None:
                clock.lap(step.name)
    return ran, timings


class Clock:
    """Wall seconds of the driver's phases, in order (``lap(name)`` closes the running phase)."""

    def __init__(self):
        self.t0 = self.t = time.perf_counter()
        self.c = time.process_time()
        self.phases: dict[str, float] = {}
        self.cpu: dict[str, float] = {}  # the driver's CPU seconds per phase

    def lap(self, name: str) -> None:
        now, cpu = time.perf_counter(), time.process_time()
        self.phases[name] = self.phases.get(name, 0.0) + now - self.t
        self.cpu[name] = self.cpu.get(name, 0.0) + cpu - self.c
        self.t, self.c = now, cpu

    @property
    def wall(self) -> float:
        return time.perf_counter() - self.t0


def _sum(results, key) -> float:
    return float(sum(r.get(key, 0.0) for r in results))


def time_budget(clock: Clock, workers: int, chunk_results: list[dict], step_results: dict[str, list[dict]],
                writer: ChunkWriter | None = None) -> dict:
    """Where the run's time went, in worker-seconds of a budget ``wall x workers``.

    ``solve``: seconds inside the solver (or optimiser), summed over the tasks of the chunks
    and of the steps (polish, series).  The rest, by part: the driver's phases while the
    workers wait (each phase's wall x workers, its tasks' own time taken out), and inside the
    tasks the workers' start-up (imports, kernels) and what else the tasks did.  The driver's
    writes of the chunks (``writer``: while the workers solve) are ``driver_write_seconds``.
    ``efficiency`` = solve / (wall x workers).
    """
    wall = clock.wall
    budget = wall * workers
    tasks = list(chunk_results) + [r for rs in step_results.values() for r in rs]
    solve = _sum(tasks, "seconds")
    parts = {}
    for name, seconds in clock.phases.items():
        inside = step_results.get(name, chunk_results if name == "chunks" else [])
        task_seconds = _sum(inside, "task_seconds") + _sum(inside, "start_seconds")
        if name == "chunks" or name in step_results:
            # the phase's worker time not spent in its tasks: scheduling, waiting for the last task
            parts[f"{name}: idle or scheduling"] = max(0.0, seconds * workers - task_seconds)
        else:
            parts[name] = seconds * workers
    parts["worker start-up"] = _sum(tasks, "start_seconds")
    parts["in tasks, besides solving"] = max(0.0, _sum(tasks, "task_seconds") - solve)
    return {"wall_seconds": round(wall, 3), "workers": workers, "solve_worker_seconds": round(solve, 3),
            "efficiency": round(solve / budget, 4) if budget > 0 else 0.0,
            "phases_wall_seconds": {k: round(v, 3) for k, v in clock.phases.items()},
            "driver_cpu_seconds": {k: round(v, 3) for k, v in clock.cpu.items()},
            "tasks_cpu_seconds": round(_sum(tasks, "task_cpu_seconds"), 3),
            "worker_start_cpu_seconds": round(_sum(tasks, "start_cpu_seconds"), 3),
            "driver_write_seconds": {"writes": round(writer.seconds["write"], 3) if writer else 0.0,
                                     "fsync": round(writer.seconds["sync"], 3) if writer else 0.0,
                                     "done markers": round(writer.seconds["mark"], 3) if writer else 0.0,
                                     "chunks written": writer.written if writer else 0},
            "not_solving_worker_seconds": {k: round(v, 3) for k, v in
                                           sorted(parts.items(), key=lambda kv: -kv[1]) if v >= 0.0005}}


def run_scene(scene, store: str | Path | None = None, *, scheduler: str | None = None,
              workers: int | None = None, overwrite: bool = False, progress: bool = True,
              echo=print, session: Session | None = None) -> RunSummary:
    """Run ``scene`` (of any kind) into ``store``, resuming whatever an earlier run left undone.

    Raises
    ------
    StoreMismatch
        The store holds a different scene or a Zarr store the pipeline did not write
        (:class:`~pipeline._store.StoreForeign`; both replaced where ``overwrite``), or is not a
        Zarr store; or it cannot be written there (:class:`~pipeline._store.StoreUnwritable`).
    StoreBusy
        Another run holds the store's lock.
    SchedulerUnavailable
        A dask.distributed scheduler that does not answer, or has no worker (nothing written).

    ``session`` (a :class:`Session`) lets several runs share one pool of worker processes, so
    each worker imports the solver and loads its kernels once (``python -m pipeline paper``).
    """
    kind = kind_of(scene)
    clock = Clock()
    with open_run(scene, store, scheduler, workers, session, progress, echo, overwrite) as (run, early):
        if early is None or not is_complete(early["state"]) or overwrite:
            run.scheduler.start()  # the workers start while this process prepares the store
        meta = prepare_store(run, kind, overwrite)
        pending = kind.pending_chunks(run.store)
        try:
            check_layout(run, kind, meta, pending)
        except StoreMismatch:
            if not overwrite:
                raise
            meta = prepare_store(run, kind, overwrite, replace=True)
            pending = kind.pending_chunks(run.store)
        clock.lap("setup")
        if pending or not is_complete(meta["state"]):
            start_workers(run, kind, echo)
            clock.lap("warm-up")
        t_solve = time.perf_counter()
        results, writer = compute_chunks(run, kind, meta, pending, clock)
        solve_seconds = time.perf_counter() - t_solve if pending else 0.0
        computed_points = sum(r["points"] for r in results)
        ran, step_results = finish(run, kind, meta["state"], bool(pending), clock)
        failures = kind.failures(run.store, scene)
        timing = None
        if pending or ran or not is_complete(meta["state"]):
            set_state(run.store, **{flag: True for flag in STATE_FLAGS})
            clock.lap("record")
            timing = time_budget(clock, run.n_workers, results, step_results, writer)
            record_run(run.store, {
                "finished": dt.datetime.now(dt.timezone.utc).isoformat(timespec="seconds"),
                "wall_seconds": round(clock.wall, 3),
                "solve_seconds": round(solve_seconds, 3), "computed_points": computed_points,
                "computed_chunks": len(pending), "total_chunks": _chunk_count(meta), "failures": failures,
                "scheduler": run.scheduler.name, "workers": run.n_workers,
                "threads_per_worker": run.scheduler.threads, "timing": timing})
            consolidate(run.store)
    return RunSummary(scene=scene.name, store=str(run.store), points=scene.n_points,
                      computed_points=computed_points, computed_chunks=len(pending),
                      total_chunks=_chunk_count(meta), failures=failures,
                      wall_seconds=clock.wall, solve_seconds=solve_seconds,
                      reductions_computed="reductions" in ran, series_computed="series" in ran, timing=timing)


@dataclass(frozen=True)
class KeptChunks:
    """What a stopped run left in its store: ``kept`` chunks with their done marker of
    ``total`` (None where the store's record does not exist yet)."""

    kept: int
    total: int | None

    def summary(self) -> str:
        """``N of M chunks kept; rerun the same command to resume``."""
        if self.total is None:
            return "no chunk kept (the store was not created yet); rerun the same command to start it"
        return f"{self.kept} of {self.total} chunks kept; rerun the same command to resume"

    def line(self, what: str = "interrupted") -> str:
        """``interrupted: N of M chunks kept; rerun the same command to resume``."""
        return f"{what}: {self.summary()}"


def kept_chunks(scene, store: str | Path | None) -> KeptChunks:
    """The chunks of ``scene``'s ``store`` with their done marker (after a run was stopped)."""
    store = Path(store) if store is not None else default_store(scene)
    try:
        meta = open_existing(store)
    except StoreMismatch:
        meta = None
    if meta is None:
        return KeptChunks(0, None)
    total = _chunk_count(meta)
    return KeptChunks(total - len(kind_of(scene).pending_chunks(store)), total)
