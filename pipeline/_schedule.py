"""Where tasks run: the dask schedulers, a shared worker pool, and a text progress bar.

``compute(tasks, scheduler, progress)`` runs a list of ``dask.delayed`` tasks on one of dask's
local schedulers ("processes", "threads", "synchronous") or on a dask.distributed cluster
("tcp://host:port", also "tls://", "inproc://", "ucx://") and returns their results in order.
Tasks are keyed ``pipeline-...`` so the progress bar counts them and nothing else.
"""

from __future__ import annotations

import os
import sys
import time

__all__ = ["DISTRIBUTED_PREFIXES", "LOCAL_SCHEDULERS", "Progress", "Scheduler", "Session", "compute"]

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


class Scheduler:
    """Where tasks run: a scheduler name (or cluster address) and a local worker count.

    One process pool serves every ``compute`` on "processes" until ``close``, so each worker
    process imports the solver (and loads its compiled kernels) once.  Use as a context manager;
    a ``Session`` is the same object shared by several runs (``python -m pipeline paper``).
    """

    def __init__(self, name: str, workers: int | None):
        self.name, self.workers = name, workers
        self._pool = None

    @property
    def distributed(self) -> bool:
        return self.name.startswith(DISTRIBUTED_PREFIXES)

    @property
    def n_workers(self) -> int:
        """Local workers ("processes", "threads": ``workers`` or every core); 1 otherwise."""
        if self.name in ("processes", "threads"):
            return self.workers or os.cpu_count() or 1
        return 1

    def pool(self):
        if self._pool is None:
            import multiprocessing
            from concurrent.futures import ProcessPoolExecutor

            self._pool = ProcessPoolExecutor(self.n_workers, mp_context=multiprocessing.get_context("spawn"))
        return self._pool

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


def compute(tasks, scheduler: Scheduler, progress: Progress) -> list:
    """Run the delayed ``tasks`` on ``scheduler``; their results in order.  ``progress`` is
    advanced once per finished task whose key starts with ``pipeline-``."""
    import dask

    if scheduler.distributed:
        from distributed import Client, as_completed

        with Client(scheduler.name, set_as_default=False) as client:
            futures = client.compute(tasks)
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
    if scheduler.name == "processes":
        kwargs["pool"] = scheduler.pool()
    with _Count():
        return list(dask.compute(*tasks, **kwargs))
