"""Driver: read every store (refusing foreign ones before writing anything), then build the site."""

from __future__ import annotations

from pathlib import Path

from ._html import SiteBuilder
from ._read import open_scene_store, shipped_scenes

__all__ = ["build_report", "default_stores"]


def default_stores(root: str | Path = "out") -> list[Path]:
    """Every ``*.zarr`` directly under ``root`` (sorted)."""
    root = Path(root)
    return sorted(p for p in root.glob("*.zarr") if p.is_dir()) if root.is_dir() else []


def build_report(stores, out, *, list_unrun: bool = True) -> Path:
    """Build ``out/index.html`` (and ``out/plotly.min.js``) from ``stores``.

    Parameters
    ----------
    stores : iterable of path
        Zarr stores written by ``python -m pipeline run``. A path that does not exist is a
        scene not yet run (listed, not an error).
    out : path
        Output directory.
    list_unrun : bool
        Also list the shipped scenes (``workflows/*.toml``) that have no store among ``stores``.

    Returns
    -------
    Path of ``index.html``.

    Raises
    ------
    StoreRefused
        A store of a different or newer format, or not a pipeline store (nothing is written).
    """
    loaded, missing = [], []
    for s in stores:
        p = Path(s)
        if not p.exists():
            missing.append(p)
            continue
        loaded.append(open_scene_store(p))  # raises before anything is written
    site = SiteBuilder(Path(out))
    for sd in loaded:
        site.add_scene(sd)
    from ._study import combined_honesty  # over every study store together (issue 6)

    honesty = combined_honesty(loaded)
    if honesty is not None:
        site.sections.append(honesty)
    have = {sd.name for sd in loaded}
    shipped = {e["name"]: e for e in shipped_scenes()}
    for p in missing:
        name = p.name.removesuffix(".zarr")
        e = dict(shipped.get(name, {"name": name}))
        e["command"] = f"python -m pipeline run {e.get('file', 'workflows/' + name + '.toml')} --store {p}"
        site.add_not_run(e)
        have.add(name)
    if list_unrun:
        for name, e in shipped.items():
            if name not in have:
                site.add_not_run({**e, "command": f"python -m pipeline run {e['file']}"})
    return site.write()
