"""Reading a store's array whole, its chunk files straight from disk.

The report reads every array it uses whole. Through zarr-python each chunk is one request of
its asynchronous store and codec pipeline: about 0.3 ms of CPU and 0.6-0.9 ms of wall time per
chunk file (measured: the 720 chunks of ``force_laws.zarr/seconds``, 0.60 s through zarr, 0.03 s
to read the files), and a paper's stores hold ~49,000 chunk files, so reading dominated the
report's build (issue 36). The pipeline writes one layout only (regular chunk grid, default
chunk keys, ``bytes`` + ``zstd`` codecs), which :func:`read_whole` reads directly: each file read
once, decompressed, and placed in the output. Any other layout (sharding, transposes, other
codecs or data types, storage transformers) returns None, and the caller reads it through zarr.

``tests/test_report_read.py`` compares :func:`read_whole` with zarr's reads on synthetic arrays
(edge chunks, missing chunks, every numeric data type, 0-d) and on every array of a pipeline
store.
"""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np

__all__ = ["read_whole", "layout_is_plain"]

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
    sep = meta["chunk_key_encoding"].get("configuration", {}).get("separator", "/")
    decompress = None
    if [c["name"] for c in meta["codecs"]][-1] == "zstd":
        from numcodecs import Zstd

        decompress = Zstd().decode
    grid = tuple(-(-s // c) for s, c in zip(shape, chunk))
    for idx in np.ndindex(*grid):
        key = sep.join(["c", *map(str, idx)])
        try:
            raw = (array_dir / key).read_bytes()
        except FileNotFoundError:
            continue
        if decompress is not None:
            raw = decompress(raw)
        block = np.frombuffer(raw, dtype=dtype).reshape(chunk)
        region = tuple(slice(i * c, min((i + 1) * c, s)) for i, c, s in zip(idx, chunk, shape))
        out[region] = block[tuple(slice(0, r.stop - r.start) for r in region)]
    return out
