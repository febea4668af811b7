"""The scene-kind protocol: what the driver (``pipeline._run``) needs of one kind of scene.

A run is a chain of small named steps, the same for every kind (pangeo-forge-recipes'
``StoreToZarr`` is the model)::

    lock the store -> open or create its skeleton -> pending chunks -> check their blocks ->
    fan out tasks of their blocks, the driver writing each chunk once whole -> the kind's
    driver-side steps (series, reductions) -> run record, consolidation

Two units (``_store``): a *block* is what a task solves at a time, a *chunk* what the store
keeps in one file per array (whole blocks, ~1 MiB), the unit of resuming.  A kind supplies
the parts that differ:

* ``create_skeleton(run)``: every array, coordinate and attribute of an empty store, before
  any task runs (``pipeline.kind`` names the kind; format-1 grid stores carry no kind): the
  kind's own arrays between ``_store.new_group`` and ``_store.finish_skeleton`` (done
  markers, provenance, layout, state: the same for every kind);
* ``block_layout(scene)``: the block shape the scene's store must have, a function of the
  scene alone (never of a timing); a store of other blocks with chunks still to compute is
  refused.  ``None`` (the default): whatever the kind's skeleton chose;
* ``pending_chunks(store)``: the (storage) chunk indices without their done marker;
* ``chunks_per_task(run, blocks, pending)``: how many consecutive pending blocks one task
  computes (default 1); it moves no block boundary, so no stored value depends on it;
* ``solve_chunk(scene, blocks, index)``: a module-level function, run inside a task
  (picklable arguments only), that computes block ``index`` of the layout ``blocks`` and
  returns a ``_store.SolvedChunk`` (its writes, points, failures, seconds solving); the
  shared mechanics (``_store.ChunkWriter``, in the driver) write each chunk whole once its
  blocks are back, make it durable, then set its done marker, for every kind alike;
* ``chunk_cost(scene, index)``: relative cost of block ``index`` where the kind can tell
  (tasks run longest first; default: equal);
* ``steps(scene)``: driver-side :class:`Step` objects after the chunks (reductions), each
  owning one flag of ``pipeline.state`` (a step's ``run`` may return its tasks' timings, for
  the run's time budget);
* ``failures(store, scene)``: the count the run summary reports;
* ``kernel_sets(scene)``: the solver kernel sets its tasks use, loaded once per worker
  process when its pool starts (``_schedule.Scheduler``; compiled once, by one of them, when
  numba's cache is empty), or in the driver where it runs the tasks itself.

Which report section shows a store is for ``reports`` to choose from the store's kind; the
pipeline never imports ``reports`` for it.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Callable

import numpy as np

from ._schedule import Scheduler
from ._store import read_done

__all__ = ["RunContext", "SceneKind", "Step", "TASKS_PER_WORKER", "tasks_by_count"]

#: tasks per worker at least, where a scene has the chunks for them: the last tasks then leave
#: cores idle briefly (and a task of several chunks writes each while it solves the next)
TASKS_PER_WORKER = 16


def tasks_by_count(chunk_points: int, task_points: int, pending: int, workers: int) -> int:
    """Chunks per task: as many as fit in ``task_points`` points, but at least
    ``TASKS_PER_WORKER`` tasks per worker where ``pending`` chunks allow; at least one.  From
    counts alone: no timing moves a task boundary (nor, ever, a chunk's)."""
    fit = max(1, int(task_points) // max(1, int(chunk_points)))
    return max(1, min(fit, int(pending) // (TASKS_PER_WORKER * max(1, int(workers)))))


@dataclass(frozen=True)
class RunContext:
    """One scene's run as its kind's skeleton and steps see it.

    ``n_workers`` is the parallelism the run plans for (``--workers``, else every core on the
    local pools, else 1); ``echo(message, file=...)`` prints a line for the user.
    """

    scene: object
    store: Path
    scheduler: Scheduler
    n_workers: int
    progress: bool
    echo: Callable


@dataclass(frozen=True)
class Step:
    """A driver-side step after the chunks.

    It runs when its ``state`` flag (``pipeline.state[state]``) is not set, and again after any
    run that computed chunks when ``after_chunks`` (a reduction over them; a series of its own
    points does not depend on them).  ``run(context)`` writes the step's arrays; the driver sets
    the flag after it returns, so a run killed inside a step repeats the step on resume.
    """

    name: str
    state: str
    run: Callable[[RunContext], None]
    after_chunks: bool = True


class SceneKind:
    """Base of the scene kinds (module docstring); the defaults suit any chunked store."""

    #: ``[scene] kind`` values this kind parses
    names: tuple[str, ...] = ()
    #: unit of the progress bar's rate
    rate_unit = "solves/s"
    #: computes one chunk, unwritten: a module-level function (picklable by reference)
    solve_chunk: Callable[..., object]

    def parse(self, doc: dict, ctx, text: str):
        """The validated scene of the TOML document ``doc`` (``ctx``: a ``ParseContext``)."""
        raise NotImplementedError

    def create_skeleton(self, run: RunContext) -> None:
        raise NotImplementedError

    def block_layout(self, scene) -> tuple[int, ...] | None:
        """The block shape of ``scene``'s store, from the scene alone; None: not checked."""
        return None

    def chunks_per_task(self, run: RunContext, chunks: tuple[int, ...], pending: list) -> int:
        """Consecutive pending blocks one task computes."""
        return 1

    def pending_chunks(self, store: Path) -> list[tuple[int, ...]]:
        """Storage chunk indices (C order) whose done marker is not set."""
        done = read_done(store)
        return [tuple(int(i) for i in idx) for idx in zip(*np.nonzero(~done))]

    def chunk_cost(self, scene, index: tuple[int, ...]) -> float:
        """Relative cost of block ``index`` where the kind can tell it from the scene (tasks
        run longest first); equal by default (tasks run in block order)."""
        return 0.0

    def steps(self, scene) -> tuple[Step, ...]:
        return ()

    def failures(self, store: Path, scene) -> int:
        raise NotImplementedError

    def kernel_sets(self, scene) -> tuple[str, ...]:
        """Solver kernel sets the tasks use (keys of ``solver.KERNEL_SETS``)."""
        return ("periodic",)
