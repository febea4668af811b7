"""The paper's figures in order (``reports/figures.toml``) and the store views under each.

A :class:`View` is a whole store or the part of it one figure draws (a coordinate selected,
a range of it, some reductions or maps); :func:`arrange` places every loaded store: under the
figures whose views name its scene, else under the figure its scene's ``figure`` field names,
else among the studies (by scene kind) or the other stores.
"""

from __future__ import annotations

import dataclasses
import math
import re
import tomllib
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

__all__ = ["FIGURES_FILE", "Figure", "View", "load_figures", "figure_labels", "view_store", "arrange", "Placement"]

FIGURES_FILE = Path(__file__).resolve().with_name("figures.toml")


@dataclass(frozen=True)
class View:
    scene: str
    select: dict = field(default_factory=dict)
    ranges: dict = field(default_factory=dict)
    reductions: tuple | None = None
    quantities: tuple | None = None

    def describe(self) -> str:
        parts = [f"{d} = {v:g}" for d, v in self.select.items()]
        parts += [f"{lo:g} ≤ {d} ≤ {hi:g}" if math.isfinite(hi) else f"{d} ≥ {lo:g}"
                  for d, (lo, hi) in self.ranges.items()]
        if self.reductions:
            parts.append("reductions " + ", ".join(self.reductions))
        return "; ".join(parts)


@dataclass(frozen=True)
class Figure:
    label: str
    title: str
    finding: str
    kind: str = "result"          # result | schematic | limit | examples
    see: str = ""                 # examples: the figure whose views draw such motions
    views: tuple = ()


def load_figures(path: Path | str = FIGURES_FILE) -> list[Figure]:
    doc = tomllib.loads(Path(path).read_text(encoding="utf-8"))
    out = []
    for f in doc.get("figures", []):
        views = tuple(View(scene=v["scene"], select=dict(v.get("select", {})), ranges=dict(v.get("ranges", {})),
                           reductions=tuple(v["reductions"]) if "reductions" in v else None,
                           quantities=tuple(v["quantities"]) if "quantities" in v else None)
                      for v in f.get("views", []))
        out.append(Figure(label=f["label"], title=f["title"], finding=f["finding"], kind=f.get("kind", "result"),
                          see=f.get("see", ""), views=views))
    return out


def figure_labels(text: str) -> list[str]:
    """Figure labels named in a scene's ``figure`` field: "UPEtaDiag1, UPEtaDiag2",
    "UEtaMax (coarse)" -> ["UEtaMax"]."""
    return [m.group(1) for part in (text or "").split(",") if (m := re.match(r"\s*([A-Za-z][\w]*)", part))]


def _indices(coord: np.ndarray, *, value=None, bounds=None) -> np.ndarray:
    if value is not None:
        return np.flatnonzero(np.isclose(coord, float(value), rtol=1e-6, atol=1e-12))
    lo, hi = bounds
    return np.flatnonzero((coord >= lo) & (coord <= hi))


def view_store(sd, view: View):
    """The part of ``sd`` that ``view`` shows (a SceneStore over a subset), or None when the
    store holds none of it (e.g. a quick store without that coordinate)."""
    ds = sd.ds
    wanted = [(d, {"value": v}) for d, v in view.select.items()] + [(d, {"bounds": b}) for d, b in view.ranges.items()]
    for d, how in wanted:
        if d not in ds.dims:
            return None
        idx = _indices(np.asarray(ds[d].values, dtype=np.float64), **how)
        if not idx.size:
            return None
        ds = ds.isel({d: idx})
    science = dict(sd.science)
    if view.reductions is not None:
        science["reductions"] = [r for r in sd.reductions if r["name"] in view.reductions]
    if view.quantities is not None:
        science["outputs"] = {**science.get("outputs", {}), "quantities": list(view.quantities)}
    return dataclasses.replace(sd, ds=ds, science=science)


@dataclass
class Placement:
    """Where each loaded store goes: per figure label a list of (store view, view note);
    studies and other stores in load order."""

    figures: dict
    studies: list
    others: list


def arrange(stores, figures, study_kinds) -> Placement:
    named = {v.scene for f in figures for v in f.views}
    labels = {f.label for f in figures}
    place = Placement(figures={f.label: [] for f in figures}, studies=[], others=[])
    for sd in stores:
        kind = sd.meta.get("kind", "grid")
        if kind in study_kinds:
            place.studies.append(sd)
            continue
        if sd.name in named:
            for f in figures:
                for v in f.views:
                    if v.scene == sd.name:
                        part = view_store(sd, v)
                        note = (f"part of store <code>{sd.name}</code>: {v.describe()}" if v.describe() else "")
                        if part is None:
                            note = f"store <code>{sd.name}</code> holds no cells for this figure ({v.describe()})"
                        place.figures[f.label].append((part, note))
            continue
        hits = [lab for lab in figure_labels(sd.figure) if lab in labels]
        if hits:
            for lab in hits:
                place.figures[lab].append((sd, ""))
        else:
            place.others.append(sd)
    return place
