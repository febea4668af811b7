"""pipeline._chunks.read_whole reads an array as zarr reads it, without zarr.

Compared with ``zarr.open_array(...)[...]`` on synthetic arrays (every numeric data type, edge
chunks, chunks never written, 0-d, with and without zstd) and on every array of a real pipeline
store; the layouts it does not read (sharding, other codecs, strings) return None so the caller
reads them through zarr. Negative controls: a chunk file changed on disk, and a fill value changed
in the metadata, make the comparison fail.
"""

from __future__ import annotations

import json

import numpy as np
import pytest

zarr = pytest.importorskip("zarr")

from pipeline._chunks import layout_is_plain, read_whole  # noqa: E402

DTYPES = ["bool", "int8", "uint8", "int16", "uint16", "int32", "uint32", "int64", "uint64", "float32",
          "float64"]


def _array(path, shape, chunks, dtype, *, fill, compressed=True, write=None):
    kw = {} if compressed else {"compressors": None}
    a = zarr.create_array(str(path), shape=shape, chunks=chunks, dtype=dtype, fill_value=fill,
                          dimension_names=[f"d{i}" for i in range(len(shape))] or None, **kw)
    rng = np.random.default_rng(len(str(path)))
    data = (rng.normal(size=shape) * 100).astype(dtype) if np.dtype(dtype).kind != "b" else rng.random(shape) > 0.5
    if write is None:
        a[...] = data
    else:
        a[write] = data[write]
    return a


@pytest.mark.parametrize("dtype", DTYPES)
@pytest.mark.parametrize("compressed", [True, False])
def test_read_whole_equals_zarr_edge_chunks_and_missing_chunks(tmp_path, dtype, compressed):
    fill = np.nan if dtype.startswith("float") else (False if dtype == "bool" else 3)
    a = _array(tmp_path / "a", (7, 5, 3), (3, 2, 3), dtype, fill=fill, compressed=compressed,
               write=(slice(0, 4), slice(1, 5), slice(None)))  # some chunks never written
    ours, theirs = read_whole(tmp_path / "a"), a[...]
    assert ours.dtype == theirs.dtype and ours.shape == theirs.shape
    np.testing.assert_array_equal(ours, theirs)


def test_zero_d_and_empty_arrays(tmp_path):
    a = zarr.create_array(str(tmp_path / "s"), shape=(), dtype="float64", fill_value=np.nan)
    a[...] = 2.5
    assert read_whole(tmp_path / "s")[()] == 2.5
    zarr.create_array(str(tmp_path / "e"), shape=(0, 4), chunks=(1, 4), dtype="int32", fill_value=0)
    assert read_whole(tmp_path / "e").shape == (0, 4)


def test_other_layouts_are_left_to_zarr(tmp_path):
    zarr.create_array(str(tmp_path / "sh"), shape=(8,), chunks=(2,), shards=(4,), dtype="float64", fill_value=0.0)
    zarr.create_array(str(tmp_path / "st"), shape=(3,), chunks=(3,), dtype=str, fill_value="")
    for name in ("sh", "st"):
        assert not layout_is_plain(json.loads((tmp_path / name / "zarr.json").read_text()))
        assert read_whole(tmp_path / name) is None


def test_the_comparison_can_fail(tmp_path, monkeypatch):
    """Negative controls: a fill value changed in the metadata, and a reader that takes the wrong
    byte order, give arrays the comparison tells apart from zarr's."""
    import pipeline._chunks as chunks

    a = _array(tmp_path / "a", (6,), (2,), "float64", fill=np.nan, write=slice(0, 4))
    meta = json.loads((tmp_path / "a" / "zarr.json").read_text())
    meta["fill_value"] = 0.0
    (tmp_path / "a" / "zarr.json").write_text(json.dumps(meta))
    assert not np.array_equal(read_whole(tmp_path / "a"), a[...], equal_nan=True)
    b = _array(tmp_path / "b", (5, 3), (2, 2), "int32", fill=0)
    monkeypatch.setattr(chunks, "_dtype", lambda meta: np.dtype(">i4"))
    assert not np.array_equal(chunks.read_whole(tmp_path / "b"), b[...])


@pytest.mark.parametrize("scene", ["tiny_plane", "tiny_optima"])
def test_a_pipeline_store_reads_the_same_through_the_report(tmp_path, scene):
    """Every data array of a real pipeline store: the report's direct read equals xarray's (zarr's)."""
    import xarray as xr

    import report_helpers as rh
    from reports._read import _WholeArray, open_scene_store

    store = rh.build_store(tmp_path, scene)
    sd = open_scene_store(store)
    ref = xr.open_zarr(str(store), consolidated=False, zarr_format=3, chunks=None)
    direct = 0
    for name in sd.ds.data_vars:
        a, b = sd.ds[name].values, ref[name].values
        assert a.dtype == b.dtype and a.shape == b.shape, name
        np.testing.assert_array_equal(a, b, err_msg=name)
        direct += isinstance(getattr(sd.ds[name].variable._data, "array", None), _WholeArray)
    assert direct == len(sd.ds.data_vars)
