"""``python -m pipeline estimate``: a scene's run time projected from a timed probe, for every kind.

The probe runs, in this process and on one core (one numba thread), a sample of the scene's
own chunks through its kind's ``solve_chunk`` (the code a run's tasks execute, in the store's
chunk layout, nothing written), and for a grid scene's polished reductions the polish of a
few cells started from the best basins of each probed chunk (``pipeline.polish.polish_cells``, as the
run's polish tasks call it).  Each part is projected as (its units) x (the probed mean per
unit), summed over the kind's cost classes (``SceneKind.chunk_cost``: the optima's Kmax), and
divided over the workers.  Before issue 45 only the grid points were probed: the optima,
studies and polishing (most of the paper's time) were left out.

The probe's clock is this process's CPU time (``time.process_time``, one numba thread): what
the work costs a free core, whatever else the machine runs meanwhile (on the shared 2-core
machine of issue 45, at a third of a core, its wall time read 3x the run's).  The chunks probed
are spread over the scene (every prefix of :func:`spread_order` is), one of every cost class
first; the probe stops at ``max_chunks`` or, once every class has one, after ``budget_seconds``
of it.  Not projected: worker start-up, writes, scheduling and the driver's steps besides
polishing (series, reductions; seconds each), contention, and a wall-time cap
met sooner on a loaded machine (the accuracy study's scipy baseline).
"""

from __future__ import annotations

import tempfile
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np

__all__ = ["PartEstimate", "SceneEstimate", "estimate_scene", "spread_order"]


@dataclass(frozen=True)
class PartEstimate:
    """One part of a scene's work: ``count`` units (``unit``: chunks, cells) of which ``probed``
    were timed in ``probe_seconds``; ``core_seconds`` projected for all of them on one core;
    ``longest_seconds`` the longest unit timed (no worker can finish a part sooner)."""

    name: str
    unit: str
    count: int
    probed: int
    core_seconds: float
    probe_seconds: float
    longest_seconds: float
    #: points (grid solves, optimisations, study points) in all of the part's units
    points: int = 0


@dataclass(frozen=True)
class SceneEstimate:
    """The projection of one scene: its parts (chunks first, then each polished reduction)."""

    scene: str
    kind: str
    points: int
    point_unit: str
    parts: tuple[PartEstimate, ...]

    @property
    def core_seconds(self) -> float:
        return float(sum(p.core_seconds for p in self.parts))

    @property
    def probe_seconds(self) -> float:
        return float(sum(p.probe_seconds for p in self.parts))

    def wall_seconds(self, workers: int) -> float:
        """Projected wall time on ``workers`` parallel workers (each part divided over them,
        but no shorter than its longest unit)."""
        w = max(1, int(workers))
        return float(sum(max(p.core_seconds / w, p.longest_seconds) for p in self.parts))


def spread_order(n: int) -> list[int]:
    """0 .. n-1 in an order whose every prefix is spread over the range: the midpoint, then the
    quarters, the eighths, ... (so a probe cut short still samples the whole scene)."""
    order, seen = [], set()
    level = 1
    while len(order) < n:
        for k in range(1, 2 * level, 2):
            i = min(n - 1, int(k * n / (2 * level)))
            if i not in seen:
                seen.add(i)
                order.append(i)
        level *= 2
        if level > 2 * n:  # every index reached by now; the rest in order
            order += [i for i in range(n) if i not in seen]
            break
    return order


def _probe_order(indices: list[tuple[int, ...]], cost) -> tuple[list[tuple[int, ...]], dict]:
    """The chunks to probe, in order: one of every cost class, spread within it, then the next
    round; and {cost class: chunks in it}."""
    classes: dict[float, list[tuple[int, ...]]] = {}
    for idx in indices:
        classes.setdefault(float(cost(idx)), []).append(idx)
    spreads = {c: [members[i] for i in spread_order(len(members))] for c, members in classes.items()}
    order = []
    for r in range(max(len(v) for v in spreads.values())):
        order += [v[r] for v in spreads.values() if r < len(v)]
    return order, classes


def _one_thread():
    """numba's threads set to one for the probe (per-core rates), restored after."""
    import contextlib

    @contextlib.contextmanager
    def ctx():
        import numba

        before = numba.get_num_threads()
        numba.set_num_threads(1)
        try:
            yield
        finally:
            numba.set_num_threads(before)

    return ctx()


def _skeleton(scene, kind, folder: Path):
    """An empty store of ``scene`` in ``folder`` (the kind's own skeleton: its blocks come from
    the code a run uses); its block layout and every block index (the tasks' units)."""
    from ._kind import RunContext
    from ._store import blocks_in, store_meta

    store = folder / "probe.zarr"
    kind.create_skeleton(RunContext(scene, store, None, 1, False, print))
    layout = store_meta(store)["layout"]
    shape, blocks, chunks = (tuple(int(n) for n in layout[k]) for k in ("shape", "blocks", "chunks"))
    return blocks, [b for c in kind.pending_chunks(store) for b in blocks_in(c, shape, blocks, chunks)]


def _solve(kind, scene, chunks, index) -> tuple[int, dict]:
    """Chunk ``index`` of the layout ``chunks`` computed as a run's task computes it, nothing
    written: its points, and its values (the first write's arrays, each of the chunk's region:
    a grid chunk's outputs).  The one place the probe meets the kinds' task protocol."""
    solved = kind.solve_chunk(scene, chunks, index)
    return int(solved.points), solved.writes[0].values


def _polish_cell(scene, r, chunks, index, values) -> dict | None:
    """A polish cell at the best point of the probed chunk ``index`` for reduction ``r`` (the
    run polishes from the best grid point of a cell), or None where the chunk has no valid
    point (or, for a reduction over subsets, none inside any subset)."""
    from ._grid import chunk_region, region_parameters
    from ._reduce import objective

    region = chunk_region(index, scene.shape, chunks)
    score = objective(r.statistic, values[r.quantity].reshape(-1))
    k = int(np.argmax(score))
    if not np.isfinite(score[k]):
        return None
    allp = region_parameters(scene, region)
    params = {name: float(v[k]) for name, v in allp.items()}
    starts = _chunk_starts(scene, r, region, score, k, allp)
    subset = None
    if r.subsets is not None:
        subset = next((j for j, masks in enumerate(r.subsets.masks(scene))
                       if all(m[int(np.argmin(np.abs(scene.axis(a).array() - params[a])))]
                              for a, m in masks.items())), None)
        if subset is None:
            return None
    return {"starts": starts, "subset": subset, "value": float(score[k])}


def _chunk_starts(scene, r, region, score, k, allp) -> list[dict]:
    """Starts as a run takes them (``_reduce.polish_starts``: distinct basins, then faces), found
    among the chunk's points at the kept position of its best point k, best first; a probe sees
    only its chunk, so a run's cell has these or more."""
    from .polish import distinct_starts, face_starts

    rshape = tuple(sl.stop - sl.start for sl in region)
    dims = scene.dims
    pos = np.unravel_index(k, rshape)
    sel = tuple(slice(None) if d in r.over else int(i) for d, i in zip(dims, pos))
    block = score.reshape(rshape)[sel]
    flat_ids = np.arange(score.size).reshape(rshape)[sel]
    cont = tuple(scene.axis(d).continuous for d in dims if d in r.over)
    found = distinct_starts(block, cont, r.polish_starts)
    found += face_starts(block, cont, found)
    return [{name: float(v[int(flat_ids.flat[j])]) for name, v in allp.items()} for j in found]


def _cells(scene, r) -> int:
    """Cells of reduction ``r`` a run polishes at most: every kept grid position (x subset)."""
    n = int(np.prod([a.size for a in scene.axes if a.name not in r.over], dtype=np.int64))
    return n * (len(r.subsets.labels) if r.subsets is not None else 1)


def estimate_scene(scene, *, max_chunks: int = 8, budget_seconds: float = 10.0,
                   max_cells: int = 4, clock=time.process_time) -> SceneEstimate:
    """Probe ``scene`` (module docstring) and project its run time.

    Parameters
    ----------
    max_chunks : chunks timed at most (at least one of every cost class).
    budget_seconds : no further chunk is started once the probe has spent this long (``clock``
        seconds) and has one of every cost class.
    max_cells : cells polished at most per polished reduction (grid scenes).
    clock : the probe's clock (default CPU seconds of this process).
    """
    from ._registry import kind_of

    kind = kind_of(scene)
    with tempfile.TemporaryDirectory(prefix="twolink-estimate-") as tmp, _one_thread():
        import solver

        solver.warm_up(kind.kernel_sets(scene))  # untimed: a run's workers load them once too
        chunks, indices = _skeleton(scene, kind, Path(tmp))
        order, classes = _probe_order(indices, lambda idx: kind.chunk_cost(scene, idx))
        timed: dict[float, list[float]] = {c: [] for c in classes}
        points: dict[float, list[int]] = {c: [] for c in classes}
        solved_chunks = []
        t_start = clock()
        for idx in order:
            have_all = all(timed.values())
            if have_all and (sum(map(len, timed.values())) >= max(1, max_chunks)
                             or clock() - t_start >= budget_seconds):
                break
            c = float(kind.chunk_cost(scene, idx))
            t0 = clock()
            n, values = _solve(kind, scene, chunks, idx)
            timed[c].append(clock() - t0)
            points[c].append(n)
            solved_chunks.append((idx, values))
        probe = clock() - t_start
        core = sum(len(classes[c]) * float(np.mean(timed[c])) for c in classes)
        n_points = int(sum(len(classes[c]) * float(np.mean(points[c])) for c in classes))
        parts = [PartEstimate("chunks", "chunks", len(indices), len(solved_chunks), core, probe,
                              max(max(v) for v in timed.values()), n_points)]
        for r in getattr(scene, "reductions", ()):
            if not getattr(r, "polish", False):
                continue
            from .polish import polish_cells

            cells = [c for c in (_polish_cell(scene, r, chunks, idx, v) for idx, v in solved_chunks) if c][:max_cells]
            count = _cells(scene, r)
            if not cells:
                parts.append(PartEstimate(f"polish {r.name}", "cells", count, 0, 0.0, 0.0, 0.0))
                continue
            t0 = clock()
            polish_cells(scene, r, cells)  # one batch, as a polish task takes its cells
            seconds = clock() - t0
            parts.append(PartEstimate(f"polish {r.name}", "cells", count, len(cells),
                                      count * seconds / len(cells), seconds, seconds / len(cells), count))
    unit = {"grid": "points", "optima": "optimisations"}.get(scene.kind, "study points")
    return SceneEstimate(scene.name, scene.kind, int(scene.n_points), unit, tuple(parts))
