"""The Zarr store of a scene: skeleton, provenance, per-chunk done markers, run lock.

Layout (Zarr format 3, one group per scene)::

    <store>/                      group; attrs["pipeline"] = provenance + layout + state (JSON text)
        <axis>                    1-D coordinate array per axis, dimension_names [axis]
        <output>                  one array per stored quantity/diagnostic, dims = scene axes
        status                    int8, 0 converged, > 0 solver failure, -1 not computed (CF flags)
        <reduction arrays>        labelled by the kept axes (+ a subset dimension)
        pipeline_state/chunk_done uint8 per chunk, 1 once the chunk's outputs are all written

Two units (issue 46): a *block* is what one task solves at a time (``layout.blocks``; with
sweeps a unit of the science, ``_grid.scene_chunks``); a *chunk* is what the store keeps in one
file per array (``layout.chunks``: whole blocks, ~1 MiB of the largest output,
:func:`storage_chunks`), and the unit of resuming.  The driver is the one writer: tasks return
their blocks, and :class:`ChunkWriter` writes each chunk once it is whole, through zarr's
public API, syncs it, then sets its done marker.  Only the driver writes attributes.
Every attribute goes through :mod:`pipeline._attrs` (:func:`create_array`, the record's
functions here), so a store is netCDF- and CF-ready: ``xarray.open_zarr(store).to_netcdf(path)``
works on it as it is (issue 34).
"""

from __future__ import annotations

import datetime as _dt
import fcntl
import functools
import itertools
import json
import os
import platform
import shutil
import subprocess
import time
import warnings
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import zarr

from solver.periodic.options import engine_options

from ._attrs import ATTRS_KEY, encode_attrs, read_record, record_text
from ._grid_scene import DIAGNOSTICS, QUANTITIES, Reduction, Scene, axis_attrs
from ._scene import engine_versions

__all__ = [
    "ATTRS_KEY", "CHUNK_BYTES", "FORMAT_VERSION", "NOT_COMPUTED", "STATE_FLAGS", "STATE_GROUP", "STARTED_MARKER",
    "ChunkWrite", "ChunkWriter", "Skeleton", "SolvedChunk", "StoreBusy", "StoreForeign", "StoreMismatch",
    "StoreUnwritable", "blocks_in", "chunk_bytes", "consolidate", "create_array", "create_skeleton",
    "finish_skeleton", "is_complete", "mark_done", "new_group", "open_existing", "open_group", "output_dtype",
    "provenance", "read_arrays", "read_done", "record_run", "reduction_arrays", "remove_partials", "run_lock",
    "set_state", "status_meanings", "storage_chunks", "store_meta", "sync_written", "unwritable_reason",
    "write_arrays",
]

#: Layout version of the store (readers such as reports/ check it).  3 (issue 46): chunks of
#: whole blocks (``layout.blocks``, ``layout.chunks``), markers per chunk; 2 (issue 34):
#: attributes as netCDF takes them (``_attrs``: the record as JSON text, CF flags, ``units`` on
#: every float array), a chunk per block; 1: nested attributes.  The reports read all three;
#: a run resumes only its own.
FORMAT_VERSION = 3
STATE_GROUP = "pipeline_state"
DONE_ARRAY = f"{STATE_GROUP}/chunk_done"
NOT_COMPUTED = -1


class StoreBusy(RuntimeError):
    """Another run holds the store's lock."""


class StoreMismatch(RuntimeError):
    """The store was built from a different scene (or is not a pipeline store)."""


class StoreForeign(StoreMismatch):
    """A Zarr store the pipeline did not write (no pipeline record, no sign that a run of the
    pipeline started it): replaced only where the user asks (``--overwrite``)."""


class StoreUnwritable(StoreMismatch):
    """The store (or its lock file) cannot be created or written where it was asked for: a
    read-only folder, a path under a regular file, a file system that refuses it."""


#: the file a run writes first into a store it creates, before the store's root group: the
#: positive sign that the pipeline started this store, so that a skeleton interrupted before
#: its record was written (which reads as a group without a pipeline record) is rebuilt, while
#: a Zarr store the pipeline did not write is refused (issue 45: one written by xarray was
#: deleted and replaced).  Removed once the skeleton's record is in place.
STARTED_MARKER = ".pipeline-skeleton"


# ---------------------------------------------------------------------------
# Lock
# ---------------------------------------------------------------------------


def lock_path(store: Path) -> Path:
    return store.with_name(store.name + ".lock")


def unwritable_reason(path: Path, exc: OSError) -> str:
    """Why ``path`` could not be created, in words: a file where a folder must be (mkdir says
    only "File exists" or "Not a directory" there), else the system's reason."""
    above = next((p for p in Path(path).parents if os.path.lexists(p)), None)
    if above is not None and not above.is_dir():
        return f"{above} is a file, not a folder"
    return exc.strerror or str(exc)


@contextmanager
def run_lock(store: Path):
    """Hold an exclusive lock on ``store`` for the duration of a run.

    The lock is an ``flock`` on ``<store>.lock``, which also records the holder's pid, host and
    start time.  The kernel drops an ``flock`` when its holder dies (SIGKILL, power loss), so a
    lock file left behind by a dead run is stale and is taken over; a live holder makes this
    raise :class:`StoreBusy` naming its pid, and leaves the file as it is (its holder's record
    is what the next refusal shows).  The holder empties the file when it is done; a run that
    leaves no store behind (refused, or stopped before its skeleton) removes the lock file it
    created, so nothing of it remains.  A lock file that cannot be created (a read-only
    folder, a path under a regular file) raises :class:`StoreUnwritable`.
    """
    path = lock_path(store)
    while True:
        created = not path.exists()
        try:
            path.parent.mkdir(parents=True, exist_ok=True)
            fd = os.open(path, os.O_RDWR | os.O_CREAT, 0o644)  # non-inheritable: spawned workers do not keep it
        except OSError as exc:
            raise StoreUnwritable(f"{store}: cannot create the store's lock file {path}: "
                                  f"{unwritable_reason(path, exc)}; choose another --store (or --out)") from None
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            try:
                holder = json.loads(os.pread(fd, 4096, 0).decode() or "{}")
            except (ValueError, OSError):
                holder = {}
            os.close(fd)  # the holder's record left as it is
            raise StoreBusy(
                f"{store}: another run is using this store (pid {holder.get('pid', '?')} on "
                f"{holder.get('host', '?')} since {holder.get('since', '?')}); lock file {path}"
            ) from None
        except BaseException:
            os.close(fd)
            raise
        # the file may have been removed by a run that held it and left no store (below)
        # between our open and our flock: then this lock is on a file no one else sees; retry
        try:
            same = os.stat(path).st_ino == os.fstat(fd).st_ino
        except FileNotFoundError:
            same = False
        if same:
            break
        os.close(fd)
    try:
        os.ftruncate(fd, 0)
        info = {"pid": os.getpid(), "host": platform.node(),
                "since": _dt.datetime.now(_dt.timezone.utc).isoformat(timespec="seconds")}
        os.pwrite(fd, json.dumps(info).encode(), 0)
        yield path
    finally:
        try:
            if created and not os.path.lexists(store):
                os.unlink(path)  # nothing was written: nothing of this run remains
            else:
                os.ftruncate(fd, 0)  # the empty file is harmless and reused next time
        except OSError:
            pass
        os.close(fd)  # releases the flock


# ---------------------------------------------------------------------------
# Provenance
# ---------------------------------------------------------------------------


@functools.lru_cache(maxsize=None)
def _git_commit() -> str | None:
    """The commit of the checkout this process imported the pipeline from ("+dirty" with
    uncommitted changes), None outside git; asked once per process (two git calls, ~10 ms: a
    ``paper`` run builds 16 skeletons)."""
    here = Path(__file__).resolve().parent
    try:
        commit = subprocess.run(["git", "-C", str(here), "rev-parse", "HEAD"], capture_output=True,
                                text=True, timeout=5)
        if commit.returncode != 0:
            return None
        dirty = subprocess.run(["git", "-C", str(here), "status", "--porcelain", "--untracked-files=no"],
                               capture_output=True, text=True, timeout=5)
        return commit.stdout.strip() + ("+dirty" if dirty.stdout.strip() else "")
    except (OSError, subprocess.SubprocessError):
        return None


@functools.lru_cache(maxsize=None)
def _versions() -> dict[str, str]:
    """Versions of the libraries this process runs on, read once per process (reading a
    package's metadata costs ~5 ms)."""
    import importlib.metadata as md

    out = {"python": platform.python_version()}
    for name in ("numpy", "scipy", "numba", "dask", "distributed", "zarr", "xarray"):
        try:
            out[name] = md.version(name)
        except md.PackageNotFoundError:
            pass
    return out


@functools.lru_cache(maxsize=None)
def _package_version() -> str:
    import importlib.metadata as md

    try:
        return md.version("twolink")
    except md.PackageNotFoundError:
        return "0+unknown"


def read_provenance_once() -> None:
    """Read what every store's provenance shares and this process reads once (the libraries'
    versions, the package's, the git commit): a run of many scenes pays it before its first
    scene instead of inside it."""
    _versions(), _package_version(), _git_commit()


def provenance(scene: Scene) -> dict:
    return {
        "scene_name": scene.name,
        "scene_file": str(scene.path),
        "scene_hash": scene.hash,
        "engines": engine_versions(),
        "engine_options": engine_options(),
        "scene": scene.science,
        "scene_toml": scene.text,
        "title": scene.title,
        "figure": scene.figure,
        "package_version": _package_version(),
        "git_commit": _git_commit(),
        "library_versions": dict(_versions()),
        "created": _dt.datetime.now(_dt.timezone.utc).isoformat(timespec="seconds"),
        "host": platform.node(),
    }


# ---------------------------------------------------------------------------
# Skeleton
# ---------------------------------------------------------------------------


def output_dtype(name: str):
    if name in ("iterations", "n_tau"):
        return np.dtype(np.int32), 0
    if name == "status":
        return np.dtype(np.int8), NOT_COMPUTED
    return np.dtype(np.float64), np.nan


def open_group(store: Path, mode: str):
    """The store's root group (Zarr format 3, metadata read unconsolidated)."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return zarr.open_group(store=str(store), mode=mode, zarr_format=3, use_consolidated=False)


def status_meanings(method: str | None = None) -> dict[str, str]:
    """{code: meaning} of the solver's statuses, in the words of engine ``method`` (None:
    whichever engine gave it, ``solver.STATUS_REASONS``)."""
    import solver

    meanings = {str(NOT_COMPUTED): "not computed yet"}
    meanings.update({str(int(k)): (solver.status_reason(k, method) if method else str(v))
                     for k, v in sorted(solver.STATUS_REASONS.items())})
    return meanings


def reduction_arrays(scene: Scene, r: Reduction) -> tuple[tuple[str, ...], tuple[int, ...], dict[str, tuple]]:
    """Dimensions, shape and {array name: (dtype, fill, attrs)} of reduction ``r``'s results."""
    kept = tuple(a for a in scene.axes if a.name not in r.over)
    dims = tuple(a.name for a in kept)
    shape = tuple(a.size for a in kept)
    if r.subsets is not None:
        dims += (r.subsets.dim,)
        shape += (len(r.subsets.labels),)
    f8 = np.dtype(np.float64)
    what = f"{r.statistic} of {r.quantity} over {', '.join(r.over)}"
    arrays: dict[str, tuple] = {}
    prefixes = [("", "grid")] + ([("_polished", "polished")] if r.polish else [])
    for suffix, kind in prefixes:
        base = f"{r.name}{suffix}"
        label = f"{what} ({'best grid point' if kind == 'grid' else 'polished by ' + r.polish_method})"
        # the paper's quantities are nondimensional (lengths in link lengths, mu_n mu_s = 1): units "1"
        arrays[base] = (f8, np.nan, {"long_name": label, "units": "1"})
        if r.statistic == "absmax":
            arrays[f"{base}_signed"] = (f8, np.nan, {"long_name": f"signed {r.quantity} at the optimum of {base}",
                                                       "units": "1"})
        for ax in r.over:
            arrays[f"{base}_{ax}"] = (f8, np.nan, {"long_name": f"{ax} at the optimum of {base}",
                                                 **{k: v for k, v in axis_attrs(ax).items() if k == "units"}})
        for q in r.report:
            if q in (r.quantity,):
                continue
            arrays[f"{base}_{q}"] = (f8, np.nan, {"long_name": f"{q} at the optimum of {base}", "units": "1"})
        if kind == "polished":
            from .polish import STATUS_MEANINGS

            arrays[f"{base}_status"] = (np.dtype(np.int8), NOT_COMPUTED,
                                        {"long_name": f"polish status of {r.name} (pipeline.polish.record)",
                                         "flag_meanings": {str(NOT_COMPUTED): "not computed yet", **STATUS_MEANINGS}})
            arrays[f"{base}_evaluations"] = (np.dtype(np.int32), 0,
                                             {"long_name": "solver calls spent polishing (all starts)"})
            arrays[f"{base}_uncertainty"] = (f8, np.nan, {
                "long_name": f"relative convergence estimate of {base}: spread of the starts that reached "
                             "the best basin, else the best start's last relative change", "units": "1"})
            for ax in r.over:
                arrays[f"{base}_{ax}_edge"] = (np.dtype(np.int8), 0, {
                    "long_name": f"{ax} at the optimum of {base} on the polish domain's edge",
                    "flag_meanings": {"-1": "lower end", "0": "interior", "1": "upper end"}})
    return dims, shape, arrays


def create_array(group, name, *, shape, chunks, dtype, fill, dims, attrs):
    """A new array ``name`` in ``group`` (replacing one of that name), labelled by ``dims``,
    its attributes ``attrs`` (the Python view) stored as netCDF takes them
    (:func:`pipeline._attrs.encode_attrs`).  A float array must say its ``units`` ("1" where
    dimensionless): CF asks it of every quantity.  In a kind's skeleton (:class:`Skeleton`)
    ``chunks`` over the scene's dimensions is the task unit, a block; :func:`finish_skeleton`
    stores the array in chunks of whole blocks (:func:`storage_chunks`)."""
    if np.dtype(dtype).kind == "f" and "units" not in attrs:
        raise ValueError(f"array {name!r}: a float array needs 'units' in its attributes ('1' if dimensionless)")
    return group.create_array(name, shape=tuple(shape), chunks=tuple(chunks), dtype=dtype, fill_value=fill,
                              dimension_names=list(dims), attributes=encode_attrs(attrs, np.dtype(dtype)),
                              overwrite=True)


class Skeleton:
    """A kind's skeleton as it declares it (``create_array``, ``create_group``, ``in``,
    ``attrs``, and ``[:] = values`` on an array), recorded: :func:`finish_skeleton` chooses the
    storage chunks once every array is known, then creates them through zarr's public API."""

    def __init__(self, path: str = "", root: "Skeleton | None" = None):
        self.path, self.root = path, root or self
        if root is None:
            self.groups: list[str] = []
            self.arrays: dict[str, dict] = {}
            self.values: dict[str, np.ndarray] = {}
            self.group_attrs: dict[str, dict] = {}
        self.attrs: dict = self.root.group_attrs.setdefault(path, {})

    def _key(self, name: str) -> str:
        return f"{self.path}/{name}" if self.path else name

    def __contains__(self, name: str) -> bool:
        return self._key(name) in self.root.groups or self._key(name) in self.root.arrays

    def create_group(self, name: str) -> "Skeleton":
        self.root.groups.append(self._key(name))
        return Skeleton(self._key(name), self.root)

    def create_array(self, name: str, **kwargs) -> "_Declared":
        self.root.arrays[self._key(name)] = kwargs
        return _Declared(self.root, self._key(name))


class _Declared:
    """An array of a :class:`Skeleton`: ``[:] = values`` records its values."""

    def __init__(self, root: Skeleton, key: str):
        self.root, self.key = root, key

    def __setitem__(self, selection, values) -> None:
        if selection != slice(None):
            raise ValueError(f"{self.key}: a skeleton's array is filled whole ([:] = values)")
        self.root.values[self.key] = np.asarray(values)


def new_group(store: Path) -> Skeleton:
    """The first step of every kind's skeleton: an empty root group at ``store`` (whatever was
    there removed: the caller decides whether that is allowed), and the :class:`Skeleton` the
    kind declares its arrays in, created in ``store`` by :func:`finish_skeleton`.

    The store's :data:`STARTED_MARKER` is written (and synced) before anything else, so a run
    killed at any point before the skeleton's record is in place leaves a store that the next
    run recognises as its own interrupted skeleton and rebuilds (:func:`open_existing`)."""
    if store.exists():
        shutil.rmtree(store)
    store.mkdir(parents=True)
    marker = store / STARTED_MARKER
    with open(marker, "w") as f:
        json.dump({"started_by": "twolink pipeline", "pid": os.getpid(), "host": platform.node(),
                   "since": _dt.datetime.now(_dt.timezone.utc).isoformat(timespec="seconds")}, f)
        f.flush()
        os.fsync(f.fileno())
    _fsync_all([store])  # the marker's entry durable before the group exists
    open_group(store, "a")  # on disk at once ("a": the marker kept); from here on an interrupted skeleton
    return Skeleton()


#: uncompressed bytes aimed at for one chunk of the largest output per point (1 MiB: 131,072
#: float64 grid points), inside the 0.5-8 MB that xarray, Dask and object stores work well
#: with (issue 46); a chunk holds at least one block (a task's unit), so it may be smaller
CHUNK_BYTES = 1 << 20


def chunk_bytes() -> int:
    """:data:`CHUNK_BYTES`, or ``TWOLINK_PIPELINE_CHUNK_BYTES`` where set (the tests set 1: one
    block per chunk, so that a small scene has several chunks to kill and resume).  It decides
    a new store's chunks only: a store keeps the chunks its record names."""
    return int(os.environ.get("TWOLINK_PIPELINE_CHUNK_BYTES") or CHUNK_BYTES)


def storage_chunks(shape, blocks, point_bytes: int, target: int | None = None) -> tuple[int, ...]:
    """The storage chunk over ``shape``: whole ``blocks`` (so each block lies in one chunk), as
    many as fit ``target`` bytes (:func:`chunk_bytes`) at ``point_bytes`` per point, trailing
    axes first (whole while they fit, then the axis where the room runs out cut into the fewest
    equal runs of blocks); at least one block.

    >>> storage_chunks((3, 3, 20, 20), (1, 1, 10, 20), 8, 8 * 1000)   # room for 1000 points: 2 x 400
    (1, 2, 20, 20)
    """
    target = chunk_bytes() if target is None else int(target)
    room = max(1, target // max(1, int(point_bytes)))
    chunks = [int(b) for b in blocks]
    for i in range(len(chunks) - 1, -1, -1):
        others = int(np.prod(chunks)) // chunks[i]
        n_blocks = -(-int(shape[i]) // int(blocks[i]))
        fit = room // (others * int(blocks[i]))
        if fit >= n_blocks:
            chunks[i] = int(shape[i])
            continue
        if fit > 1:
            chunks[i] = -(-n_blocks // -(-n_blocks // fit)) * int(blocks[i])
        break
    return tuple(chunks)


def _laid_over(kw: dict, dims, shape, blocks) -> bool:
    """Whether a declared array is laid over the scene's dimensions in blocks (its leading
    dimensions, shape and chunks those of the layout): stored in the layout's chunks."""
    n = len(dims)
    return (tuple(kw["dimension_names"][:n]) == tuple(dims) and tuple(kw["shape"][:n]) == tuple(shape)
            and tuple(kw["chunks"][:n]) == tuple(blocks))


def _write_skeleton(g: Skeleton, store: Path) -> None:
    """Create the skeleton ``g`` in ``store`` through zarr: groups, arrays, their values, then
    the groups' attributes, the root's (its ``pipeline`` record, ``skeleton_complete`` set)
    last."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        made = {"": open_group(store, "r+")}
        for key in g.groups:  # parents before children, as declared
            parent, _, name = key.rpartition("/")
            made[key] = made[parent].create_group(name)
        for key, kw in g.arrays.items():
            parent, _, name = key.rpartition("/")
            arr = made[parent].create_array(name, **kw)
            if key in g.values:
                arr[...] = g.values[key]
        for key in sorted(made, key=lambda k: (k == "", k)):
            if g.group_attrs.get(key):
                made[key].update_attributes(g.group_attrs[key])


def finish_skeleton(g, scene, *, store: Path, dims, shape, chunks, head: dict | None = None,
                    layout: dict | None = None, reductions_complete: bool = False,
                    series_complete: bool = True) -> None:
    """The part of every kind's skeleton that is the same.  ``chunks`` is the task unit over
    the scene's ``dims`` and ``shape``, a block (what one task solves at a time, and with
    sweeps a unit of the science: ``_grid.scene_chunks``); every declared array laid over the
    scene in blocks is stored in chunks of whole blocks (:func:`storage_chunks`, sized by the
    largest of them per point), each written once, by the driver, whole (:class:`ChunkWriter`).
    Then the done markers (one per storage chunk, labelled ``chunk_<dim>``) and the ``pipeline``
    attributes (``head`` first: ``kind`` and its version; provenance, layout with ``blocks``
    and ``chunks``, state); the skeleton ``g`` is created in ``store`` with its record last, so
    that ``skeleton_complete`` is set only on a whole skeleton."""
    blocks = tuple(int(c) for c in chunks)
    laid = {k: kw for k, kw in g.arrays.items() if _laid_over(kw, dims, shape, blocks)}
    point_bytes = max((np.dtype(kw["dtype"]).itemsize * int(np.prod(kw["shape"][len(dims):]))
                       for kw in laid.values()), default=8)
    stored = storage_chunks(shape, blocks, point_bytes)
    for kw in laid.values():
        kw["chunks"] = stored + tuple(kw["chunks"][len(dims):])
    grid = tuple(-(-int(s) // int(c)) for s, c in zip(shape, stored))
    sg = g.create_group(STATE_GROUP)
    create_array(sg, "chunk_done", shape=grid, chunks=(1,) * len(grid), dtype=np.uint8, fill=0,
                 dims=tuple(f"chunk_{d}" for d in dims),
                 attrs={"long_name": "1 once every output of the chunk is written and synced (written last)"})
    g.attrs[ATTRS_KEY] = record_text({
        "format_version": FORMAT_VERSION, **(head or {}),
        "provenance": provenance(scene),
        "layout": {"dims": list(dims), "shape": [int(s) for s in shape], "blocks": list(blocks),
                   "chunks": list(stored), "chunk_grid": list(grid), **(layout or {})},
        "state": {"skeleton_complete": True, "chunks_complete": False,
                  "reductions_complete": bool(reductions_complete), "series_complete": bool(series_complete)},
    })
    _write_skeleton(g, Path(store))
    _remove_started_marker(Path(store))


def _remove_started_marker(store: Path) -> None:
    """The skeleton's record in place: the store is recognised by it from now on, and its
    :data:`STARTED_MARKER` has done its work (the folder synced first, so that no power loss
    leaves a store with neither)."""
    _fsync_all([store])
    (store / STARTED_MARKER).unlink(missing_ok=True)


def create_skeleton(store: Path, scene: Scene, chunks: tuple[int, ...]) -> None:
    """Create the whole store (every array, coordinate and attribute) before any task runs;
    ``chunks``: the blocks the tasks solve (``_grid.scene_chunks``).

    Any existing content at ``store`` is removed first (the caller decides whether that is allowed).
    ``pipeline.state.skeleton_complete`` is set last, so a skeleton interrupted half-way is
    simply rebuilt by the next run.
    """
    g = new_group(store)
    for a in scene.axes:
        create_array(g, a.name, shape=(a.size,), chunks=(a.size,), dtype=np.float64, fill=np.nan,
                     dims=(a.name,), attrs={**axis_attrs(a.name), "spacing": a.spacing})[:] = a.array()
    shape = scene.shape
    for name in scene.outputs + ("status",):
        dtype, fill = output_dtype(name)
        # the paper's nondimensional quantities (lengths in link lengths, mu_n mu_s = 1): units "1"
        attrs = {"long_name": QUANTITIES.get(name) or DIAGNOSTICS.get(name) or "solver status", "units": "1"}
        if name == "status":
            del attrs["units"]
            attrs["flag_meanings"] = status_meanings(scene.method)
            attrs["long_name"] = "solver status: 0 converged; any other code is a failure (outputs NaN)"
        create_array(g, name, shape=shape, chunks=chunks, dtype=dtype, fill=fill, dims=scene.dims, attrs=attrs)
    for r in scene.reductions:
        dims, rshape, arrays = reduction_arrays(scene, r)
        if r.subsets is not None:
            s = r.subsets
            if s.kind == "window":
                attrs = {"long_name": f"half-width of the {s.axes[0]} window centred at {s.center:g}",
                         "units": axis_attrs(s.axes[0])["units"]}
            else:
                attrs = {"long_name": f"index of the set of exponents allowed for {', '.join(s.axes)}", "units": "1",
                         "sets": [list(x) for x in s.sets]}
            if s.dim not in g:
                create_array(g, s.dim, shape=(len(s.labels),), chunks=(len(s.labels),), dtype=np.float64,
                             fill=np.nan, dims=(s.dim,), attrs=attrs)[:] = np.asarray(s.labels)
        rchunks = tuple(max(1, n) for n in rshape)
        for name, (dtype, fill, attrs) in arrays.items():
            create_array(g, name, shape=rshape, chunks=rchunks, dtype=dtype, fill=fill, dims=dims,
                         attrs={**attrs, "reduction": r.name})
    if scene.series is not None:
        ser = scene.series
        n = len(ser.points)
        create_array(g, "series_point", shape=(n,), chunks=(n,), dtype=np.int32, fill=-1, dims=("series_point",),
                     attrs={"long_name": "index of a point where u(tau) is stored"})[:] = np.arange(n)
        create_array(g, "series_tau", shape=(ser.n_tau,), chunks=(ser.n_tau,), dtype=np.float64, fill=np.nan,
                     dims=("series_tau",), attrs={"long_name": "scaled time tau = t/T", "units": "1"}
                     )[:] = np.arange(ser.n_tau) / ser.n_tau
        for d in scene.dims:
            create_array(g, f"series_{d}", shape=(n,), chunks=(n,), dtype=np.float64, fill=np.nan,
                         dims=("series_point",), attrs=axis_attrs(d))[:] = [dict(p)[d] for p in ser.points]
        create_array(g, "series_u", shape=(n, ser.n_tau), chunks=(n, ser.n_tau), dtype=np.float64, fill=np.nan,
                     dims=("series_point", "series_tau"),
                     attrs={"long_name": "scaled velocity u(tau) = T dx_CM/dt (eq. tau), resampled to uniform tau",
                            "units": "1"})
        create_array(g, "series_status", shape=(n,), chunks=(n,), dtype=np.int8, fill=NOT_COMPUTED,
                     dims=("series_point",), attrs={"long_name": "solver status of the series points",
                                                    "flag_meanings": status_meanings(scene.method)})
    finish_skeleton(g, scene, store=store, dims=scene.dims, shape=shape, chunks=chunks,
                    reductions_complete=False, series_complete=scene.series is None)


def open_existing(store: Path) -> dict | None:
    """The pipeline record of an existing store (the Python view, of either format: the caller
    checks ``format_version``), or None where there is no store yet (nothing there, an empty
    folder) or a skeleton the pipeline started and did not finish (:data:`STARTED_MARKER`; or
    a record without ``skeleton_complete``): the caller builds it anew.

    Raises :class:`StoreMismatch` where ``store`` is not a Zarr store (a file, a folder of other
    files: never touched, ``--overwrite`` or not), and :class:`StoreForeign` where it is a Zarr
    store (or an unreadable one) that the pipeline did not write: no pipeline record and no
    start marker (replaced only with ``--overwrite``).
    """
    if not os.path.lexists(store):
        return None
    if not store.is_dir():
        raise StoreMismatch(f"{store}: exists and is not a Zarr store (a file); refusing to touch it: "
                            "choose another --store")
    if not any(store.iterdir()):
        return None
    meta = None
    if (store / "zarr.json").is_file():
        try:
            meta = read_record(dict(open_group(store, "r").attrs))
        except Exception:  # an unreadable group: ours only if the marker says so (below)
            meta = None
    if meta and meta.get("state", {}).get("skeleton_complete"):
        return meta
    if meta or (store / STARTED_MARKER).is_file():
        return None  # a skeleton of ours, interrupted: rebuilt by the caller
    if not (store / "zarr.json").is_file():
        raise StoreMismatch(f"{store}: exists and is not a Zarr store (a folder of other files); refusing "
                            "to touch it: choose another --store")
    raise StoreForeign(f"{store}: a Zarr store the pipeline did not write (no pipeline record); refusing "
                       "to replace it: rerun with --overwrite to replace it, or choose another --store")


def _update_record(store: Path, update) -> None:
    """Rewrite the store's record as ``update(record)`` returns it (the driver only)."""
    g = open_group(store, "r+")
    g.attrs[ATTRS_KEY] = record_text(update(read_record(dict(g.attrs))))


def set_state(store: Path, **state) -> None:
    """Set flags of the record's ``state``."""
    _update_record(store, lambda meta: {**meta, "state": {**meta["state"], **state}})


def record_run(store: Path, run: dict) -> None:
    """Record the latest run that computed something (``run``), and accumulate compute time."""
    def update(meta):
        previous = meta.get("run", {})
        new = dict(run)
        new["wall_seconds_all_runs"] = float(previous.get("wall_seconds_all_runs", 0.0)) + float(new["wall_seconds"])
        new["runs"] = int(previous.get("runs", 0)) + 1
        return {**meta, "run": new}

    _update_record(store, update)


def remove_partials(store: Path) -> int:
    """Delete temporary files of writes interrupted by a kill (Zarr writes to *.partial then
    renames), and a :data:`STARTED_MARKER` outliving the record of a complete skeleton (a kill
    between the two)."""
    (store / STARTED_MARKER).unlink(missing_ok=True)
    n = 0
    for p in store.rglob("*.partial"):
        p.unlink(missing_ok=True)
        n += 1
    return n


def read_done(store: Path) -> np.ndarray:
    """The done markers, one per storage chunk: True where the chunk is stored whole."""
    return read_arrays(store, [DONE_ARRAY])[DONE_ARRAY] == 1


def _fsync_all(paths) -> None:
    """fsync every path (files and folders); one that is gone (a chunk zarr removed because it
    held only fill values) has nothing left to sync."""
    for path in paths:
        try:
            fd = os.open(path, os.O_RDONLY)
        except FileNotFoundError:
            continue
        try:
            os.fsync(fd)
        finally:
            os.close(fd)


def _files_under(folder: Path) -> list[Path]:
    """Every file below ``folder`` (none where it does not exist)."""
    return [Path(dirpath) / name for dirpath, _, names in os.walk(folder) for name in names]


def sync_written(array, since_ns: int) -> int:
    """Make what was written to ``array`` (a ``zarr.Array`` of a local store) since
    ``since_ns`` (``time.time_ns()``) durable: every file below the array's folder (a local
    store keeps each key as a file there, whatever its chunk key encoding or sharding: no key
    path is built by hand) modified since then (a second's margin for the file system's coarser
    clock) is fsynced, then its folders and the array's.  The files synced.

    Plain ``os.walk``, not the store's asynchronous listing: a Ctrl-C between creating that
    listing's coroutine and running it left a "coroutine was never awaited" warning under the
    run's one line (seen once in CI, tests/test_pipeline_mistakes.py[Ctrl-C])."""
    root = Path(array.store.root)
    files = []
    for path in _files_under(root / array.path):
        try:
            if path.stat().st_mtime_ns >= since_ns - 1_000_000_000:
                files.append(path)
        except FileNotFoundError:
            pass
    _fsync_all(files + sorted({p.parent for p in files} | {root / array.path}))
    return len(files)


@dataclass(frozen=True)
class ChunkWrite:
    """What a task computed for one block of some arrays: ``values`` {array name: ndarray of
    the region's shape}, at ``region`` of arrays of ``shape``; ``chunk_index`` and ``chunks``
    are the block's index and the block layout (the trailing, non-scene axes whole)."""

    region: tuple
    chunk_index: tuple
    chunks: tuple
    shape: tuple
    values: dict


@dataclass(frozen=True)
class SolvedChunk:
    """What a kind's ``solve_chunk`` computed for one block: its writes (one per group of
    arrays of one shape), the points it holds, their failures and the seconds spent solving."""

    writes: tuple
    points: int
    failures: int
    seconds: float


def mark_done(store: Path, index: tuple[int, ...]) -> None:
    """Set the done marker of storage chunk ``index`` (after its data is durable)."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        zarr.open_array(store=str(store), path=DONE_ARRAY, mode="r+")[tuple(index)] = 1


def blocks_in(index, shape, blocks, chunks) -> list[tuple[int, ...]]:
    """The blocks (indices in the block layout) of storage chunk ``index``, in C order."""
    ranges = []
    for i, s, b, c in zip(index, shape, blocks, chunks):
        lo = i * c // b
        ranges.append(range(lo, -(-min((i + 1) * c, s) // b)))
    return [tuple(ix) for ix in itertools.product(*ranges)]


class ChunkWriter:
    """The driver's writer of one run's chunks, the one writer of every chunk of the store.

    The tasks return what they computed (:class:`SolvedChunk`, one per block); :meth:`add`
    places a block in its storage chunk's buffers, and once every block of the chunk has come,
    writes each array's region of the chunk through zarr (``array[region] = values``: whole,
    aligned chunks), makes them durable (:func:`sync_written`), and only then sets the chunk's
    done marker (:func:`mark_done`).  A run stopped before that loses the chunk's blocks, and
    the next run computes them again: a resumed store equals an uninterrupted one.

    ``layout``: the record's (``dims``, ``shape``, ``blocks``, ``chunks``); ``pending``: the
    storage chunks to write.  ``seconds``: time spent writing, syncing and marking.
    """

    def __init__(self, store: Path, layout: dict, pending):
        self.store = Path(store)
        self.shape = tuple(int(n) for n in layout["shape"])
        self.blocks = tuple(int(n) for n in layout["blocks"])
        self.chunks = tuple(int(n) for n in layout["chunks"])
        self.missing = {tuple(c): len(blocks_in(c, self.shape, self.blocks, self.chunks)) for c in pending}
        self.buffers: dict[tuple, dict[str, np.ndarray]] = {}
        self.arrived: dict[tuple, set] = {}
        self.arrays: dict[str, object] = {}
        self.seconds = {"write": 0.0, "sync": 0.0, "mark": 0.0}
        self.written = 0

    def chunk_of(self, block) -> tuple[int, ...]:
        return tuple(int(i) * b // c for i, b, c in zip(block, self.blocks, self.chunks))

    def chunk_region(self, index) -> tuple[slice, ...]:
        return tuple(slice(i * c, min((i + 1) * c, s)) for i, c, s in zip(index, self.chunks, self.shape))

    def add(self, block, solved: SolvedChunk) -> tuple[int, ...] | None:
        """Place block ``block``'s values; the storage chunk written and marked if it is whole
        now (else None)."""
        chunk = self.chunk_of(block)
        if chunk not in self.missing:
            raise ValueError(f"{self.store}: block {tuple(block)} lies in chunk {chunk}, which is not to be written")
        n = len(self.shape)
        region = self.chunk_region(chunk)
        own = tuple(slice(i * b, min((i + 1) * b, s)) for i, b, s in zip(block, self.blocks, self.shape))
        buffers = self.buffers.setdefault(chunk, {})
        names = {name for w in solved.writes for name in w.values}
        if buffers and set(buffers) != names:
            raise ValueError(f"{self.store}: block {tuple(block)} writes {sorted(names)}, its chunk's other blocks "
                             f"{sorted(buffers)}")
        for w in solved.writes:
            if tuple(w.region[:n]) != own or any(sl != slice(0, m) for sl, m in zip(w.region[n:], w.shape[n:])):
                raise ValueError(f"{self.store}: a write at {w.region} is not block {tuple(block)} (whole trailing axes)")
            at = tuple(slice(o.start - r.start, o.stop - r.start) for o, r in zip(own, region))
            for name, v in w.values.items():
                v = np.asarray(v)
                if name not in buffers:
                    buffers[name] = np.empty(tuple(r.stop - r.start for r in region) + tuple(w.shape[n:]), v.dtype)
                buffers[name][at] = v
        arrived = self.arrived.setdefault(chunk, set())
        if tuple(block) in arrived:
            return None  # a task run twice (a lost worker's, rerun): the same values again
        arrived.add(tuple(block))
        self.missing[chunk] -= 1
        if self.missing[chunk] > 0:
            return None
        self.write(chunk, self.buffers.pop(chunk))
        del self.missing[chunk], self.arrived[chunk]
        return chunk

    def _array(self, name: str):
        if name not in self.arrays:
            self.arrays[name] = zarr.open_array(store=str(self.store), path=name, mode="r+")
        return self.arrays[name]

    def write(self, chunk, values: dict[str, np.ndarray]) -> None:
        """Write storage chunk ``chunk`` of every array in ``values``, sync it, then mark it."""
        region = self.chunk_region(chunk)
        t0, since = time.perf_counter(), time.time_ns()
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            arrays = {name: self._array(name) for name in values}
            for name, v in values.items():
                a = arrays[name]
                # whole, aligned chunks: the region is exactly the array's chunk ``chunk``
                assert tuple(a.chunks[:len(region)]) == self.chunks, f"{name}: chunks {a.chunks} != {self.chunks}"
                a[region + (slice(None),) * (v.ndim - len(region))] = v.astype(a.dtype, copy=False)
        t1 = time.perf_counter()
        for a in arrays.values():
            sync_written(a, since)
        t2 = time.perf_counter()
        # Test hook: widen the window between data and marker, where a kill leaves a half-done chunk.
        time.sleep(float(os.environ.get("TWOLINK_PIPELINE_MARKER_DELAY", "0") or 0))
        t3 = time.perf_counter()
        mark_done(self.store, chunk)
        self.seconds["write"] += t1 - t0
        self.seconds["sync"] += t2 - t1
        self.seconds["mark"] += time.perf_counter() - t3
        self.written += 1


def read_arrays(store: Path, names) -> dict[str, np.ndarray]:
    """The whole arrays ``names`` of ``store``, in memory (through zarr)."""
    out = {}
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        for n in names:
            out[n] = zarr.open_array(store=str(store), path=n, mode="r")[...]
    return out


def write_arrays(store: Path, arrays: dict[str, np.ndarray]) -> None:
    """Write whole arrays (the driver's reductions), cast to each stored array's dtype."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        for n, v in arrays.items():
            a = zarr.open_array(store=str(store), path=n, mode="r+")
            a[...] = np.asarray(v).astype(a.dtype)


def consolidate(store: Path) -> None:
    """Write the consolidated metadata (readers open the store with one read)."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        zarr.consolidate_metadata(str(store), zarr_format=3)


def store_meta(store: Path) -> dict:
    """The ``pipeline`` record of ``store`` (provenance, layout, state, run), decoded."""
    return read_record(dict(open_group(store, "r").attrs))


#: Flags of ``pipeline.state`` besides ``skeleton_complete``; a store is complete when all are set.
STATE_FLAGS = ("chunks_complete", "reductions_complete", "series_complete")


def is_complete(state: dict) -> bool:
    """Every part of the store written (``state``: the ``pipeline.state`` attribute)."""
    return all(state.get(flag) for flag in STATE_FLAGS)
