"""The reports read a pipeline store through xarray and zarr's public API (issue 46: no reader
of zarr's files of its own), whatever its chunks.

Every data array of a real pipeline store, as the report opens it, equals zarr's own read of
it; and the store of a scene in chunks of one block (format 2's layout) and the same store in
chunks of several blocks read the same.
"""

from __future__ import annotations

import numpy as np
import pytest

zarr = pytest.importorskip("zarr")


@pytest.mark.parametrize("scene", ["tiny_plane", "tiny_optima"])
def test_a_pipeline_store_reads_the_same_through_the_report(tmp_path, scene):
    """Every data array of a real pipeline store: the report's read equals zarr's."""
    import report_helpers as rh
    from reports._read import open_scene_store

    store = rh.build_store(tmp_path, scene)
    sd = open_scene_store(store)
    assert sd.ds.data_vars
    for name in sd.ds.data_vars:
        a, b = sd.array(name), zarr.open_array(str(store), path=name, mode="r")[...]
        assert a.dtype == b.dtype and a.shape == b.shape, name
        np.testing.assert_array_equal(a, b, err_msg=name)


def test_chunks_of_one_block_and_of_several_read_the_same(tmp_path, monkeypatch):
    """The same tiny store built in chunks of one block (conftest's setting) and in the default
    chunks of many: every data array reads the same, and the second holds fewer chunk files
    (the control that the two layouts differ)."""
    import report_helpers as rh
    from reports._read import open_scene_store

    (tmp_path / "one").mkdir(), (tmp_path / "many").mkdir()
    one = rh.build_store(tmp_path / "one", "tiny_plane")
    monkeypatch.delenv("TWOLINK_PIPELINE_CHUNK_BYTES")
    many = rh.build_store(tmp_path / "many", "tiny_plane")
    a, b = open_scene_store(one), open_scene_store(many)
    assert sorted(a.ds.data_vars) == sorted(b.ds.data_vars)
    for name in a.ds.data_vars:
        np.testing.assert_array_equal(a.array(name), b.array(name), err_msg=name)

    def files(store):
        return sum(1 for p in store.rglob("*") if p.is_file() and "/c/" in str(p))

    assert files(many) < files(one)
