"""A store of any kind as a CF-style ``xarray.Dataset``, and as a netCDF file.

The stores keep their attributes as the pipeline and the reports read them (nested
``attrs["pipeline"]``, ``flag_meanings`` as {code: meaning}); netCDF allows only strings and
numbers (and 1-D numeric arrays) as attributes.  :func:`cf_dataset` opens a store with
``xarray.open_zarr`` and rewrites its attributes for netCDF and CF:

* a dict or a list that is not all numbers becomes its JSON text (``attrs["pipeline"]``: the
  provenance, layout, state and run record, whole);
* ``flag_meanings`` {code: meaning} becomes CF's ``flag_values`` (the codes, in the variable's
  dtype) and ``flag_meanings`` (one word per code, blank-separated), the sentences kept in
  ``flag_descriptions``;
* booleans become 0/1, None is dropped;
* 64-bit integers become 32-bit where the values fit (netCDF 3 has no int64).

``to_netcdf(store, path)`` writes that dataset (any xarray netCDF engine).
"""

from __future__ import annotations

import json
import re
import warnings
from pathlib import Path

import numpy as np

__all__ = ["cf_attrs", "cf_dataset", "to_netcdf"]


def _word(meaning: str, code: str) -> str:
    """One blank-free word for a flag meaning: its first clause, lower case, words joined by _."""
    head = re.split(r"[:;,(]", str(meaning), maxsplit=1)[0].strip().lower()
    word = re.sub(r"[^a-z0-9]+", "_", head).strip("_")
    return word or f"code_{code}"


def cf_attrs(attrs: dict, dtype=None) -> dict:
    """``attrs`` with netCDF-safe values (module docstring); ``dtype``: the variable's, for
    ``flag_values``."""
    out = {}
    for key, value in attrs.items():
        if key == "flag_meanings" and isinstance(value, dict):
            codes = sorted(value, key=lambda c: int(c))
            words, seen = [], set()
            for c in codes:
                w = _word(value[c], c)
                w = w if w not in seen else f"{w}_{c}".replace("-", "minus_")
                seen.add(w)
                words.append(w)
            out["flag_values"] = np.array([int(c) for c in codes], dtype=dtype if dtype is not None else np.int32)
            out["flag_meanings"] = " ".join(words)
            out["flag_descriptions"] = "; ".join(f"{c}: {value[c]}" for c in codes)
        elif value is None:
            continue
        elif isinstance(value, (bool, np.bool_)):
            out[key] = int(value)
        elif isinstance(value, (str, int, float, np.integer, np.floating)):
            out[key] = value
        elif isinstance(value, (list, tuple)) and value and all(
                isinstance(v, (int, float, np.integer, np.floating)) and not isinstance(v, bool) for v in value):
            out[key] = np.asarray(value)
        else:
            out[key] = json.dumps(value, sort_keys=True, default=str)
    return out


def cf_dataset(store: str | Path):
    """The store at ``store`` (any kind) as an ``xarray.Dataset`` whose attributes netCDF takes."""
    import xarray as xr

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        ds = xr.open_zarr(str(store), zarr_format=3, consolidated=False)
    ds.attrs = cf_attrs(dict(ds.attrs))
    for name in list(ds.variables):
        var = ds[name]
        if var.dtype.kind in "iu" and var.dtype.itemsize == 8:
            values = var.values
            if values.size == 0 or (values.min() >= np.iinfo(np.int32).min and values.max() <= np.iinfo(np.int32).max):
                ds[name] = var.astype(np.int32)
                var = ds[name]
        var.attrs = cf_attrs(dict(var.attrs), var.dtype)
        var.encoding.pop("fill_value", None)
    return ds


def to_netcdf(store: str | Path, path: str | Path, **kwargs) -> Path:
    """Write the store at ``store`` to the netCDF file ``path`` (``xarray.Dataset.to_netcdf``'s
    ``kwargs``, e.g. ``engine``); the path written."""
    ds = cf_dataset(store)
    ds.to_netcdf(str(path), **kwargs)
    return Path(path)
