"""Reading a store's array whole, and writing one chunk of it, its chunk files straight from disk.

The report reads every array it uses whole. Through zarr-python each chunk is one request of
its asynchronous store and codec pipeline: about 0.3 ms of CPU and 0.6-0.9 ms of wall time per
chunk file (measured: the 720 chunks of ``force_laws.zarr/seconds``, 0.60 s through zarr, 0.03 s
to read the files), and a paper's stores hold ~49,000 chunk files, so reading dominated the
report's build (issue 36). The pipeline writes one layout only (regular chunk grid, default
chunk keys, ``bytes`` + ``zstd`` codecs), which :func:`read_whole` reads directly: each file read
once, decompressed, and placed in the output. Any other layout (sharding, transposes, other
codecs or data types, storage transformers) returns None, and the caller reads it through zarr.

Writing is the mirror image (:func:`write_chunk`): a worker stores each solved chunk as one
file per output, and through zarr-python each costs ~2.5 ms of CPU (its event loop, codec
pipeline and metadata), ~15 ms for a grid chunk's six outputs and its done marker, in the
worker's writer thread, beside the solving, on the same core.  :func:`write_chunk` writes the
file zarr would write, byte for byte (zarr's own ``zstd`` codec object, the same ``bytes``
order; no file where the chunk holds only the fill value, as zarr's default
``write_empty_chunks=False``; written to a temporary name and renamed, as zarr's ``LocalStore``).

``tests/test_report_read.py`` compares :func:`read_whole` with zarr's reads on synthetic arrays
(edge chunks, missing chunks, every numeric data type, 0-d) and on every array of a pipeline
store; ``tests/test_pipeline_chunks.py`` compares :func:`write_chunk`'s files with zarr's.
"""

from __future__ import annotations

import json
import math
import os
import uuid
from pathlib import Path

import numpy as np

__all__ = ["chunk_key", "read_whole", "layout_is_plain", "write_chunk", "write_whole"]

_KINDS = "biuf"  # bool, signed and unsigned integers, floats
_SPECIAL_FLOATS = {"NaN": math.nan, "Infinity": math.inf, "-Infinity": -math.inf}


def _dtype(meta: dict) -> np.dtype | None:
    try:
        dt = np.dtype(meta["data_type"])
    except TypeError:
        return None
    if dt.kind not in _KINDS:
        return None
    endian = next((c.get("configuration", {}).get("endian") for c in meta["codecs"] if c["name"] == "bytes"), None)
    if dt.itemsize > 1:
        dt = dt.newbyteorder("<" if endian in (None, "little") else ">")
    return dt


def layout_is_plain(meta: dict) -> bool:
    """True where ``meta`` (an array's ``zarr.json``) is the layout :func:`read_whole` reads: a
    regular chunk grid, default chunk keys, codecs ``bytes`` (+ ``zstd``), a numeric data type, a
    number as fill value, no storage transformers."""
    try:
        codecs = [c["name"] for c in meta["codecs"]]
        return (meta.get("zarr_format") == 3 and meta.get("node_type") == "array"
                and meta["chunk_grid"]["name"] == "regular"
                and meta["chunk_key_encoding"]["name"] == "default"
                and codecs in (["bytes"], ["bytes", "zstd"])
                and not meta.get("storage_transformers")
                and _dtype(meta) is not None
                and (isinstance(meta["fill_value"], (int, float, bool)) or meta["fill_value"] in _SPECIAL_FLOATS))
    except (KeyError, TypeError):
        return False


def chunk_key(meta: dict, index) -> str:
    """The key of chunk ``index`` under its array's folder, by the array's default chunk key
    encoding (``c/i/j`` with separator "/")."""
    sep = meta["chunk_key_encoding"].get("configuration", {}).get("separator", "/")
    return sep.join(["c", *map(str, index)])


def read_whole(array_dir) -> np.ndarray | None:
    """The whole array stored under ``array_dir`` (a folder with its ``zarr.json``), or None where
    its layout is not :func:`layout_is_plain` (read it through zarr then). Missing chunks hold the
    fill value, as zarr reads them."""
    array_dir = Path(array_dir)
    meta = json.loads((array_dir / "zarr.json").read_text())
    if not layout_is_plain(meta):
        return None
    dtype = _dtype(meta)
    shape = tuple(int(n) for n in meta["shape"])
    chunk = tuple(int(n) for n in meta["chunk_grid"]["configuration"]["chunk_shape"])
    fill = meta["fill_value"]
    out = np.full(shape, _SPECIAL_FLOATS.get(fill, fill) if isinstance(fill, str) else fill, dtype=dtype)
    if out.size == 0:
        return out
    decompress = None
    if [c["name"] for c in meta["codecs"]][-1] == "zstd":
        from numcodecs import Zstd

        decompress = Zstd().decode
    grid = tuple(-(-s // c) for s, c in zip(shape, chunk))
    for idx in np.ndindex(*grid):
        try:
            raw = (array_dir / chunk_key(meta, idx)).read_bytes()
        except FileNotFoundError:
            continue
        if decompress is not None:
            raw = decompress(raw)
        block = np.frombuffer(raw, dtype=dtype).reshape(chunk)
        region = tuple(slice(i * c, min((i + 1) * c, s)) for i, c, s in zip(idx, chunk, shape))
        out[region] = block[tuple(slice(0, r.stop - r.start) for r in region)]
    return out


def _fill(meta: dict):
    fill = meta["fill_value"]
    return _SPECIAL_FLOATS.get(fill, fill) if isinstance(fill, str) else fill


def _only_fill(block: np.ndarray, fill) -> bool:
    """zarr's test for a chunk it does not write (``NDBuffer.all_equal``): NaN equals NaN, and a
    float fill of 0 compares bit patterns (so -0.0 is written)."""
    if block.dtype.kind == "f" and fill == 0.0:
        zero = np.zeros((), dtype=block.dtype)
        return bool(np.all(block.view(f"V{block.dtype.itemsize}") == zero.view(f"V{block.dtype.itemsize}")))
    return bool(np.array_equal(block, np.broadcast_to(np.asarray(fill, dtype=block.dtype), block.shape),
                               equal_nan=block.dtype.kind == "f"))


def _zstd(config: dict):
    from zarr.codecs import ZstdCodec

    key = (config.get("level", 0), config.get("checksum", False))
    codec = _ZSTD.get(key)
    if codec is None:
        codec = _ZSTD[key] = ZstdCodec(level=key[0], checksum=key[1])._zstd_codec
    return codec


_ZSTD: dict = {}


def write_chunk(array_dir, meta: dict, index: tuple[int, ...], values: np.ndarray) -> Path | None:
    """Store chunk ``index`` of the array under ``array_dir`` (its ``zarr.json`` decoded as
    ``meta``, a :func:`layout_is_plain` layout) holding ``values`` (the chunk's part of the
    array: the chunk's shape, or less at the array's far edges, the rest being fill).

    Writes the file zarr would write for ``array[region] = values`` (atomically: a temporary
    name, then renamed), or removes it where every value is the fill value (zarr then keeps no
    file).  Returns the path written, or None where no file is kept.
    """
    array_dir = Path(array_dir)
    dtype = _dtype(meta)
    chunk = tuple(int(n) for n in meta["chunk_grid"]["configuration"]["chunk_shape"])
    values = np.asarray(values)
    if values.ndim != len(chunk) or any(v > c for v, c in zip(values.shape, chunk)):
        raise ValueError(f"{array_dir.name}: values of shape {values.shape} do not fit a chunk {chunk}")
    fill = _fill(meta)
    block = np.full(chunk, fill, dtype=dtype)
    block[tuple(slice(0, n) for n in values.shape)] = values
    path = array_dir / chunk_key(meta, index)
    if _only_fill(block, fill):
        path.unlink(missing_ok=True)
        return None
    raw = block.tobytes()
    codecs = meta["codecs"]
    if codecs[-1]["name"] == "zstd":
        raw = _zstd(codecs[-1].get("configuration", {})).encode(raw)
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_suffix(f".{uuid.uuid4().hex}.partial")
    try:
        with open(tmp, "wb") as f:
            f.write(raw)
        os.replace(tmp, path)
    except BaseException:
        tmp.unlink(missing_ok=True)
        raise
    return path


def write_whole(array_dir, meta: dict, values) -> None:
    """Store the whole array under ``array_dir`` (a :func:`layout_is_plain` layout, its
    ``zarr.json`` decoded as ``meta``) as ``values`` (broadcast to the array's shape and cast to
    its data type, as ``zarr_array[...] = values`` does): every chunk by :func:`write_chunk`."""
    shape = tuple(int(n) for n in meta["shape"])
    chunk = tuple(int(n) for n in meta["chunk_grid"]["configuration"]["chunk_shape"])
    whole = np.broadcast_to(np.asarray(values).astype(_dtype(meta).newbyteorder("=")), shape)
    grid = tuple(-(-s // c) for s, c in zip(shape, chunk))
    for idx in np.ndindex(*grid):
        region = tuple(slice(i * c, min((i + 1) * c, s)) for i, c, s in zip(idx, chunk, shape))
        write_chunk(array_dir, meta, idx, whole[region])
