"""The pipeline: scenes (TOML) fanned out with dask into resumable Zarr stores, with reductions.

Public API::

    scene = pipeline.load_scene("workflows/quick.toml")     # validated, frozen
    summary = pipeline.run_scene(scene, "out/quick.zarr", scheduler="processes")
    print(summary.line())

The command line is ``python -m pipeline run workflows/<scene>.toml``.  A store is read with
``xarray.open_zarr(store)`` and exports as it is, ``xarray.open_zarr(store).to_netcdf(path)``;
its record (provenance, layout, state, run) is ``pipeline.read_record(ds.attrs)`` and any
attributes' nested values ``pipeline.decode_attrs(attrs)``.
"""

from ._attrs import decode_attrs, read_record
from ._export import cf_dataset, to_netcdf
from ._grid_scene import Reduction, Scene, Series
from ._kind import RunContext, SceneKind, Step
from ._registry import KINDS, load_scene, parse_scene
from ._run import RunSummary, default_store, run_scene
from ._scene import Axis, Execution, SceneError
from ._schedule import Session
from ._store import StoreBusy, StoreMismatch

__all__ = ["Axis", "Execution", "KINDS", "Reduction", "RunContext", "RunSummary", "Scene", "SceneError", "SceneKind",
           "Series", "Session", "Step", "StoreBusy", "StoreMismatch", "default_store", "load_scene", "parse_scene",
           "cf_dataset", "decode_attrs", "read_record", "run_scene", "to_netcdf"]
