"""The Zarr store of a scene: skeleton, provenance, per-chunk done markers, run lock.

Layout (Zarr format 3, one group per scene)::

    <store>/                      group; attrs["pipeline"] = provenance + layout + state (JSON text)
        <axis>                    1-D coordinate array per axis, dimension_names [axis]
        <output>                  one array per stored quantity/diagnostic, dims = scene axes
        status                    int8, 0 converged, > 0 solver failure, -1 not computed (CF flags)
        <reduction arrays>        labelled by the kept axes (+ a subset dimension)
        pipeline_state/chunk_done uint8 per chunk, 1 once the chunk's outputs are all written

Only the driver writes attributes; tasks write only their own chunks and then their marker.
Every attribute goes through :mod:`pipeline._attrs` (:func:`create_array`, the record's
functions here), so a store is netCDF- and CF-ready: ``xarray.open_zarr(store).to_netcdf(path)``
works on it as it is (format 2, issue 34).
"""

from __future__ import annotations

import datetime as _dt
import fcntl
import functools
import json
import os
import platform
import shutil
import subprocess
import warnings
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import zarr

from solver.periodic.options import engine_options

from ._attrs import ATTRS_KEY, encode_attrs, read_record, record_text
from ._chunks import chunk_key, layout_is_plain, read_whole, write_chunk, write_whole
from ._grid_scene import DIAGNOSTICS, QUANTITIES, Reduction, Scene, axis_attrs
from ._scene import engine_versions

__all__ = [
    "ATTRS_KEY",
    "FORMAT_VERSION",
    "NOT_COMPUTED",
    "STATE_GROUP",
    "STARTED_MARKER",
    "StoreBusy",
    "StoreForeign",
    "StoreMismatch",
    "StoreUnwritable",
    "unwritable_reason",
    "create_skeleton",
    "finish_skeleton",
    "SkeletonGroup",
    "new_group",
    "open_existing",
    "output_dtype",
    "reduction_arrays",
    "run_lock",
    "read_done",
    "is_marked",
    "mark_done",
    "write_region",
    "ChunkWrite",
    "SolvedChunk",
    "store_chunk",
    "remove_partials",
    "provenance",
    "set_state",
    "record_run",
    "status_meanings",
    "create_array",
    "open_group",
    "read_arrays",
    "write_arrays",
    "consolidate",
    "store_meta",
    "is_complete",
    "STATE_FLAGS",
    "COMPACT_ELEMENTS",
    "COMPACT_FILES",
    "wants_compaction",
    "compact",
    "compact_chunks",
    "expand",
    "rechunk",
    "recover_rechunk",
]

#: Layout version of the store (readers such as reports/ check it).  2 (issue 34): attributes
#: as netCDF takes them (``_attrs``: the record as JSON text, CF flags, ``units`` on every float
#: array); 1: nested attributes (read by the reports, refused for resuming).
FORMAT_VERSION = 2
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
    dimensionless): CF asks it of every quantity."""
    if np.dtype(dtype).kind == "f" and "units" not in attrs:
        raise ValueError(f"array {name!r}: a float array needs 'units' in its attributes ('1' if dimensionless)")
    return group.create_array(name, shape=shape, chunks=chunks, dtype=dtype, fill_value=fill,
                              dimension_names=list(dims), attributes=encode_attrs(attrs, np.dtype(dtype)),
                              overwrite=True)


class SkeletonGroup:
    """A kind's skeleton as it is declared: the groups, arrays (``create_array``'s arguments,
    and the values assigned with ``[:] = values``) and root attributes, recorded, then built
    in memory in one pass (:meth:`files`) and written by :func:`_write_skeleton`.

    Through zarr-python every array created or filled is one round trip through its event
    loop (~1 ms idle, 3-5 ms loaded, ~48 of them for a grid scene's skeleton: most of a
    small scene's set-up); recorded, they are made together, concurrently, in one.  Supports
    what the kinds' skeletons use of a zarr group: ``create_array``, ``create_group``, ``in``,
    ``attrs``."""

    def __init__(self, path: str = "", root: "SkeletonGroup | None" = None):
        self.path = path
        self.root = root or self
        if root is None:
            self.groups: list[str] = []
            self.arrays: list[tuple[str, dict]] = []
            self.values: dict[str, object] = {}
            self.group_attrs: dict[str, dict] = {}
        self.attrs: dict = self.root.group_attrs.setdefault(path, {})

    def _key(self, name: str) -> str:
        return f"{self.path}/{name}" if self.path else name

    def __contains__(self, name: str) -> bool:
        key = self._key(name)
        return key in self.root.groups or any(k == key for k, _ in self.root.arrays)

    def create_group(self, name: str) -> "SkeletonGroup":
        self.root.groups.append(self._key(name))
        return SkeletonGroup(self._key(name), self.root)

    def create_array(self, name: str, **kwargs) -> "_DeclaredArray":
        key = self._key(name)
        self.root.arrays.append((key, kwargs))
        return _DeclaredArray(self.root, key)

    def files(self) -> dict[str, bytes]:
        """{key: bytes} of every file of the skeleton, built by zarr in a memory store in one
        pass: groups, then every array at once, then their values, then the root's attributes."""
        import asyncio

        from zarr.core.group import AsyncGroup
        from zarr.core.sync import sync
        from zarr.storage import MemoryStore

        mem = MemoryStore()

        async def build():
            root = await AsyncGroup.from_store(mem, zarr_format=3)
            made = {"": root}
            for key in self.groups:  # parents before children, as declared
                parent, _, name = key.rpartition("/")
                made[key] = await made[parent].create_group(name)
            arrays = await asyncio.gather(*(made[k.rpartition("/")[0]].create_array(k.rpartition("/")[2], **kw)
                                            for k, kw in self.arrays))
            by_key = {k: a for (k, _), a in zip(self.arrays, arrays)}
            await asyncio.gather(*(by_key[k].setitem(slice(None), v) for k, v in self.values.items()))
            for key, group in made.items():
                attrs = self.group_attrs.get(key)
                if attrs:
                    await group.update_attributes(attrs)

        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            sync(build())
        return {k: v.to_bytes() for k, v in mem._store_dict.items()}


class _DeclaredArray:
    """An array of a :class:`SkeletonGroup`: ``[:] = values`` records its values."""

    def __init__(self, root: SkeletonGroup, key: str):
        self.root, self.key = root, key

    def __setitem__(self, selection, values) -> None:
        if selection != slice(None):
            raise ValueError(f"{self.key}: a skeleton's array is filled whole ([:] = values)")
        self.root.values[self.key] = np.asarray(values)


def new_group(store: Path) -> SkeletonGroup:
    """The first step of every kind's skeleton: an empty root group at ``store`` (whatever was
    there removed: the caller decides whether that is allowed), and the group the kind
    declares its skeleton in (:class:`SkeletonGroup`), built and written to ``store`` by
    :func:`finish_skeleton`.

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
    _fsync_path(store)  # the marker's entry durable before the group exists
    open_group(store, "a")  # on disk at once ("a": the marker kept); from here on an interrupted skeleton
    return SkeletonGroup()


def _write_skeleton(g: SkeletonGroup, store: Path) -> None:
    """Write the files of the skeleton ``g`` to ``store``: every file but the root group's
    metadata, then that one (its ``pipeline`` record, ``skeleton_complete`` set) last,
    replacing the empty group's atomically."""
    files = g.files()
    root = files.pop("zarr.json")
    for key in sorted(files):
        path = store / key
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_bytes(files[key])
    tmp = store / "zarr.json.partial"
    tmp.write_bytes(root)
    os.replace(tmp, store / "zarr.json")


def finish_skeleton(g, scene, *, store: Path, dims, shape, chunks, head: dict | None = None,
                    layout: dict | None = None, reductions_complete: bool = False,
                    series_complete: bool = True) -> None:
    """The part of every kind's skeleton that is the same: the done markers (one per chunk of
    the layout ``chunks`` over ``shape``, labelled ``chunk_<dim>``) and the ``pipeline``
    attributes (``head`` first: ``kind`` and its version; provenance, layout, state); then the
    skeleton ``g`` (built in memory, :func:`new_group`) is written to ``store``, its record
    last, so that ``skeleton_complete`` is set only on a whole skeleton."""
    grid = tuple(-(-int(s) // int(c)) for s, c in zip(shape, chunks))
    sg = g.create_group(STATE_GROUP)
    create_array(sg, "chunk_done", shape=grid, chunks=(1,) * len(grid), dtype=np.uint8, fill=0,
                 dims=tuple(f"chunk_{d}" for d in dims),
                 attrs={"long_name": "1 once every output of the chunk is written (written last by its task)"})
    g.attrs[ATTRS_KEY] = record_text({
        "format_version": FORMAT_VERSION, **(head or {}),
        "provenance": provenance(scene),
        "layout": {"dims": list(dims), "shape": [int(s) for s in shape], "chunks": [int(c) for c in chunks],
                   "chunk_grid": list(grid), **(layout or {})},
        "state": {"skeleton_complete": True, "chunks_complete": False,
                  "reductions_complete": bool(reductions_complete), "series_complete": bool(series_complete)},
    })
    _write_skeleton(g, Path(store))
    _remove_started_marker(Path(store))


def _remove_started_marker(store: Path) -> None:
    """The skeleton's record in place: the store is recognised by it from now on, and its
    :data:`STARTED_MARKER` has done its work (the folder synced first, so that no power loss
    leaves a store with neither)."""
    _fsync_path(store)
    (store / STARTED_MARKER).unlink(missing_ok=True)


def create_skeleton(store: Path, scene: Scene, chunks: tuple[int, ...]) -> None:
    """Create the whole store (every array, coordinate and attribute) before any task runs.

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


def is_marked(store: Path, index: tuple[int, ...]) -> bool:
    """Whether chunk ``index`` has its done marker (its marker's file exists: a marker is
    written as a value 1 where the fill is 0, so zarr and ``_chunks.write_chunk`` keep a file
    for it; read through zarr where the layout is not plain)."""
    meta = _plain_meta(store, DONE_ARRAY)
    if meta is None:
        return bool(read_done(store)[tuple(index)])
    return (store / DONE_ARRAY / chunk_key(meta, index)).is_file()


def read_done(store: Path) -> np.ndarray:
    """The done markers, one per chunk: True where the chunk is stored whole (read as
    :func:`read_arrays` reads, one file per chunk)."""
    return read_arrays(store, [DONE_ARRAY])[DONE_ARRAY] == 1


def _fsync_path(path: Path) -> None:
    try:
        fd = os.open(path, os.O_RDONLY)
    except FileNotFoundError:
        return  # an all-fill chunk is not written by Zarr
    try:
        os.fsync(fd)
    finally:
        os.close(fd)


#: array handles of this process, by (store, array), with the mtime of the array's zarr.json:
#: a task's chunks reopen the same arrays, and opening one reads and parses its metadata (~1 ms
#: idle, ~10 ms loaded, for each of a chunk's arrays); a skeleton rebuilt in place has a new mtime
_ARRAYS: dict[tuple[str, str], tuple[int, object]] = {}
_ARRAYS_KEPT = 256


def _array(store: Path, name: str):
    key = (str(store), name)
    mtime = os.stat(store / name / "zarr.json").st_mtime_ns
    hit = _ARRAYS.get(key)
    if hit is not None and hit[0] == mtime:
        return hit[1]
    if len(_ARRAYS) >= _ARRAYS_KEPT:
        _ARRAYS.clear()
    arr = zarr.open_array(store=str(store), path=name, mode="r+")
    _ARRAYS[key] = (mtime, arr)
    return arr


_FSYNC_POOL = None


def _fsync_all(paths) -> None:
    """fsync every path, concurrently: a journalling file system commits concurrent fsyncs
    together (ext4's group commit) instead of one journal commit each."""
    global _FSYNC_POOL
    paths = list(paths)
    if len(paths) <= 1:
        for path in paths:
            _fsync_path(path)
        return
    if _FSYNC_POOL is None:
        from concurrent.futures import ThreadPoolExecutor

        _FSYNC_POOL = ThreadPoolExecutor(8, thread_name_prefix="fsync")
    list(_FSYNC_POOL.map(_fsync_path, paths))


#: decoded ``zarr.json`` of this process's arrays written directly, by (store, array), keyed by
#: the file's inode and mtime (a skeleton rebuilt in place writes a new file); None where the
#: layout is not ``_chunks.layout_is_plain`` (written through zarr then)
_METAS: dict[tuple[str, str], tuple[tuple[int, int], dict | None]] = {}


def _plain_meta(store: Path, name: str) -> dict | None:
    key = (str(store), name)
    path = store / name / "zarr.json"
    st = os.stat(path)
    stamp = (st.st_ino, st.st_mtime_ns)
    hit = _METAS.get(key)
    if hit is not None and hit[0] == stamp:
        return hit[1]
    if len(_METAS) >= _ARRAYS_KEPT:
        _METAS.clear()
    meta = json.loads(path.read_text())
    meta = meta if layout_is_plain(meta) else None
    _METAS[key] = (stamp, meta)
    return meta


def _write_whole_chunk(store: Path, name: str, region: tuple[slice, ...], chunk_index: tuple[int, ...],
                       chunks: tuple[int, ...], values) -> Path | None:
    """Write whole chunk ``chunk_index`` of array ``name``: its file straight from here
    (``_chunks.write_chunk``, the bytes zarr writes) where the layout is plain, else through
    zarr.  The path of the chunk file (None where no file is kept: only fill values)."""
    meta = _plain_meta(store, name)
    if meta is not None:
        layout = tuple(int(n) for n in meta["chunk_grid"]["configuration"]["chunk_shape"])
        assert layout == tuple(chunks), f"{name}: chunks {layout} != layout {chunks}"
        return write_chunk(store / name, meta, chunk_index, values)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        arr = _array(store, name)
        assert tuple(arr.chunks) == tuple(chunks), f"{name}: chunks {arr.chunks} != layout {chunks}"
        arr[region] = values
    return store / name / "c" / "/".join(str(i) for i in chunk_index)


def write_region(store: Path, region: tuple[slice, ...], chunk_index: tuple[int, ...],
                 chunks: tuple[int, ...], shape: tuple[int, ...], values: dict[str, np.ndarray]) -> None:
    """Write one whole chunk of every output, then make it durable before the marker is written."""
    for i, c, n, sl in zip(chunk_index, chunks, shape, region):
        # Whole, aligned chunks only: two tasks never touch the same chunk file.
        assert sl.start == i * c and sl.stop == min((i + 1) * c, n), f"region {region} is not chunk {chunk_index}"
    files = [_write_whole_chunk(store, name, region, chunk_index, chunks, v) for name, v in values.items()]
    # Durable before the marker: after power loss a marked chunk must have its data on disk
    # (the files and their entries in their folders, in one round of concurrent fsyncs).
    files = [f for f in files if f is not None]
    _fsync_all(files + sorted({f.parent for f in files}))


def mark_done(store: Path, chunk_index: tuple[int, ...]) -> None:
    ones = np.ones((1,) * len(chunk_index), dtype=np.uint8)
    _write_whole_chunk(store, DONE_ARRAY, tuple(slice(i, i + 1) for i in chunk_index), tuple(chunk_index),
                       (1,) * len(chunk_index), ones)


@dataclass(frozen=True)
class ChunkWrite:
    """Whole aligned chunk ``chunk_index`` of a layout ``chunks`` over arrays of ``shape``:
    ``values`` {array name: ndarray of the region's shape}, written at ``region``."""

    region: tuple
    chunk_index: tuple
    chunks: tuple
    shape: tuple
    values: dict


@dataclass(frozen=True)
class SolvedChunk:
    """What a kind's ``solve_chunk`` computed for one chunk: its writes (one per chunk layout
    its arrays use), the points it holds, their failures and the seconds spent solving."""

    writes: tuple
    points: int
    failures: int
    seconds: float


def store_chunk(store: Path, index: tuple[int, ...], solved: SolvedChunk) -> dict:
    """The one way a chunk reaches a store, for every kind: each write whole and durable, then
    the chunk's done marker (last: a chunk without it is recomputed on resume).

    Returns ``{"points", "failures", "seconds"}`` of ``solved`` and the seconds spent writing
    (``write_seconds``, fsyncs included) and marking (``mark_seconds``).
    """
    import time

    t0 = time.perf_counter()
    for w in solved.writes:
        write_region(store, w.region, w.chunk_index, w.chunks, w.shape, w.values)
    t1 = time.perf_counter()
    # Test hook: widen the window between data and marker, where a kill leaves a half-done chunk.
    time.sleep(float(os.environ.get("TWOLINK_PIPELINE_MARKER_DELAY", "0") or 0))
    t2 = time.perf_counter()
    mark_done(store, index)
    return {"points": int(solved.points), "failures": int(solved.failures), "seconds": float(solved.seconds),
            "write_seconds": t1 - t0, "mark_seconds": time.perf_counter() - t2}


def read_arrays(store: Path, names) -> dict[str, np.ndarray]:
    """The whole arrays ``names`` of ``store``, in memory: the chunk files read straight from
    disk where the array has the layout this pipeline writes (``_chunks.read_whole``; through
    zarr-python each chunk costs ~0.3 ms of CPU, and a grid scene's reductions read ~20 arrays
    of up to 1,309 chunks), else through zarr."""
    out = {}
    for n in names:
        whole = read_whole(Path(store) / n) if (Path(store) / n / "zarr.json").is_file() else None
        if whole is None:
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                whole = zarr.open_array(store=str(store), path=n, mode="r")[...]
        out[n] = whole
    return out


def write_arrays(store: Path, arrays: dict[str, np.ndarray]) -> None:
    """Write whole arrays (the driver's reductions), cast to each stored array's dtype: their
    chunk files straight from here (``_chunks.write_whole``) where the layout is plain (through
    zarr each array costs ~3-5 ms, and a grid scene's reductions write ~15-40), else through zarr."""
    for n, v in arrays.items():
        meta = _plain_meta(store, n)
        if meta is not None:
            write_whole(store / n, meta, v)
            continue
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
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


# ---------------------------------------------------------------------------
# Compaction: few chunk files once a store is complete (issue 34 item 6)
# ---------------------------------------------------------------------------

#: elements per chunk at most once a store is complete (8 MiB of float64 before compression):
#: a whole array of up to 2^20 points is one file, a 10^6-point scene's array one or two
COMPACT_ELEMENTS = 1 << 20
#: a complete store of at least this many chunk files is compacted (reading one through
#: zarr-python costs ~0.3 ms of CPU, and a rewrite about as much as one read).  Above the
#: paper's stores (force_laws 11,636 files, fourier_optima 9,623, linear_two_phase 6,622): at
#: 4,096 the rewrite took 4.5 s of linear_two_phase's 42.4 s wall on 2 idle cores, its
#: solving share 76 % instead of 85 % (docs/validation.md, issue 34); a user's 10^6-point
#: grid scene (~3,900 chunks of 256 points x ~14 arrays, ~55,000 files) is compacted
COMPACT_FILES = 16384
_STAGING = f"{STATE_GROUP}/rechunk_new"  # a rewritten array, until it is swapped in
_RETIRED = f"{STATE_GROUP}/rechunk_old"  # the array it replaces, until the swap is done


def compact_chunks(shape: tuple[int, ...], limit: int = COMPACT_ELEMENTS) -> tuple[int, ...]:
    """Chunks of at most ``limit`` elements over ``shape``: the trailing axes whole while they
    fit, the axis where that runs out cut into the fewest equal pieces that fit, the axes
    before it single values."""
    chunk, n = [1] * len(shape), 1
    for i in range(len(shape) - 1, -1, -1):
        if n * shape[i] <= limit:
            chunk[i], n = int(shape[i]), n * int(shape[i])
        else:
            pieces = -(-n * int(shape[i]) // limit)
            chunk[i] = -(-int(shape[i]) // pieces)
            break
    return tuple(max(1, c) for c in chunk)


def _key(name: str) -> str:
    return name.replace("/", "~")


def _fsync_tree(root: Path) -> None:
    paths = [p for p in root.rglob("*") if p.is_file()]
    _fsync_all(paths)
    _fsync_all({p.parent for p in paths} | {root, root.parent})


def recover_rechunk(store: Path) -> None:
    """Finish or undo the swap of an array that a kill interrupted in :func:`rechunk`: a staged
    copy whose array is still in place may be partial and is removed; one whose array was
    already moved away is complete (it is moved away only then) and is moved in; a moved-away
    array whose place is empty is moved back."""
    for area in (_STAGING, _RETIRED):
        folder = store / area
        if not folder.is_dir():
            continue
        for d in sorted(folder.iterdir()):
            target = store / d.name.replace("~", "/")
            if target.exists():
                shutil.rmtree(d)
            else:
                os.rename(d, target)
        folder.rmdir()


def _chunked_arrays(store: Path) -> dict[str, tuple[tuple[int, ...], tuple[int, ...]]]:
    """{path: (shape, chunks)} of the store's arrays (root and ``pipeline_state``) of more than
    one chunk."""
    out = {}
    for zj in sorted(list(store.glob("*/zarr.json")) + list((store / STATE_GROUP).glob("*/zarr.json"))):
        meta = json.loads(zj.read_text())
        if meta.get("node_type") != "array" or meta["chunk_grid"]["name"] != "regular":
            continue
        shape, chunks = meta["shape"], meta["chunk_grid"]["configuration"]["chunk_shape"]
        if any(-(-s // c) > 1 for s, c in zip(shape, chunks)):
            out[str(zj.parent.relative_to(store))] = (tuple(int(s) for s in shape), tuple(int(c) for c in chunks))
    return out


def wants_compaction(store: Path) -> bool:
    """Whether :func:`compact` is due on ``store`` once complete: not compacted yet, and an
    interrupted compaction to finish or :data:`COMPACT_FILES` chunk files or more."""
    meta = store_meta(store)
    if meta["state"].get("compacted"):
        return False
    if meta.get("compacted_from"):
        return True
    files = sum(int(np.prod([-(-s // c) for s, c in zip(shape, chunks)]))
                for shape, chunks in _chunked_arrays(store).values())
    return files >= COMPACT_FILES


def rechunk(store: Path, chunks_of: dict[str, tuple[int, ...]]) -> None:
    """Rewrite arrays ``{path: chunks}`` of ``store`` in the chunks given, their values, data
    type, fill value, dimension names and attributes unchanged, each swapped in atomically: the
    copies are written whole under ``pipeline_state/rechunk_new`` and synced (all at once: one
    journal commit, not one per array), then each array is moved to ``rechunk_old`` and its
    copy into its place, and the old ones removed (a kill at any point leaves each array old or
    wholly new: :func:`recover_rechunk`)."""
    recover_rechunk(store)
    staged = {}
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        for name, chunks in chunks_of.items():
            old = zarr.open_array(store=str(store), path=name, mode="r")
            if tuple(old.chunks) == tuple(chunks):
                continue
            staged[name] = store / _STAGING / _key(name)
            new = zarr.create_array(store=str(staged[name]), shape=old.shape, chunks=tuple(chunks), dtype=old.dtype,
                                    fill_value=old.metadata.fill_value, zarr_format=3,
                                    dimension_names=old.metadata.dimension_names, attributes=dict(old.attrs))
            new[...] = old[...]
    if not staged:
        return
    _fsync_tree(store / _STAGING)  # every copy whole on disk before the first array is moved
    retired = store / _RETIRED
    retired.mkdir(parents=True, exist_ok=True)
    for name, copy in staged.items():
        os.rename(store / name, retired / _key(name))
        os.rename(copy, store / name)
    _fsync_all({(store / name).parent for name in staged} | {retired, store / _STAGING})
    recover_rechunk(store)  # removes the old arrays and the emptied folders


def compact(store: Path) -> int:
    """Rewrite every array of more than one chunk of the complete store ``store`` (the driver
    does so where :func:`wants_compaction`) in chunks of
    :func:`compact_chunks` (few files: a task's chunk of ~256 points is ~2 KB, and a 10^6-point
    scene would otherwise be tens of thousands of files), after recording each array's chunks
    in the record (``compacted_from``) so that :func:`expand` can restore them; sets
    ``state.compacted`` last.  Returns the arrays rewritten."""
    meta = store_meta(store)
    plan = meta.get("compacted_from") or {k: chunks for k, (_, chunks) in _chunked_arrays(store).items()}
    plan = {k: [int(c) for c in v] for k, v in plan.items()}
    _update_record(store, lambda m: {**m, "compacted_from": plan})
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        target = {name: compact_chunks(zarr.open_array(store=str(store), path=name, mode="r").shape) for name in plan}
    rechunk(store, target)
    _update_record(store, lambda m: {**m, "state": {**m["state"], "compacted": True}})
    return len(plan)


def expand(store: Path) -> None:
    """Undo :func:`compact` (chunks to compute again on a compacted store: each task writes its
    own chunk files): the arrays back in the chunks recorded in ``compacted_from``."""
    meta = store_meta(store)
    plan = meta.get("compacted_from")
    if plan:
        rechunk(store, {k: tuple(v) for k, v in plan.items()})
    _update_record(store, lambda m: {**{k: v for k, v in m.items() if k != "compacted_from"},
                                     "state": {**m["state"], "compacted": False}})
