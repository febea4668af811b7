"""Where tasks run: the dask schedulers, a shared worker pool, and a text progress bar.

``compute(tasks, scheduler, progress)`` runs a list of :class:`Task` on a pool of worker
processes ("processes", the default: the tasks go to the pool directly, in the order given),
on one of dask's other local schedulers ("threads", "synchronous") or on a dask.distributed
cluster ("tcp://host:port", also "tls://", "inproc://", "ucx://") and returns their results in
order.  Tasks are keyed ``pipeline-...`` so the progress bar counts them and nothing else.

The progress bar moves as each task finishes, on every scheduler.  The pool's worker processes
end when their driver dies, by any signal (SIGKILL included: :func:`watch_parent`), and ignore
Ctrl-C, which the driver handles (it ends them itself: ``Scheduler.close(kill=True)``).
"""

from __future__ import annotations

import contextlib
import os
import signal
import sys
import threading
import time
from dataclasses import dataclass
from typing import Callable

__all__ = ["CONNECT_SECONDS", "DISTRIBUTED_PREFIXES", "LOCAL_SCHEDULERS", "Progress", "Scheduler",
           "SchedulerUnavailable", "Session", "Task", "compute", "threads_per_worker", "usable_cores",
           "watch_parent"]

LOCAL_SCHEDULERS = ("processes", "threads", "synchronous")
#: addresses of a dask.distributed scheduler
DISTRIBUTED_PREFIXES = ("tcp://", "inproc://", "tls://", "ucx://")
#: seconds a dask.distributed scheduler has to answer (and to have a worker) before a run is
#: refused, with nothing written (dask's own default is 30 s)
CONNECT_SECONDS = 5.0
#: seconds between a worker's checks that its driver is alive (:func:`watch_parent`)
PARENT_POLL_SECONDS = 0.5


class SchedulerUnavailable(RuntimeError):
    """The scheduler named cannot run tasks: a cluster that does not answer, or has no worker."""


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


#: ``prctl`` option: the signal the kernel sends this process when its parent thread ends
_PR_SET_PDEATHSIG = 1


def watch_parent(parent_pid: int, *, death_signal: bool = False, interval: float = PARENT_POLL_SECONDS) -> None:
    """End this process (a pool's worker) when the process ``parent_pid`` (its driver) dies, by
    any signal, SIGKILL included: a killed driver left its workers (188 MB each) and the
    multiprocessing resource tracker running for minutes (issue 45).

    Two watches: on Linux, where ``death_signal`` (the worker was spawned from the driver's
    main thread, whose end is the process's), the kernel sends SIGKILL at once
    (``prctl(PR_SET_PDEATHSIG)``, through ctypes); everywhere, a daemon thread compares
    ``os.getppid()`` with ``parent_pid`` every ``interval`` seconds (an orphan is adopted by
    another process) and exits.  A driver already gone when this is called ends it at once."""
    if death_signal and sys.platform.startswith("linux"):
        try:
            import ctypes

            ctypes.CDLL(None, use_errno=True).prctl(_PR_SET_PDEATHSIG, int(signal.SIGKILL), 0, 0, 0)
        except (OSError, AttributeError):
            pass  # the polling below still holds
    if os.getppid() != parent_pid:
        os._exit(1)

    def poll():
        while True:
            time.sleep(interval)
            if os.getppid() != parent_pid:
                os._exit(1)

    threading.Thread(target=poll, name="twolink-parent-watch", daemon=True).start()


def _start_worker(threads: int, kernel_sets: tuple[str, ...], parent_pid: int | None = None,
                  death_signal: bool = False) -> None:
    """Initializer of a pool's worker process: it watches its driver (:func:`watch_parent`) and
    leaves Ctrl-C to it, sets its numba thread count, then loads the solver and its kernels once,
    before any task (so no task's timing pays for them)."""
    t0, c0 = time.perf_counter(), time.process_time()
    if parent_pid is not None:  # a pool's worker (not a test calling this in its own process)
        watch_parent(parent_pid, death_signal=death_signal)
        signal.signal(signal.SIGINT, signal.SIG_IGN)  # the driver handles Ctrl-C and ends its workers
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


@contextlib.contextmanager
def _sigint_ignored(here: bool):
    """SIGINT ignored in this process for the block (``here``: the main thread, the only one
    that may set a handler): processes spawned inside inherit the disposition through exec and
    keep it, so a Ctrl-C that reaches a worker still starting prints no traceback there."""
    if not here:
        yield
        return
    previous = signal.signal(signal.SIGINT, signal.SIG_IGN)
    try:
        yield
    finally:
        signal.signal(signal.SIGINT, previous)


class Scheduler:
    """Where tasks run: a scheduler name (or cluster address) and a local worker count.

    One process pool serves every ``compute`` on "processes" until ``close``, so each worker
    process imports the solver (and loads the compiled kernels of ``kernel_sets``) once, with
    :func:`threads_per_worker` numba threads.  ``start()`` spawns the workers at once, so they
    start while the driver prepares the store.  On a dask.distributed cluster, ``connect()``
    opens one client for the scheduler's runs (refusing, within :data:`CONNECT_SECONDS`, a
    cluster that does not answer or has no worker) and counts its workers.  Use as a context
    manager; a ``Session`` is the same object shared by several runs (``python -m pipeline
    paper``).  Leaving it by an exception that is not an error (Ctrl-C: KeyboardInterrupt)
    ends the worker processes at once instead of waiting for their tasks.
    """

    def __init__(self, name: str, workers: int | None, kernel_sets: tuple[str, ...] = ()):
        self.name, self.workers = name, workers
        self.kernel_sets = tuple(kernel_sets)
        self._pool = None
        self._ready = []
        self._client = None
        self._cluster_workers = None

    @property
    def distributed(self) -> bool:
        return self.name.startswith(DISTRIBUTED_PREFIXES)

    @property
    def n_workers(self) -> int:
        """Tasks that run at once: local workers ("processes", "threads": ``workers`` or every
        core); on a cluster its workers' threads, counted by ``connect`` (1 before); else 1."""
        if self.name in ("processes", "threads"):
            return self.workers or usable_cores()
        if self.distributed and self._cluster_workers:
            return self._cluster_workers
        return 1

    @property
    def threads(self) -> int:
        """numba threads of each worker process (``threads_per_worker``)."""
        return threads_per_worker(self.n_workers)

    def connect(self, timeout: float = CONNECT_SECONDS) -> "Scheduler":
        """On a dask.distributed cluster: open the client these runs use and count the
        cluster's task slots (the threads of its workers) for ``n_workers``.  Raises
        :class:`SchedulerUnavailable` (one line) where the scheduler does not answer within
        ``timeout`` seconds, or has no worker by then.  A no-op on the local schedulers."""
        if not self.distributed or self._client is not None:
            return self
        try:
            from distributed import Client
        except ImportError:
            raise SchedulerUnavailable(f"--scheduler {self.name}: the package 'distributed' is not "
                                       "installed (pip install distributed)") from None
        try:
            client = Client(self.name, timeout=timeout, set_as_default=False)
        except (OSError, TimeoutError, ValueError, TypeError) as exc:
            raise SchedulerUnavailable(f"--scheduler {self.name}: no dask scheduler answers there within "
                                       f"{timeout:g} s ({' '.join(str(exc).split()) or type(exc).__name__}); "
                                       "start the cluster first, or choose another --scheduler") from None
        try:
            try:
                client.wait_for_workers(1, timeout=timeout)
            except (OSError, TimeoutError):
                raise SchedulerUnavailable(f"--scheduler {self.name}: the scheduler answers but has no worker "
                                           f"after {timeout:g} s; start its workers, or choose another "
                                           "--scheduler") from None
            workers = client.scheduler_info().get("workers", {})
            self._cluster_workers = max(1, sum(int(w.get("nthreads", 1)) for w in workers.values()))
        except BaseException:
            client.close()
            raise
        self._client = client
        return self

    def client(self):
        """The cluster's client (``connect``-ed on first use)."""
        return self.connect()._client

    def pool(self):
        """The process pool, its workers spawned at once from this thread (each one watches
        this process, :func:`watch_parent`, and ignores Ctrl-C from its start)."""
        if self._pool is None:
            import multiprocessing
            from concurrent.futures import ProcessPoolExecutor

            main = threading.current_thread() is threading.main_thread()
            self._pool = ProcessPoolExecutor(self.n_workers, mp_context=multiprocessing.get_context("spawn"),
                                             initializer=_start_worker,
                                             initargs=(self.threads, self.kernel_sets, os.getpid(), main))
            with _sigint_ignored(main):
                # a submitted call spawns a worker while none is idle: all of them here, in this thread
                self._ready = [self._pool.submit(_ready) for _ in range(self.n_workers)]
        return self._pool

    def start(self) -> "Scheduler":
        """Spawn the worker processes now (on "processes"; a no-op otherwise), without waiting."""
        if self.name == "processes":
            self.pool()
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

    def worker_pids(self) -> list[int]:
        """Process ids of the pool's workers (none on the other schedulers)."""
        return sorted(getattr(self._pool, "_processes", None) or {}) if self._pool is not None else []

    def close(self, kill: bool = False):
        """Shut the pool down (waiting for the tasks running; ``kill``: ending its worker
        processes at once, as after Ctrl-C) and close a cluster's client."""
        if self._pool is not None:
            if kill:
                for process in list((getattr(self._pool, "_processes", None) or {}).values()):
                    with contextlib.suppress(OSError, ValueError, AttributeError):
                        process.kill()
            self._pool.shutdown(wait=True, cancel_futures=True)
            self._pool = None
        if self._client is not None:
            client, self._client = self._client, None
            with contextlib.suppress(Exception):
                client.close()

    def __enter__(self):
        return self

    def __exit__(self, exc_type, exc, tb):
        self.close(kill=exc_type is not None and not issubclass(exc_type, Exception))


#: A scheduler (and its process pool) shared by several runs; use as a context manager.
Session = Scheduler


@dataclass(frozen=True)
class Task:
    """One task: ``func(*args)``, a module-level function and picklable arguments; ``key``
    names it (``pipeline-...``) on dask's schedulers."""

    key: str
    func: Callable
    args: tuple


def compute(tasks: list[Task], scheduler: Scheduler, progress: Progress, on_result=None) -> list:
    """Run ``tasks`` on ``scheduler``; their results in order.  ``progress`` is advanced as each
    task finishes, on every scheduler (on "processes" it waited for the first exception or the
    last task, so the bar stood still, then printed every line at once: issue 45), and
    ``on_result(i, result)`` is called, in this thread, with each task's result as it comes
    (the driver writes the finished chunks there: ``_store.ChunkWriter``); an exception it
    raises stops the run as a task's does.

    On "processes" the tasks go straight to the scheduler's pool in the order given (so a kind
    can put its longest tasks first), all queued at once; on the other schedulers through dask
    (``dask.delayed``).  The first task to raise cancels those not yet started and raises here,
    and so does an interrupt (Ctrl-C).
    """
    if scheduler.name == "processes":
        from concurrent.futures import as_completed

        pool = scheduler.pool()
        futures = [pool.submit(t.func, *t.args) for t in tasks]
        index = {f: i for i, f in enumerate(futures)}
        results = [None] * len(futures)
        try:
            for f in as_completed(futures):
                results[index[f]] = f.result()  # raises the task's exception
                if on_result is not None:
                    on_result(index[f], results[index[f]])
                progress.update()
        except BaseException:
            for f in futures:
                f.cancel()
            raise
        return results
    import dask

    delayed = [dask.delayed(t.func, pure=False)(*t.args, dask_key_name=t.key) for t in tasks]
    if scheduler.distributed:
        from distributed import as_completed

        client = scheduler.client()
        futures = client.compute(delayed)
        index = {f.key: i for i, f in enumerate(futures)}
        results = [None] * len(futures)
        try:
            for fut in as_completed(futures, loop=client.loop):
                results[index[fut.key]] = fut.result()
                if on_result is not None:
                    on_result(index[fut.key], results[index[fut.key]])
                progress.update()
        except BaseException:
            with contextlib.suppress(Exception):
                client.cancel(futures)
            raise
        return results
    from dask.callbacks import Callback

    index = {t.key: i for i, t in enumerate(tasks)}

    class _Count(Callback):
        # called by dask's local scheduler in the thread that called dask.compute (this one)
        def _posttask(self, key, result, dsk, state, worker_id):
            if isinstance(key, str) and key in index:
                if on_result is not None:
                    on_result(index[key], result)
                progress.update()

    kwargs = {"scheduler": scheduler.name}
    if scheduler.name == "threads":
        kwargs["num_workers"] = scheduler.n_workers
    with _Count():
        return list(dask.compute(*delayed, **kwargs))
