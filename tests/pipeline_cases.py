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
    extra = "polish = true\npolish_max_evaluations = 12" if polish else ""
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


def assert_exports_to_netcdf(store: Path, tmp_path: Path) -> None:
    """``pipeline.to_netcdf`` writes the store as netCDF that reads back with every data
    variable equal to ``xarray.open_zarr``'s, CF flags on ``status`` (as many ``flag_values`` as
    ``flag_meanings`` words) and ``units`` on every float output; while the raw
    ``xarray.open_zarr(store).to_netcdf`` refuses the nested attributes (the negative control:
    without the export's rewriting the check would fail)."""
    import pytest
    import xarray as xr

    from pipeline import to_netcdf

    raw = xr.open_zarr(str(store), zarr_format=3, consolidated=False)
    with pytest.raises((TypeError, ValueError)):
        raw.to_netcdf(tmp_path / "raw.nc")
    path = to_netcdf(store, tmp_path / "export.nc")
    with xr.open_dataset(path) as back:
        assert sorted(back.data_vars) == sorted(raw.data_vars)
        for name in raw.data_vars:
            np.testing.assert_array_equal(back[name].values, raw[name].values, err_msg=name)
        status = back["status"].attrs
        assert len(status["flag_meanings"].split()) == len(np.atleast_1d(status["flag_values"])) >= 2
        assert "pipeline" in back.attrs and isinstance(back.attrs["pipeline"], str)
