"""Small scenes and helpers shared by the pipeline tests (kept apart from the solver's cases)."""

from __future__ import annotations

import os
import subprocess
import sys
import warnings
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parent.parent

#: A small harmonic scene: 2 x 2 x 4 x 4 = 64 points in 8 chunks of 8 points (1 x 1 x 2 x 4), one per task,
#: each chunk solved as a warm-started sweep (as the paper's grid scenes are).
SMALL = """
[scene]
name = "small"
title = "pipeline test scene"
family = "harmonic"

[axes]
anisotropy_ratio = { values = [0.0625, 16.0] }
scaled_period = { log2_range = [0, 1], step = 1 }
A0 = { range = [0.4, 1.5], num = 4 }
A1_ratio = { range = [0.2, 0.8], num = 4 }

[fixed]
p = 0.0
delta = 1e-5

[solver]
method = "periodic"
rtol = {rtol}
sweeps = true

[outputs]
quantities = ["scaled_speed", "scaled_efficiency", "relative_efficiency"]
diagnostics = ["error_estimate", "iterations"]

[[reductions]]
name = "best_efficiency"
quantity = "scaled_efficiency"
statistic = "absmax"
over = ["A0", "A1_ratio"]
report = ["relative_efficiency", "scaled_speed"]
{polish}

[[reductions]]
name = "fastest"
quantity = "scaled_speed"
statistic = "max"
over = ["A0", "A1_ratio", "scaled_period"]

[series]
n_tau = 64
points = [{ anisotropy_ratio = 16.0, scaled_period = 2.0, A0 = 0.4, A1_ratio = 0.8 },
          { anisotropy_ratio = 0.0625, scaled_period = 1.0, A0 = 1.5, A1_ratio = 0.2 }]

[execution]
points_per_chunk = 8
points_per_task = 8
"""


def small_scene_text(rtol: float = 1e-3, polish: bool = False) -> str:
    extra = "polish = true\npolish_max_evaluations = 200\npolish_rtol = 1e-6" if polish else ""
    return SMALL.replace("{rtol}", repr(rtol)).replace("{polish}", extra)


def write_scene(tmp_path: Path, text: str, name: str = "small.toml") -> Path:
    path = tmp_path / name
    path.write_text(text)
    return path


def cli(*args, env_extra=None, **kw) -> subprocess.CompletedProcess:
    """Run ``python -m pipeline ...`` in a real subprocess from the repository root."""
    env = dict(os.environ)
    env["PYTHONPATH"] = str(REPO) + os.pathsep + env.get("PYTHONPATH", "")
    env.update(env_extra or {})
    return subprocess.run([sys.executable, "-m", "pipeline", *map(str, args)], cwd=REPO, env=env,
                          capture_output=True, text=True, **kw)


def read_store(store: Path) -> dict[str, np.ndarray]:
    """Every array in the store (root arrays and pipeline_state/*), by path."""
    import zarr

    out = {}
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        g = zarr.open_group(str(store), mode="r", use_consolidated=False)

        def walk(group, prefix):
            for name, arr in group.arrays():
                out[prefix + name] = arr[...]
            for name, sub in group.groups():
                walk(sub, prefix + name + "/")

        walk(g, "")
    return out


def assert_stores_equal(a: Path, b: Path) -> None:
    """Same arrays, same dtypes, same values (NaN equal to NaN)."""
    va, vb = read_store(a), read_store(b)
    assert sorted(va) == sorted(vb)
    for name in va:
        assert va[name].dtype == vb[name].dtype, name
        np.testing.assert_array_equal(va[name], vb[name], err_msg=name)


#: data types netCDF 3 (scipy's writer, the one netCDF writer CI always has) stores as they are
NETCDF3_DTYPES = tuple(np.dtype(t) for t in ("int8", "int16", "int32", "float32", "float64"))


def _netcdf_attr_problem(value) -> str | None:
    """Why netCDF refuses the attribute value ``value`` (None: it takes it): written from
    netCDF's rules (a string, a number, a non-empty 1-D array of numbers; no bool, no None),
    not from ``pipeline._attrs``."""
    if isinstance(value, (bool, np.bool_)) or value is None:
        return f"a {type(value).__name__}"
    if isinstance(value, (str, int, float, np.integer, np.floating)):
        return None
    if isinstance(value, (list, tuple, np.ndarray)):
        arr = np.asarray(value)
        if arr.ndim == 1 and arr.size and arr.dtype.kind in "if":
            return None
        return f"a {type(value).__name__} of {arr.dtype} with shape {arr.shape}"
    return f"a {type(value).__name__}"


def netcdf_problems(ds) -> list[str]:
    """What of the ``xarray.Dataset`` ``ds`` netCDF 3 refuses: an attribute (of the dataset or
    of a variable) that is not a string, a number or a 1-D numeric array, or a variable of a
    data type netCDF 3 lacks (bool, unsigned or 64-bit integers, strings)."""
    out = [f"attrs[{k!r}]: {why}" for k, v in ds.attrs.items() if (why := _netcdf_attr_problem(v))]
    for name, var in ds.variables.items():
        out += [f"{name}.attrs[{k!r}]: {why}" for k, v in var.attrs.items() if (why := _netcdf_attr_problem(v))]
        if var.dtype not in NETCDF3_DTYPES:
            out.append(f"{name}: dtype {var.dtype}")
    return out


def assert_same_dataset(a, b) -> None:
    """``b`` (read back from netCDF) holds ``a``'s variables (names, dims, dtypes, values; NaN
    equal to NaN) and attributes (their Python view through ``pipeline.decode_attrs``; the
    ``pipeline`` record through ``pipeline.read_record``)."""
    from pipeline import decode_attrs, read_record

    assert sorted(a.variables) == sorted(b.variables)
    for name in a.variables:
        va, vb = a[name], b[name]
        assert va.dims == vb.dims and va.dtype == vb.dtype, (name, va.dims, vb.dims, va.dtype, vb.dtype)
        np.testing.assert_array_equal(va.values, vb.values, err_msg=name)
        assert decode_attrs(va.attrs) == decode_attrs(vb.attrs), name
    record = read_record(a.attrs)
    assert isinstance(record, dict) and read_record(b.attrs) == record
    assert decode_attrs(a.attrs) == decode_attrs(b.attrs)


def netcdf_engines() -> list[str | None]:
    """``None`` (xarray's default netCDF writer: the plain ``to_netcdf(path)``) and scipy's netCDF 3
    writer where the default is another (netCDF4 or h5netcdf installed)."""
    import importlib.util

    default_is_scipy = not any(importlib.util.find_spec(m) for m in ("netCDF4", "h5netcdf"))
    return [None] if default_is_scipy else [None, "scipy"]


def assert_exports_to_netcdf(store: Path, tmp_path: Path) -> None:
    """Issue 34: the store exports as it is, ``xarray.open_zarr(store).to_netcdf(path)`` (with
    xarray's default writer, and scipy's netCDF 3 writer where the default is another), and
    through ``pipeline.to_netcdf``; each file reads back with the store's variables and
    attributes (:func:`assert_same_dataset`); nothing in the store is a value netCDF refuses
    (:func:`netcdf_problems`); the status variables carry CF flags (as many ``flag_values`` as
    ``flag_meanings`` words, sentences in ``flag_descriptions``) and every float variable
    carries ``units``."""
    import xarray as xr

    from pipeline import decode_attrs, read_record, to_netcdf

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        raw = xr.open_zarr(str(store), zarr_format=3, consolidated=False)
    assert netcdf_problems(raw) == []
    assert read_record(raw.attrs)["format_version"] == 3
    flagged = [n for n, v in raw.variables.items() if "flag_values" in v.attrs]
    assert "status" in flagged
    for name in flagged:
        attrs = raw[name].attrs
        assert len(attrs["flag_meanings"].split()) == len(attrs["flag_values"]) >= 2, name
        assert sorted(decode_attrs(attrs)["flag_meanings"], key=int) == [str(v) for v in attrs["flag_values"]]
    assert [n for n, v in raw.variables.items() if v.dtype.kind == "f" and "units" not in v.attrs] == []
    paths = []
    for engine in netcdf_engines():
        paths.append(tmp_path / f"raw_{engine or 'default'}.nc")
        raw.to_netcdf(paths[-1], engine=engine)
    paths.append(to_netcdf(store, tmp_path / "export.nc"))
    for path in paths:
        with xr.open_dataset(path) as back:
            assert_same_dataset(raw, back)


def downgrade_to_format_1(store: Path) -> None:
    """Rewrite ``store``'s attributes (every ``zarr.json``, the consolidated copy included) as
    store format 1 wrote them: their Python view (nested record, {code: meaning} flags, label
    lists), ``format_version`` 1.  The arrays are untouched: the stores of a user from before
    issue 34."""
    import json

    from pipeline import decode_attrs

    def old(attrs: dict) -> dict:
        view = decode_attrs(attrs)
        if isinstance(view.get("pipeline"), dict):
            view["pipeline"]["format_version"] = 1
        return view

    for zj in store.rglob("zarr.json"):
        doc = json.loads(zj.read_text())
        doc["attributes"] = old(doc.get("attributes", {}))
        for meta in doc.get("consolidated_metadata", {}).get("metadata", {}).values():
            meta["attributes"] = old(meta.get("attributes", {}))
        zj.write_text(json.dumps(doc))
