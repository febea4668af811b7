"""Polish of a grid reduction's maxima: from the best few distinct grid basins, a bounded local
method to a relative value tolerance, with a record that says whether it converged.

Modules: ``space`` (the box of the continuous ``over`` axes), ``starts`` (distinct grid
basins), ``local`` (the local method), ``record`` (value, arg-max, evaluations, status,
uncertainty, edges). ``polish_cells`` is the entry point the pipeline's tasks call.
"""

from __future__ import annotations

import numpy as np

from .local import METHODS, LocalResult, maximise
from .record import CAPPED, CONVERGED, FAILED, STATUS_MEANINGS, cell_record
from .space import EDGE_FRACTION, PolishSpace
from .starts import distinct_starts, face_starts

__all__ = ["polish_cells", "polish_rtol", "PolishSpace", "distinct_starts", "maximise", "LocalResult",
           "cell_record", "face_starts", "METHODS", "STATUS_MEANINGS", "CONVERGED", "CAPPED", "FAILED", "EDGE_FRACTION",
           "solve_objective"]


def polish_rtol(scene, r) -> float:
    """The solver rtol while polishing reduction ``r`` (its ``polish_rtol``, else the grid's)."""
    return r.polish_rtol if r.polish_rtol is not None else scene.rtol


def solve_objective(scene, r, params: dict, rtol: float) -> tuple[float, dict]:
    """The objective of ``r`` at one point (every parameter) and its record
    ``{"params", "values", "status"}``: one solver call; -inf where the solve failed."""
    from .._grid import solve_points
    from .._reduce import objective

    outputs = (r.quantity,) + tuple(n for n in r.report if n != r.quantity)
    arrays = {k: np.array([v], dtype=np.float64) for k, v in params.items()}
    vals = solve_points(scene.family, arrays, outputs, method=scene.method, rtol=rtol)
    o = float(objective(r.statistic, vals[r.quantity])[0])
    status = int(vals["status"][0])
    if status != 0:
        o = -np.inf
    return o, {"params": dict(params), "status": status, "values": {k: float(vals[k][0]) for k in outputs}}


def polish_cells(scene, r, cells: list[dict], *, tolerance: float | None = None,
                 max_evaluations: int | None = None, method: str | None = None,
                 rtol: float | None = None) -> list[dict]:
    """Polish every cell of reduction ``r``.

    Parameters
    ----------
    cells : list of dict
        ``{"starts": [params, ...], "subset": int | None, "group": hashable}``, the start points
        best first (every parameter of each, ``starts.distinct_starts``); ``{"params": ...}``
        alone is one start.  Cells of one ``group`` (the subsets of one grid cell, in the order
        of the subsets) are polished in order, each also from the last earlier one's optimum
        that lies in its domain (``PolishSpace.inside``).
    tolerance, max_evaluations, method, rtol :
        Override the scene's ``polish_tolerance``, ``polish_max_evaluations`` (per start),
        ``polish_method`` and polish rtol (for measurements and tests).

    Returns
    -------
    list of dict, one per cell (``record.cell_record``): the best point over every start. The
    continuous ``over`` axes move (log2 axes in log2) inside the axes' range and the subset's
    window; the discrete ones stay at their start's values.
    """
    tol = r.polish_tolerance if tolerance is None else tolerance
    cap = r.polish_max_evaluations if max_evaluations is None else max_evaluations
    how = r.polish_method if method is None else method
    rt = polish_rtol(scene, r) if rtol is None else rtol
    space = PolishSpace(scene, r)
    out = []
    polished: dict = {}  # group -> arg-max of the cells of that group polished so far
    for cell in cells:
        starts = list(cell.get("starts") or [cell["params"]])
        group = cell.get("group")
        # The optimum of the last subset of the same grid cell polished before whose optimum lies
        # in this one's domain (the next narrower window, the next smaller exponent set) starts
        # here too: over nested subsets the maximum is then never below a narrower one's (by
        # induction; one seed, not all of them: duty_cycle's 10 windows doubled its cost so).
        inside = [p for p in polished.get(group, []) if space.inside(p, cell["subset"])] if group is not None else []
        if inside and inside[-1] not in starts:
            starts.append(inside[-1])
        bounds = space.bounds(cell["subset"])
        results = []
        for base in starts:
            def fun(x, base=base):
                return solve_objective(scene, r, space.params(base, x), rt)

            results.append(maximise(fun, space.to_x(base), bounds, space.step, tolerance=tol,
                                    max_evaluations=cap, method=how))
        rec = cell_record(space, starts, results, cell["subset"])
        if group is not None and rec["values"] is not None:
            polished.setdefault(group, []).append(rec["params"])
        out.append(rec)
    return out
