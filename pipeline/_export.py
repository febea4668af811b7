"""A store of any kind as a CF-style ``xarray.Dataset``, and as a netCDF file.

A store of format 2 (issue 34) exports as it is: ``xarray.open_zarr(store).to_netcdf(path)``
(its attributes are strings, numbers and 1-D numeric lists, :mod:`pipeline._attrs`).
:func:`cf_dataset` also takes a store of format 1, whose attributes were nested (the record as
a dict, ``flag_meanings`` as {code: meaning}, labels as lists): it opens the store with
``xarray.open_zarr`` and stores each attribute's Python view again as format 2 writes it
(:func:`pipeline._attrs.encode_attrs` of :func:`pipeline._attrs.decode_attrs`: the identity on
a format-2 store); it gives ``flag_values`` the variable's type, as CF asks (the raw route
writes them as 32-bit integers: Zarr's JSON attributes carry no type), and makes 64-bit
integers 32-bit where the values fit (netCDF 3 has no int64; the pipeline writes none).

``to_netcdf(store, path)`` writes that dataset (any xarray netCDF engine).
"""

from __future__ import annotations

import warnings
from pathlib import Path

import numpy as np

from ._attrs import decode_attrs, encode_attrs

__all__ = ["cf_dataset", "to_netcdf"]


def cf_dataset(store: str | Path):
    """The store at ``store`` (any kind, format 1 or 2) as an ``xarray.Dataset`` whose
    attributes netCDF takes."""
    import xarray as xr

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        ds = xr.open_zarr(str(store), zarr_format=3, consolidated=False)
    ds.attrs = encode_attrs(decode_attrs(dict(ds.attrs)))
    for name in list(ds.variables):
        var = ds[name]
        if var.dtype.kind in "iu" and var.dtype.itemsize == 8:
            values = var.values
            if values.size == 0 or (values.min() >= np.iinfo(np.int32).min and values.max() <= np.iinfo(np.int32).max):
                ds[name] = var.astype(np.int32)
                var = ds[name]
        attrs = encode_attrs(decode_attrs(dict(var.attrs)), var.dtype)
        if "flag_values" in attrs:  # CF: in the variable's type (Zarr's JSON attributes have none)
            attrs["flag_values"] = np.asarray(attrs["flag_values"], dtype=var.dtype)
        var.attrs = attrs
        var.encoding.pop("fill_value", None)
    return ds


def to_netcdf(store: str | Path, path: str | Path, **kwargs) -> Path:
    """Write the store at ``store`` to the netCDF file ``path`` (``xarray.Dataset.to_netcdf``'s
    ``kwargs``, e.g. ``engine``); the path written."""
    ds = cf_dataset(store)
    ds.to_netcdf(str(path), **kwargs)
    return Path(path)
