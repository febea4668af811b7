"""Where tasks run: the dask schedulers, a shared worker pool, and a text progress bar.

``compute(tasks, scheduler, progress)`` runs a list of :class:`Task` on a pool of worker
processes ("processes", the default: the tasks go to the pool directly, in the order given),
on one of dask's other local schedulers ("threads", "synchronous") or on a dask.distributed
cluster ("tcp://host:port", also "tls://", "inproc://", "ucx://") and returns their results in
order.  Tasks are keyed ``pipeline-...`` so the progress bar counts them and nothing else.
"""

from __future__ import annotations

import os
import sys
import time
from dataclasses import dataclass
from typing import Callable

__all__ = ["DISTRIBUTED_PREFIXES", "LOCAL_SCHEDULERS", "Progress", "Scheduler", "Session", "Task", "compute",
           "threads_per_worker", "usable_cores"]

LOCAL_SCHEDULERS = ("processes", "threads", "synchronous")
#: addresses of a dask.distributed scheduler
DISTRIBUTED_PREFIXES = ("tcp://", "inproc://", "tls://", "ucx://")


class Progress:
    """A one-line text progress bar on stderr (a line per 10% when stderr is not a terminal).

    ``total`` tasks of ``points_per_task`` points each; the rate is shown in ``rate_unit``.
    """

    def __init__(self, total: int, points_per_task: float, label: str, enabled: bool = True,
                 unit: str = "chunks", rate_unit: str = "solves/s"):
        self.total, self.ppc, self.label, self.unit, self.rate_unit = total, points_per_task, label, unit, rate_unit
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


def usable_cores() -> int:
    """Cores this process may run on (its affinity mask where the OS has one)."""
    try:
        return len(os.sched_getaffinity(0)) or 1
    except (AttributeError, OSError):
        return os.cpu_count() or 1


def threads_per_worker(workers: int, cores: int | None = None) -> int:
    """numba threads for each of ``workers`` worker processes so that workers x threads = cores
    (at least 1): more oversubscribes the cores, and an OpenMP thread that waits for a
    descheduled sibling spins (measured in docs/validation.md, "Pipeline at scale").  A
    ``NUMBA_NUM_THREADS`` set by the user caps each worker's threads."""
    if cores is None:
        cores = usable_cores()
        limit = os.environ.get("NUMBA_NUM_THREADS", "")
        if limit.isdigit() and int(limit) > 0:  # the user's own cap on numba threads holds
            cores = min(cores, int(limit) * max(1, workers))
    return max(1, cores // max(1, workers))


#: seconds the worker process spent starting (imports, the solver's kernels loaded), reported
#: once, with the first task it runs (``take_start_seconds``)
_worker_start = {"seconds": 0.0, "cpu": 0.0}


def set_numba_threads_env(threads: int) -> None:
    """``NUMBA_NUM_THREADS`` = ``threads`` for this process, before numba's thread pool starts.

    numba reads the variable when it is imported, and again (``config.reload_config``) at every
    compilation, refusing a value other than the pool's once the pool runs.  A spawned worker
    has often imported numba already (the driver's ``__main__``, e.g. ``python -m pipeline``,
    is imported again in the child), with the default of one thread per core: so the config is
    reloaded here, before anything launches the pool.  Without it the first kernel compiled
    after the pool's launch (a first run, numba's cache empty) raised "Cannot set
    NUMBA_NUM_THREADS to a different value once the threads have been launched" in every
    worker (found running a scene from a fresh checkout)."""
    os.environ["NUMBA_NUM_THREADS"] = str(threads)
    if "numba" in sys.modules:
        from numba.core import config
        from numba.np.ufunc import parallel

        if parallel._is_initialized:
            # too late to change the pool: keep the variable equal to it, so later reloads
            # agree; ``numba.set_num_threads`` still caps the threads used
            os.environ["NUMBA_NUM_THREADS"] = str(config.NUMBA_NUM_THREADS)
        else:
            config.reload_config()


def _start_worker(threads: int, kernel_sets: tuple[str, ...]) -> None:
    """Initializer of a pool's worker process: its numba thread count, then the solver and its
    kernels loaded once, before any task (so no task's timing pays for them)."""
    t0, c0 = time.perf_counter(), time.process_time()
    set_numba_threads_env(threads)
    import pipeline  # noqa: F401  (the tasks' modules, imported once here)

    if kernel_sets:
        import solver

        cache = solver.kernel_cache()
        if cache.populated or not cache.directory:
            solver.warm_up(kernel_sets)
        else:
            # numba's cache is empty (a first run): one worker compiles, the others wait and load
            import fcntl

            with open(os.path.join(os.path.dirname(cache.directory), ".twolink-compile.lock"), "w") as lock:
                fcntl.flock(lock, fcntl.LOCK_EX)
                solver.warm_up(kernel_sets)
    import numba

    numba.set_num_threads(min(threads, numba.config.NUMBA_NUM_THREADS))
    _worker_start["seconds"] += time.perf_counter() - t0
    _worker_start["cpu"] += time.process_time() - c0


def _ready(hold: float = 0.0, take: bool = False) -> tuple[int, dict]:
    """(pid, this worker's start-up not yet reported if ``take``, else zeros and left to its
    first task): a started worker's answer, after ``hold`` seconds (so that one worker does not
    answer for a sibling still starting)."""
    if hold:
        time.sleep(hold)
    return os.getpid(), take_start_seconds() if take else {"start_seconds": 0.0, "start_cpu_seconds": 0.0}


def take_start_seconds() -> dict:
    """This worker's start-up not yet reported (zeros after the first call), as task timing
    keys: ``start_seconds`` (wall) and ``start_cpu_seconds``."""
    out = {"start_seconds": _worker_start["seconds"], "start_cpu_seconds": _worker_start["cpu"]}
    _worker_start.update(seconds=0.0, cpu=0.0)
    return out


class Scheduler:
    """Where tasks run: a scheduler name (or cluster address) and a local worker count.

    One process pool serves every ``compute`` on "processes" until ``close``, so each worker
    process imports the solver (and loads the compiled kernels of ``kernel_sets``) once, with
    :func:`threads_per_worker` numba threads.  ``start()`` spawns the workers at once, so they
    start while the driver prepares the store.  Use as a context manager; a ``Session`` is the
    same object shared by several runs (``python -m pipeline paper``).
    """

    def __init__(self, name: str, workers: int | None, kernel_sets: tuple[str, ...] = ()):
        self.name, self.workers = name, workers
        self.kernel_sets = tuple(kernel_sets)
        self._pool = None
        self._ready = []

    @property
    def distributed(self) -> bool:
        return self.name.startswith(DISTRIBUTED_PREFIXES)

    @property
    def n_workers(self) -> int:
        """Local workers ("processes", "threads": ``workers`` or every core); 1 otherwise."""
        if self.name in ("processes", "threads"):
            return self.workers or usable_cores()
        return 1

    @property
    def threads(self) -> int:
        """numba threads of each worker process (``threads_per_worker``)."""
        return threads_per_worker(self.n_workers)

    def pool(self):
        if self._pool is None:
            import multiprocessing
            from concurrent.futures import ProcessPoolExecutor

            self._pool = ProcessPoolExecutor(self.n_workers, mp_context=multiprocessing.get_context("spawn"),
                                             initializer=_start_worker,
                                             initargs=(self.threads, self.kernel_sets))
        return self._pool

    def start(self) -> "Scheduler":
        """Spawn the worker processes now (on "processes"; a no-op otherwise), without waiting."""
        if self.name == "processes" and self._pool is None:
            pool = self.pool()
            self._ready = [pool.submit(_ready) for _ in range(self.n_workers)]
        return self

    def wait_ready(self, timeout: float = 600.0) -> dict:
        """Start the worker processes (on "processes") and wait until every one has run its
        initializer (imports, kernels loaded): a ``Session`` shared by several runs pays its
        start-up once, here, instead of inside its first run's budget.  Returns the start-up:
        ``wall_seconds`` (waited here), ``workers`` and ``worker_seconds`` / ``worker_cpu_seconds``
        (summed over the workers; zero on the other schedulers, which start nothing here)."""
        t0 = time.perf_counter()
        out = {"workers": 0, "wall_seconds": 0.0, "worker_seconds": 0.0, "worker_cpu_seconds": 0.0}
        if self.name != "processes":
            return out
        self.start()
        for f in self._ready:  # every worker spawned
            f.result(timeout=timeout)
        self._ready = []
        seen: set[int] = set()
        while len(seen) < self.n_workers:
            if time.perf_counter() - t0 > timeout:
                raise TimeoutError(f"{self.n_workers - len(seen)} of {self.n_workers} workers did not start in {timeout:.0f} s")
            # one answer per worker, each held a moment so that a started worker does not answer
            # for a sibling still starting (then the round is asked again)
            for f in [self._pool.submit(_ready, 0.05, True) for _ in range(self.n_workers)]:
                pid, start = f.result(timeout=max(1.0, timeout - (time.perf_counter() - t0)))
                seen.add(pid)
                out["worker_seconds"] += start["start_seconds"]
                out["worker_cpu_seconds"] += start["start_cpu_seconds"]
        out.update(workers=len(seen), wall_seconds=time.perf_counter() - t0)
        return out

    def close(self):
        if self._pool is not None:
            self._pool.shutdown(wait=True, cancel_futures=True)
            self._pool = None

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()


#: A scheduler (and its process pool) shared by several runs; use as a context manager.
Session = Scheduler


@dataclass(frozen=True)
class Task:
    """One task: ``func(*args)``, a module-level function and picklable arguments; ``key``
    names it (``pipeline-...``) on dask's schedulers."""

    key: str
    func: Callable
    args: tuple


def compute(tasks: list[Task], scheduler: Scheduler, progress: Progress) -> list:
    """Run ``tasks`` on ``scheduler``; their results in order.  ``progress`` is advanced once
    per finished task.

    On "processes" the tasks go straight to the scheduler's pool in the order given (so a kind
    can put its longest tasks first), all queued at once; on the other schedulers through dask
    (``dask.delayed``).  The first task to raise cancels those not yet started and raises here.
    """
    if scheduler.name == "processes":
        from concurrent.futures import FIRST_EXCEPTION, wait

        pool = scheduler.pool()
        futures = [pool.submit(t.func, *t.args) for t in tasks]
        index = {f: i for i, f in enumerate(futures)}
        results = [None] * len(futures)
        todo = set(futures)
        try:
            while todo:
                done, todo = wait(todo, return_when=FIRST_EXCEPTION)
                for f in done:
                    results[index[f]] = f.result()  # raises the task's exception
                    progress.update()
        except BaseException:
            for f in futures:
                f.cancel()
            raise
        return results
    import dask

    delayed = [dask.delayed(t.func, pure=False)(*t.args, dask_key_name=t.key) for t in tasks]
    if scheduler.distributed:
        from distributed import Client, as_completed

        with Client(scheduler.name, set_as_default=False) as client:
            futures = client.compute(delayed)
            index = {f.key: i for i, f in enumerate(futures)}
            results = [None] * len(futures)
            for fut in as_completed(futures, loop=client.loop):
                results[index[fut.key]] = fut.result()
                progress.update()
            return results
    from dask.callbacks import Callback

    class _Count(Callback):
        def _posttask(self, key, result, dsk, state, worker_id):
            if isinstance(key, str) and key.startswith("pipeline-"):
                progress.update()

    kwargs = {"scheduler": scheduler.name}
    if scheduler.name == "threads":
        kwargs["num_workers"] = scheduler.n_workers
    with _Count():
        return list(dask.compute(*delayed, **kwargs))
