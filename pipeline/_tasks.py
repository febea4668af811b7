"""Work done inside dask tasks: one chunk of the grid, or the polishing of a few optima.

Tasks receive only picklable arguments (paths, the frozen scene, indices) and open the store
themselves, so they run unchanged on the local schedulers and on a dask.distributed cluster
sharing the file system.
"""

from __future__ import annotations

import os
import time
from pathlib import Path

import numpy as np

from ._grid import chunk_region, region_parameters, solve_points
from ._scene import Scene
from ._store import mark_done, write_region

__all__ = ["compute_chunk"]


def compute_chunk(store: str, scene: Scene, chunks: tuple[int, ...], index: tuple[int, ...]) -> dict:
    """Solve every point of chunk ``index``, write its outputs, then mark it done.

    Returns
    -------
    dict
        ``points``, ``failures`` (nonzero status) and ``seconds`` spent in the solver.
    """
    store_path = Path(store)
    region = chunk_region(index, scene.shape, chunks)
    params = region_parameters(scene, region)
    t0 = time.perf_counter()
    values = solve_points(scene.family, params, scene.outputs, method=scene.method, rtol=scene.rtol)
    seconds = time.perf_counter() - t0
    rshape = tuple(sl.stop - sl.start for sl in region)
    values = {k: np.asarray(v).reshape(rshape) for k, v in values.items()}
    write_region(store_path, region, index, chunks, scene.shape, values)
    # Test hook: widen the window between data and marker, where a kill leaves a half-done chunk.
    time.sleep(float(os.environ.get("TWOLINK_PIPELINE_MARKER_DELAY", "0") or 0))
    mark_done(store_path, index)  # last: a chunk without its marker is recomputed on resume
    return {"points": int(np.prod(rshape)), "failures": int(np.count_nonzero(values["status"] != 0)),
            "seconds": seconds}
