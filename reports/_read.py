"""Reading pipeline stores: format check, provenance and the labelled dataset.

A store is read through ``zarr.json`` first (format, group, ``pipeline`` attributes) so a
foreign or newer store is refused before any array is touched; the arrays are then opened with
``xarray.open_zarr``, which labels them by the ``dimension_names`` the pipeline writes.
Attributes are read through ``pipeline.decode_attrs`` (the one reader of them): stores of format
2 keep them as netCDF takes them (the record as JSON text, CF flags), stores of format 1 nested;
the report sees the same values from both.

Opening reads only the metadata and the coordinate arrays: a data array is read when a figure,
table or claim first uses it, whole, through xarray and zarr (no dask graph, ``chunks=None``:
xarray's in-memory cache), and kept in memory for the rest of the build.  Stores of format 3
hold few chunks per array (~1 MiB each, issue 46), so zarr's per-chunk cost no longer matters;
stores of formats 1-2 (a chunk per 256-point block) read the same way, only slower.
:meth:`SceneStore.load` reads a list of arrays up front, so a section that draws from several
arrays (or indexes one cell by cell) reads each once. Before issue 36 every store was loaded
whole through dask (36 s of a 44 s build over the full paper's 14 stores).
"""

from __future__ import annotations

import json
import tomllib
import warnings
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import xarray as xr

from pipeline import decode_attrs, read_record

__all__ = ["StoreRefused", "SceneStore", "open_scene_store", "shipped_scenes", "SUPPORTED_FORMAT", "READ_FORMATS"]

#: Store layout version this report reads (the newest). Stores without ``format_version`` in their
#: ``pipeline`` attributes predate the field and are read as version 1.
SUPPORTED_FORMAT = 3
#: Every store layout version this report reads: 1 (nested attributes), 2 (issue 34:
#: attributes as netCDF takes them) and 3 (issue 46: chunks of whole blocks, ~1 MiB); the
#: arrays are the same, read through zarr's public API whatever their chunks.
READ_FORMATS = (1, 2, 3)
ATTRS_KEY = "pipeline"


class StoreRefused(ValueError):
    """A path that is not a pipeline store this report can read; the message is one line."""


@dataclass
class SceneStore:
    """One scene's store, opened lazily.

    Attributes
    ----------
    ds : xarray.Dataset
        Every root array, labelled by its dimension names; coordinates in memory, data arrays
        read (whole, once) on first use.
    meta : dict
        The group's ``pipeline`` attributes (provenance, layout, state).
    """

    path: Path
    meta: dict
    ds: object
    science: dict = field(default_factory=dict)

    @property
    def provenance(self) -> dict:
        return self.meta.get("provenance", {})

    @property
    def name(self) -> str:
        return self.provenance.get("scene_name") or self.path.stem

    @property
    def title(self) -> str:
        return self.provenance.get("title") or ""

    @property
    def figure(self) -> str:
        return self.provenance.get("figure") or ""

    @property
    def dims(self) -> tuple[str, ...]:
        return tuple(self.meta.get("layout", {}).get("dims", ()))

    @property
    def family(self) -> str:
        return self.science.get("family", "harmonic")

    @property
    def fixed(self) -> dict[str, float]:
        return {k: float(v) for k, v in self.science.get("fixed", {}).items()}

    @property
    def p(self) -> float:
        """Force-law exponent when fixed (labels depend on it), else 0."""
        return float(self.fixed.get("p", 0.0))

    @property
    def rtol(self) -> float:
        return float(self.science.get("solver", {}).get("rtol", 1e-4))

    @property
    def method(self) -> str:
        return self.science.get("solver", {}).get("method", "periodic")

    @property
    def reductions(self) -> list[dict]:
        return list(self.science.get("reductions", []))

    @property
    def quantities(self) -> list[str]:
        return list(self.science.get("outputs", {}).get("quantities", []))

    @property
    def state(self) -> dict:
        return self.meta.get("state", {})

    @property
    def complete(self) -> bool:
        s = self.state
        return bool(s.get("chunks_complete") and s.get("reductions_complete") and s.get("series_complete", True))

    def load(self, names) -> "SceneStore":
        """Read the data arrays ``names`` (those present; others are skipped) whole, now, each
        in one read, so later indexing of them touches memory only. Returns ``self``."""
        for name in dict.fromkeys(names):
            if name in self.ds.data_vars:
                self.ds[name].values  # noqa: B018 -- fills xarray's in-memory cache of the variable
        return self

    def array(self, name: str):
        """Variable ``name`` as a read-only numpy array, read once and kept (figures that index an
        array cell by cell index this, not ``ds[name].values``: each ``.values`` of a lazily
        opened variable walks xarray's indexing layers, ~0.1-0.6 ms, 31,000 times in a build of the
        paper's report)."""
        cache = self.__dict__.setdefault("_arrays", {})
        if name not in cache:
            v = np.asarray(self.ds[name].values)
            v.flags.writeable = False
            cache[name] = v
        return cache[name]

    def spacing(self, dim: str) -> str | None:
        if dim in self.ds.variables:
            return self.ds[dim].attrs.get("spacing")
        return None


def _refuse(path: Path, why: str) -> StoreRefused:
    return StoreRefused(f"{path}: {why}")


def read_meta(path: Path) -> dict:
    """The ``pipeline`` attributes of ``path``, after checking it is a store this report reads."""
    zj = path / "zarr.json"
    if not path.exists():
        raise _refuse(path, "no such store")
    if not zj.is_file():
        if (path / ".zgroup").is_file() or (path / ".zarray").is_file():
            raise _refuse(path, "a Zarr format 2 store; this report reads pipeline stores in Zarr format 3 "
                                f"(store format versions {', '.join(map(str, READ_FORMATS))})")
        inner = sorted(path.glob("*.zarr")) if path.is_dir() else []
        if inner:
            raise _refuse(path, f"a folder of {len(inner)} store(s), not a store; name the stores "
                                f"({path / '*.zarr'}) or leave the arguments out for out/*.zarr")
        raise _refuse(path, "not a Zarr store (no zarr.json)")
    try:
        doc = json.loads(zj.read_text())
    except (OSError, ValueError) as exc:
        raise _refuse(path, f"unreadable zarr.json ({exc})") from None
    if doc.get("zarr_format") != 3 or doc.get("node_type") != "group":
        raise _refuse(path, f"zarr.json is not a Zarr format 3 group (zarr_format={doc.get('zarr_format')!r}, "
                            f"node_type={doc.get('node_type')!r})")
    meta = read_record(doc.get("attributes", {}))
    if not isinstance(meta, dict):
        raise _refuse(path, f"not a pipeline store (no '{ATTRS_KEY}' attributes)")
    version = meta.get("format_version", meta.get("layout", {}).get("format_version", 1))
    if version not in READ_FORMATS:
        newer = isinstance(version, (int, float)) and version > SUPPORTED_FORMAT
        raise _refuse(path, f"store format version {version!r} is {'newer than' if newer else 'different from'} "
                            f"the versions this report reads ({', '.join(map(str, READ_FORMATS))}); update the reports package "
                            "or rerun the scene")
    missing = [k for k in ("provenance", "layout", "state") if not isinstance(meta.get(k), dict)]
    missing += [f"provenance.{k}" for k in ("scene_hash", "scene") if k not in meta.get("provenance", {})]
    missing += ["layout.dims"] if "dims" not in meta.get("layout", {}) else []
    if missing:
        raise _refuse(path, f"pipeline attributes lack {', '.join(missing)} (a different store format)")
    return meta


def open_scene_store(path) -> SceneStore:
    """Check and open one store (lazily: see the module docstring). Raises
    :class:`StoreRefused` with a one-line message."""
    path = Path(path)
    meta = read_meta(path)
    if not meta["state"].get("skeleton_complete"):
        raise _refuse(path, "store skeleton incomplete (interrupted before the first task); rerun the scene")
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        try:
            # chunks=None: no dask; each variable is read through zarr on first use and cached
            ds = xr.open_zarr(str(path), consolidated=False, zarr_format=3, chunks=None)
        except Exception as exc:  # an unreadable array is a store we cannot report on
            raise _refuse(path, f"cannot read arrays ({type(exc).__name__}: {exc})") from None
    ds.attrs = decode_attrs(ds.attrs)
    for var in ds.variables.values():
        var.attrs = decode_attrs(var.attrs)
    dims = list(meta["layout"]["dims"])
    for d in dims:
        if d not in ds.coords:
            raise _refuse(path, f"coordinate array {d!r} missing (a different store format)")
    # Coordinates in the scene's axis order (the order zarr lists the arrays in varies from one
    # opening to the next, and with it the order of a cell's coordinates in the audit's text).
    ds = xr.Dataset({k: ds[k].variable for k in ds.data_vars},
                    coords={**{d: ds[d].variable for d in dims}, **{k: ds[k].variable for k in ds.coords if k not in dims}},
                    attrs=ds.attrs)
    return SceneStore(path=path, meta=meta, ds=ds, science=meta["provenance"]["scene"])


def shipped_scenes(workflows: Path | None = None) -> list[dict]:
    """Name, title, figure and file of every shipped scene (read from ``workflows/*.toml``,
    the package data of :mod:`workflows`, unless ``workflows`` names another folder)."""
    if workflows is None:
        from workflows import DIRECTORY as workflows
    out = []
    for f in sorted(workflows.glob("*.toml")):
        try:
            head = tomllib.loads(f.read_text()).get("scene", {})
        except (OSError, tomllib.TOMLDecodeError):
            continue
        if "name" in head:
            out.append({"name": head["name"], "title": head.get("title", ""), "figure": head.get("figure", ""),
                        "file": f"workflows/{f.name}"})
    return out
