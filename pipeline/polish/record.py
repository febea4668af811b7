"""What a polish stores per cell: value, arg-max, evaluations, status, uncertainty and edges."""

from __future__ import annotations

import numpy as np

__all__ = ["CONVERGED", "CAPPED", "FAILED", "STATUS_MEANINGS", "cell_record"]

CONVERGED, CAPPED, FAILED = 0, 1, 2
#: flag meanings of ``{r}_polished_status``
STATUS_MEANINGS = {str(CONVERGED): "converged (relative value tolerance met)",
                   str(CAPPED): "evaluation cap reached (not converged)",
                   str(FAILED): "solve failed or no valid start"}


def cell_record(space, starts: list[dict], results: list, subset) -> dict:
    """Combine the runs of one cell's starts.

    Parameters
    ----------
    space : PolishSpace
    starts : list of dict  the start points (every parameter), as ``results``
    results : list of LocalResult  one per start; ``record`` is ``{"params", "values", "status"}``
    subset : int or None

    Returns
    -------
    dict with ``params`` and ``values`` of the best point, ``evaluations`` (all starts),
    ``status`` (0 converged: the best start met its value tolerance and no start reached the
    cap; 1 cap reached by any start, or the best start stopped unconverged; 2 no start gave a
    valid solve), ``uncertainty`` (the relative
    spread of the values of the starts that ended in the best one's basin, within one grid step
    of it along every free axis and on the same discrete values; where it alone ended there,
    its last relative change per iteration; NaN if unknown), ``edges`` ({axis: -1, 0, +1}) and
    ``starts`` (how many ran).
    """
    evaluations = int(sum(r.evaluations for r in results))
    ok = [k for k, r in enumerate(results) if np.isfinite(r.value) and r.record is not None
          and r.record["status"] == 0]
    if not ok:
        return {"params": dict(starts[0]) if starts else {}, "values": None, "evaluations": evaluations,
                "status": FAILED, "uncertainty": np.nan, "edges": {a: 0 for a in space.r.over},
                "starts": len(results)}
    b = max(ok, key=lambda k: results[k].value)
    best = results[b]
    params = best.record["params"]
    discrete = [a for a in space.r.over if a not in space.free]
    same = []
    for k in ok:
        p = results[k].record["params"]
        if any(p[a] != params[a] for a in discrete):
            continue
        if np.all(np.abs(space.to_x(p) - space.to_x(params)) <= space.step + 1e-12):
            same.append(results[k].value)
    if len(same) >= 2:
        uncertainty = (max(same) - min(same)) / max(abs(best.value), 1e-300)
    else:
        uncertainty = best.last_change
    # A start stopped by its cap could have climbed above the best: the cell is not converged.
    capped = any(r.capped for r in results)
    status = CAPPED if capped or not best.converged else CONVERGED
    return {"params": params, "values": best.record["values"], "evaluations": evaluations, "status": status,
            "uncertainty": float(uncertainty), "edges": space.edges(params, subset), "starts": len(results)}
