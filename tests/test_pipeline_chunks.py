"""``pipeline._chunks.write_chunk`` writes the files zarr writes, byte for byte.

Each case creates one array twice (same metadata) in two stores, writes the same whole chunks
through zarr (``array[region] = values``) into one and through ``write_chunk`` into the other,
and compares the two trees of chunk files: the same names and the same bytes.  The
comparison's negative control: one value changed in one tree must make them differ.
"""

from __future__ import annotations

import json
import warnings
from pathlib import Path

import numpy as np
import pytest
import zarr

from pipeline._chunks import layout_is_plain, read_whole, write_chunk


def _chunk_files(array_dir: Path) -> dict[str, bytes]:
    return {str(p.relative_to(array_dir)): p.read_bytes() for p in sorted((array_dir / "c").rglob("*"))
            if p.is_file()} if (array_dir / "c").exists() else {}


def _array(root: Path, shape, chunks, dtype, fill, **kw):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        g = zarr.open_group(str(root), mode="w", zarr_format=3)
        return g.create_array("a", shape=shape, chunks=chunks, dtype=dtype, fill_value=fill, **kw)


def _regions(shape, chunks):
    grid = tuple(-(-s // c) for s, c in zip(shape, chunks))
    for idx in np.ndindex(*grid):
        yield idx, tuple(slice(i * c, min((i + 1) * c, s)) for i, c, s in zip(idx, chunks, shape))


def _values(rng, dtype, shape):
    dtype = np.dtype(dtype)
    if dtype.kind == "f":
        v = rng.standard_normal(shape).astype(dtype)
        v.flat[1::7] = np.nan
    else:
        info = np.iinfo(dtype)
        v = rng.integers(max(info.min, -100), min(info.max, 100), size=shape, endpoint=True).astype(dtype)
    v.flat[0] = 1  # no fill value used here is 1: every such block is written
    return v


def _write_both(tmp_path, shape, chunks, dtype, fill, blocks):
    """Write ``blocks`` {chunk index: values} through zarr into one tree and through
    ``write_chunk`` into another; both array folders."""
    za = _array(tmp_path / "zarr", shape, chunks, dtype, fill)
    _array(tmp_path / "direct", shape, chunks, dtype, fill)
    direct = tmp_path / "direct" / "a"
    meta = json.loads((direct / "zarr.json").read_text())
    assert layout_is_plain(meta)
    regions = dict(_regions(shape, chunks))
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        for idx, v in blocks.items():
            za[regions[idx]] = v
            write_chunk(direct, meta, idx, v)
    return tmp_path / "zarr" / "a", direct


@pytest.mark.parametrize("dtype, fill", [(np.float64, np.nan), (np.int32, 0), (np.int8, -1), (np.uint8, 0),
                                         (np.float32, np.nan), (np.float64, 0.0), (np.int64, 7)])
def test_every_chunk_file_equals_zarrs_byte_for_byte(tmp_path, dtype, fill):
    shape, chunks = (5, 7, 9), (2, 3, 4)  # edge chunks on every axis
    rng = np.random.default_rng(0)
    blocks = {idx: _values(rng, dtype, tuple(sl.stop - sl.start for sl in reg))
              for idx, reg in _regions(shape, chunks)}
    fill_value = np.asarray(fill, dtype=dtype)
    first = next(iter(blocks))
    blocks[first] = np.full(blocks[first].shape, fill_value)  # only fill: no file
    if np.dtype(dtype).kind == "f" and fill == 0.0:
        blocks[(1, 1, 1)] = np.full(blocks[(1, 1, 1)].shape, -0.0)  # -0.0 is not the fill 0.0: a file
    a, b = _write_both(tmp_path, shape, chunks, dtype, fill, blocks)
    fa, fb = _chunk_files(a), _chunk_files(b)
    assert "/".join(["c", *map(str, first)])[2:] not in fa
    assert fa.keys() == fb.keys() and len(fa) == len(blocks) - 1
    assert fa == fb
    np.testing.assert_array_equal(read_whole(b), zarr.open_array(str(tmp_path / "zarr"), path="a", mode="r")[...])


def test_a_chunk_rewritten_as_fill_only_loses_its_file_as_in_zarr(tmp_path):
    shape, chunks = (4, 4), (2, 2)
    blocks = {(0, 0): np.ones((2, 2)), (1, 1): np.full((2, 2), 3.0)}
    a, b = _write_both(tmp_path, shape, chunks, np.float64, np.nan, blocks)
    assert _chunk_files(a) == _chunk_files(b) and len(_chunk_files(b)) == 2
    za = zarr.open_array(str(tmp_path / "zarr"), path="a", mode="r+")
    meta = json.loads((b / "zarr.json").read_text())
    za[0:2, 0:2] = np.nan
    assert write_chunk(b, meta, (0, 0), np.full((2, 2), np.nan)) is None
    assert _chunk_files(a) == _chunk_files(b) and len(_chunk_files(b)) == 1


def test_the_comparison_sees_one_value_changed(tmp_path):
    """Negative control: the byte comparison above must say "differ" when one value differs."""
    shape, chunks = (4, 6), (2, 3)
    rng = np.random.default_rng(1)
    blocks = {idx: _values(rng, np.float64, (2, 3)) for idx, _ in _regions(shape, chunks)}
    a, b = _write_both(tmp_path, shape, chunks, np.float64, np.nan, blocks)
    meta = json.loads((b / "zarr.json").read_text())
    changed = blocks[(1, 1)].copy()
    changed[0, 0] = np.nextafter(changed[0, 0], np.inf) if np.isfinite(changed[0, 0]) else 1.0
    write_chunk(b, meta, (1, 1), changed)
    assert _chunk_files(a) != _chunk_files(b)


def test_a_chunk_that_does_not_fit_is_refused(tmp_path):
    _array(tmp_path / "s", (4, 4), (2, 2), np.float64, np.nan)
    meta = json.loads((tmp_path / "s" / "a" / "zarr.json").read_text())
    with pytest.raises(ValueError, match="do not fit"):
        write_chunk(tmp_path / "s" / "a", meta, (0, 0), np.zeros((3, 2)))


def test_a_sharded_array_is_not_plain_and_is_written_through_zarr(tmp_path):
    """Negative control of the layout test: a sharded array is written through zarr by the
    pipeline's chunk writer, with the same values read back."""
    from pipeline._store import _write_whole_chunk

    za = _array(tmp_path / "s", (4, 4), (2, 2), np.float64, np.nan, shards=(4, 4))
    meta = json.loads((tmp_path / "s" / "a" / "zarr.json").read_text())
    assert not layout_is_plain(meta)
    _write_whole_chunk(tmp_path / "s", "a", (slice(2, 4), slice(0, 2)), (1, 0), (2, 2), np.full((2, 2), 5.0))
    got = zarr.open_array(str(tmp_path / "s"), path="a", mode="r")[...]
    assert np.all(got[2:4, 0:2] == 5.0) and np.isnan(got[:2]).all() and np.isnan(got[2:, 2:]).all()
    assert za.shards == (4, 4)


@pytest.mark.parametrize("shape, chunks, values", [((5, 7), (5, 7), "random"), ((5, 7), (2, 3), "random"),
                                                   ((3, 4), (3, 4), 2.5), ((4,), (4,), "random")])
def test_a_whole_array_written_directly_equals_zarrs_files(tmp_path, shape, chunks, values):
    """``write_whole`` (the reductions' writer) against ``zarr_array[...] = values``: the same
    files, byte for byte, from an array, a scalar broadcast, and float values cast to int."""
    from pipeline._chunks import write_whole

    rng = np.random.default_rng(2)
    for dtype, fill in ((np.float64, np.nan), (np.int32, 0)):
        v = rng.standard_normal(shape) * 50 if values == "random" else values
        root = tmp_path / np.dtype(dtype).name
        za = _array(root / "zarr", shape, chunks, dtype, fill)
        _array(root / "direct", shape, chunks, dtype, fill)
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            za[...] = np.asarray(v).astype(za.dtype)
        direct = root / "direct" / "a"
        write_whole(direct, json.loads((direct / "zarr.json").read_text()), v)
        assert _chunk_files(root / "zarr" / "a") == _chunk_files(direct) != {}


def _skeleton_files(store: Path) -> dict[str, object]:
    """Every file of a store: bytes, but the root's record without its creation time."""
    out = {}
    for p in sorted(store.rglob("*")):
        if p.is_file():
            key = str(p.relative_to(store))
            out[key] = p.read_bytes()
            if key == "zarr.json":
                from pipeline._attrs import read_record

                doc = json.loads(out[key])
                record = read_record(doc["attributes"])
                record["provenance"].pop("created")
                out[key] = record
    return out


@pytest.mark.parametrize("name", ["quick", "fourier_optima", "accuracy"])
def test_a_skeleton_built_in_memory_is_the_one_zarr_writes_on_disk(tmp_path, monkeypatch, name):
    """``_store.new_group`` builds a kind's skeleton in memory and ``finish_skeleton`` writes
    its files; the reference builds the same skeleton with zarr on disk, as before."""
    import pipeline._optima as optima_kind
    import pipeline._store as store_mod
    import pipeline._study as study_kind
    from pipeline import load_scene
    from pipeline._kind import RunContext
    from pipeline._registry import kind_of

    scene = load_scene(Path(__file__).resolve().parents[1] / "workflows" / f"{name}.toml")

    def build(store):
        kind_of(scene).create_skeleton(RunContext(scene=scene, store=store, scheduler=None, n_workers=2,
                                                  progress=False, echo=print))

    build(tmp_path / "memory.zarr")

    def on_disk(store):
        if store.exists():
            store_mod.shutil.rmtree(store)
        return store_mod.open_group(store, "w")

    for module in (store_mod, optima_kind, study_kind):
        monkeypatch.setattr(module, "new_group", on_disk)
    monkeypatch.setattr(store_mod, "_write_skeleton", lambda g, store: None)
    build(tmp_path / "disk.zarr")
    a, b = _skeleton_files(tmp_path / "memory.zarr"), _skeleton_files(tmp_path / "disk.zarr")
    assert len(a) > 10 and a.keys() == b.keys()
    assert a == b


def test_a_skeleton_interrupted_while_written_is_rebuilt(tmp_path, monkeypatch):
    """Killed half-way through writing its files, a skeleton reads as interrupted (no record:
    the root's metadata, written last, is still the empty group's) and the next build
    completes it; the control, the same build uninterrupted, reads as complete."""
    from pipeline import load_scene
    from pipeline._grid_kind import GRID
    from pipeline._store import create_skeleton, open_existing

    scene = load_scene(Path(__file__).resolve().parents[1] / "workflows" / "quick.toml")
    store = tmp_path / "s.zarr"
    calls = {"n": 0}
    real = Path.write_bytes

    def failing(self, data):
        calls["n"] += 1
        if calls["n"] > 5:
            raise KeyboardInterrupt("killed")
        return real(self, data)

    monkeypatch.setattr(Path, "write_bytes", failing)
    with pytest.raises(KeyboardInterrupt):
        create_skeleton(store, scene, GRID.chunk_layout(scene))
    monkeypatch.setattr(Path, "write_bytes", real)
    assert (store / "zarr.json").is_file() and open_existing(store) is None
    create_skeleton(store, scene, GRID.chunk_layout(scene))
    meta = open_existing(store)
    assert meta is not None and meta["state"]["skeleton_complete"]


# --- tasks that leave their last write to their worker (``_run.run_chunks(..., detach=True)``)

def _quick_store(tmp_path):
    from pipeline import load_scene
    from pipeline._grid_kind import GRID
    from pipeline._store import create_skeleton

    scene = load_scene(Path(__file__).resolve().parents[1] / "workflows" / "quick.toml")
    chunks = GRID.chunk_layout(scene)
    store = tmp_path / "q.zarr"
    create_skeleton(store, scene, chunks)
    return scene, chunks, store


def _fake_solve(scene, chunks, index):
    """A chunk's outputs without solving: each point's value its chunk's first index."""
    from pipeline._grid import chunk_region
    from pipeline._store import ChunkWrite, SolvedChunk, output_dtype

    region = chunk_region(index, scene.shape, chunks)
    rshape = tuple(sl.stop - sl.start for sl in region)
    values = {n: np.full(rshape, index[0] + 1, dtype=output_dtype(n)[0]) for n in scene.outputs}
    values["status"] = np.zeros(rshape, dtype=np.int8)
    return SolvedChunk(writes=(ChunkWrite(region, tuple(index), tuple(chunks), scene.shape, values),),
                       points=int(np.prod(rshape)), failures=0, seconds=0.001)


def test_a_detached_task_leaves_its_last_write_and_the_next_task_collects_it(tmp_path, monkeypatch):
    import pipeline._run as run_mod
    from pipeline._store import is_marked, read_done

    scene, chunks, store = _quick_store(tmp_path)
    grid = read_done(store).shape
    idx = [tuple(i) for i in np.ndindex(*grid)]
    monkeypatch.setattr(run_mod, "_LEFT", None)
    first = run_mod.run_chunks(_fake_solve, str(store), scene, chunks, idx[:3], detach=True)
    assert first["points"] == 3 * int(np.prod(chunks)) and first["written_chunks"] == 2
    assert run_mod._LEFT is not None and run_mod._LEFT[0] == str(store)
    second = run_mod.run_chunks(_fake_solve, str(store), scene, chunks, idx[3:4], detach=True)
    assert second["written_chunks"] == 1  # the first task's last write, collected here
    run_mod.wait_for_markers(store, idx[:4], timeout=10)
    assert all(is_marked(store, i) for i in idx[:4]) and not is_marked(store, idx[4])
    run_mod._LEFT[1].result()
    monkeypatch.setattr(run_mod, "_LEFT", None)
    # without detach every write is collected in its own task
    third = run_mod.run_chunks(_fake_solve, str(store), scene, chunks, idx[4:6], detach=False)
    assert third["written_chunks"] == 2 and run_mod._LEFT is None and all(is_marked(store, i) for i in idx[4:6])


def test_a_failed_detached_write_is_raised_by_the_next_task_of_its_process(tmp_path, monkeypatch):
    import pipeline._run as run_mod
    from pipeline._store import store_chunk

    scene, chunks, store = _quick_store(tmp_path)
    monkeypatch.setattr(run_mod, "_LEFT", None)

    def broken(store_path, index, solved):
        raise OSError("disk full")

    monkeypatch.setattr(run_mod, "store_chunk", broken)
    run_mod.run_chunks(_fake_solve, str(store), scene, chunks, [(0, 0, 0, 0)], detach=True)  # returns: write left
    with pytest.raises(OSError, match="disk full"):
        run_mod.run_chunks(_fake_solve, str(store), scene, chunks, [(0, 0, 1, 0)], detach=True)
    # raised once: the process's next task (its store writable again) is not failed by it
    assert run_mod._LEFT is None
    monkeypatch.setattr(run_mod, "store_chunk", store_chunk)
    run_mod.run_chunks(_fake_solve, str(store), scene, chunks, [(0, 0, 1, 0)], detach=True)
    run_mod._LEFT[1].result()
    monkeypatch.setattr(run_mod, "_LEFT", None)


def test_waiting_for_markers_names_the_chunk_that_has_none(tmp_path):
    """The driver's wait returns at once where every marker is there, and refuses by name,
    after its timeout, where one is missing (its negative control)."""
    import pipeline._run as run_mod
    from pipeline._store import mark_done

    scene, chunks, store = _quick_store(tmp_path)
    mark_done(store, (0, 0, 0, 0))
    mark_done(store, (1, 2, 1, 0))
    run_mod.wait_for_markers(store, [(0, 0, 0, 0), (1, 2, 1, 0)], timeout=0.05)
    with pytest.raises(RuntimeError, match=r"1 chunks without their done marker .*\(1, 2, 0, 0\)"):
        run_mod.wait_for_markers(store, [(0, 0, 0, 0), (1, 2, 0, 0)], timeout=0.05)


def test_a_declared_skeleton_keeps_every_groups_attributes(tmp_path):
    """``SkeletonGroup``: attributes set on a sub-group and on the root, an array filled whole,
    and ``in``, as a zarr group on disk has them."""
    import zarr

    from pipeline._store import SkeletonGroup, _write_skeleton, new_group

    store = tmp_path / "s.zarr"
    g = new_group(store)
    assert isinstance(g, SkeletonGroup)
    sub = g.create_group("inner")
    sub.attrs["note"] = "kept"
    g.attrs["top"] = 1
    g.create_array("x", shape=(3,), chunks=(3,), dtype="f8", fill_value=np.nan)[:] = [1.0, 2.0, 3.0]
    sub.create_array("y", shape=(2,), chunks=(1,), dtype="i4", fill_value=0)
    assert "x" in g and "inner" in g and "y" in sub and "y" not in g
    with pytest.raises(ValueError, match="filled whole"):
        g.create_array("z", shape=(2,), chunks=(2,), dtype="f8", fill_value=0.0)[0] = 1.0
    _write_skeleton(g, store)
    root = zarr.open_group(str(store), mode="r")
    assert dict(root.attrs) == {"top": 1} and dict(root["inner"].attrs) == {"note": "kept"}
    np.testing.assert_array_equal(root["x"][...], [1.0, 2.0, 3.0])
    assert root["inner/y"].shape == (2,) and not (store / "inner" / "y" / "c").exists()
