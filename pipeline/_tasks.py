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

__all__ = ["compute_chunk", "compute_series"]


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


def compute_series(store: str, scene: Scene) -> int:
    """Solve the scene's series points and write u(tau), resampled to uniform nodes tau_k = k/n_tau
    by periodic linear interpolation of the solver's final grid. Returns the number of failures."""
    import warnings

    import zarr

    s = scene.series
    params = {d: np.array([dict(p)[d] for p in s.points], dtype=np.float64) for d in scene.dims}
    for k, v in scene.fixed:
        params[k] = np.full(len(s.points), v)
    out = solve_points(scene.family, params, (), method=scene.method, rtol=scene.rtol, series=True)
    tau = np.arange(s.n_tau) / s.n_tau
    u = np.full((len(s.points), s.n_tau), np.nan)
    for i, (ui, ti) in enumerate(zip(out["u"], out["tau"])):
        if out["status"][i] == 0 and ui.size:
            u[i] = np.interp(tau, ti, ui, period=1.0)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        zarr.open_array(store=store, path="series_u", mode="r+")[...] = u
        zarr.open_array(store=store, path="series_status", mode="r+")[...] = out["status"]
    return int(np.count_nonzero(out["status"] != 0))
