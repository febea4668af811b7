"""Driver: read every store (refusing foreign ones before writing anything), then build one of
two reports:

* the **reproduction report** (when a store of a shipped scene is among them): the audit, one
  section per figure of the paper in its order, the studies, other stores, and the shipped
  scenes not yet run;
* a **report of the user's own stores** (``audit=False``, ``python -m reports build
  --no-audit``, and automatically when no store is of a shipped scene): the user's scenes
  first, then the figures and studies that have a store; no audit and no empty section.

Either way a store of reduced resolution (``python -m pipeline paper --quick``) makes the page
say so in its title and first line."""

from __future__ import annotations

import os
from pathlib import Path

from ._audit import audit_html, evaluate_claims, load_claims, write_audit_json
from ._kinds import STUDY_KINDS, render_view
from ._paper import arrange, load_figures
from ._read import open_scene_store, shipped_scenes
from ._site import Section, SiteBuilder, esc
from ._study import combined_honesty

__all__ = ["build_report", "default_stores", "reduced_stores", "AUDIT_JSON"]

AUDIT_JSON = "audit.json"
_KIND_NOTES = {
    "schematic": "A schematic: nothing to compute.",
    "limit": "The T → ∞ limit (quasi-static motions) is not computed by a shipped scene.",
    "examples": "Example motions: the report draws the motions of the optima under figure {see}.",
}


def default_stores(root: str | Path = "out") -> list[Path]:
    """Every Zarr store (a directory named ``*.zarr``) under ``root``, at any depth (``paper``
    writes ``out/*.zarr``, ``paper --quick`` ``out/quick/*.zarr``), sorted; a store's own
    directories are not searched."""
    root = Path(root)
    if not root.is_dir():
        return []
    found = []
    for folder, subdirs, _ in os.walk(root):
        stores = [d for d in subdirs if d.endswith(".zarr")]
        found += [Path(folder) / d for d in stores]
        subdirs[:] = sorted(d for d in subdirs if not d.endswith(".zarr"))
    return sorted(found)


#: What ``paper --quick`` writes in a store's provenance (``scene_file``): its scenes are reduced.
_QUICK_MARK = "(quick variant)"


def reduced_stores(stores) -> list:
    """The stores (SceneStore) of reduced resolution: scenes of ``python -m pipeline paper --quick``."""
    return [sd for sd in stores if _QUICK_MARK in str(sd.provenance.get("scene_file", ""))]


def reduced_sentence(stores) -> str:
    """"" or the sentence a report of reduced-resolution stores opens with."""
    quick = reduced_stores(stores)
    if not quick:
        return ""
    return (f"{len(quick)} of {len(stores)} stores are scenes of python -m pipeline paper --quick: coarser grids "
            "and fewer optimiser starts than the paper's, so every value and verdict here (the unexplained "
            "count too) is of those coarse grids, not the full result; python -m pipeline paper computes that.")


def _anchor(used: set, base: str) -> str:
    anchor, k = base, 2
    while anchor in used:
        anchor, k = f"{base}-{k}", k + 1
    used.add(anchor)
    return anchor


def _verdict_line(rows, label) -> str:
    mine = [r for r in rows if r.claim.figure == label]
    if not mine:
        return ""
    items = ", ".join(f"<a href='#claim-{esc(r.claim.id)}'>{esc(r.claim.id)}</a>: "
                      f"<span class='v-{r.verdict.replace(' ', '')}'>{esc(r.verdict)}</span>" for r in mine)
    return f"<p class='note'>Audit of this figure's claims: {items}.</p>"


def _views(site, used: set, stores) -> tuple[list[str], list]:
    """(HTML of each store's whole view, table-of-contents entries) for sections outside the figures."""
    parts, children = [], []
    for sd in stores:
        anchor = _anchor(used, f"scene-{sd.name}")
        children.append((anchor, esc(sd.name)))
        parts.append(f"<div class='view'>{render_view(site, sd, anchor)}</div>")
    return parts, children


def _figure_section(site, used, rows, number, fig, views, *, audit: bool) -> Section:
    anchor = _anchor(used, f"fig-{fig.label}")
    parts = [f"<h2>Figure {number} <span class='label'>fig:{esc(fig.label)}</span> — {esc(fig.title)}</h2>",
             f"<p class='finding'><b>The paper:</b> {esc(fig.finding)}</p>", _verdict_line(rows, fig.label) if audit else ""]
    children = []
    for sd, note in views:
        if sd is None:
            parts.append(f"<div class='view'><p class='note'>{note}</p></div>")
            continue
        view_anchor = _anchor(used, f"scene-{sd.name}")
        children.append((view_anchor, f"{esc(sd.name)}" + (" (part)" if note else "")))
        body = render_view(site, sd, view_anchor)
        parts.append(f"<div class='view'>{body}" + (f"<p class='note'>View: {note}.</p>" if note else "")
                     + "</div>")
    if not views:
        text = _KIND_NOTES.get(fig.kind, "No store of a scene reproducing this figure was given.")
        parts.append(f"<p class='note'>{text.format(see=fig.see)}</p>")
    return Section(anchor, f"Figure {number}: {esc(fig.title)}", "\n".join(parts), "figure", children)


def build_report(stores, out, *, list_unrun: bool = True, audit: bool | None = None, claims_file=None) -> Path:
    """Build ``out/index.html``, ``out/plotly.min.js`` and (with the audit) ``out/audit.json``
    from ``stores``.

    Parameters
    ----------
    stores : iterable of path
        Zarr stores written by ``python -m pipeline run``; every one must exist and be a
        pipeline store of a format this report reads.
    out : path
        Output directory.
    list_unrun : bool
        Also list the shipped scenes (``workflows/*.toml``) that have no store among ``stores``
        and the paper's figures no store draws (False: neither, so no section is empty).
    audit : bool, optional
        True: the reproduction report (the audit first, then the paper's figures in order);
        False: a report of the user's own stores (their scenes first, no audit, no empty
        section, no ``audit.json``); None (default): the reproduction report when a store of a
        shipped scene is among ``stores`` (or none is given: every scene not yet run), else the
        user's.
    claims_file : path, optional
        The claim registry (default ``reports/claims.toml``).

    Returns
    -------
    Path of ``index.html``.

    Raises
    ------
    StoreRefused
        A path that does not exist, a store of a different or newer format, or not a pipeline
        store (nothing is written).
    """
    # Every path must be a store this report reads: a mistyped path is refused, not taken for a
    # scene not yet run (that is a shipped scene with no store among ``stores``).
    loaded = [open_scene_store(Path(s)) for s in stores]  # raises before anything is written
    shipped = {e["name"]: e for e in shipped_scenes()}
    if audit is None:
        audit = not loaded or any(sd.name in shipped for sd in loaded)
    site = SiteBuilder(Path(out))
    site.n_stores = len(loaded)
    site.reduced = reduced_sentence(loaded)
    rows = []
    if audit:
        rows = evaluate_claims(load_claims(claims_file) if claims_file else load_claims(), loaded)
        site.front = audit_html(rows, reduced=site.reduced)
    else:
        names = [sd.name for sd in loaded]
        site.title = ("Intermittent sliding of a two-link body: " + ", ".join(names[:3])
                      + (f" and {len(names) - 3} more" if len(names) > 3 else ""))
        list_unrun = False
    figures = load_figures()
    place = arrange(loaded, figures, STUDY_KINDS)
    used: set = set()
    if not audit:
        # the user's scenes lead: every store not of a shipped scene, each in its own section,
        # in the order given
        own = [sd for sd in loaded if sd.name not in shipped and sd.meta.get("kind", "grid") not in STUDY_KINDS]
        for sd in own:
            anchor = _anchor(used, f"scene-{sd.name}")
            head = f"<h2>Scene {esc(sd.name)}" + (f" — {esc(sd.title)}" if sd.title else "") + "</h2>"
            site.sections.append(Section(_anchor(used, f"own-{sd.name}"), f"Scene {esc(sd.name)}",
                                         f"{head}<div class='view'>{render_view(site, sd, anchor)}</div>", "scene",
                                         [(anchor, esc(sd.name))]))
        mine = {sd.path for sd in own}
        place.figures = {label: [(v, note) for v, note in views if v is None or v.path not in mine]
                         for label, views in place.figures.items()}
        place.others = [sd for sd in place.others if sd.path not in mine]
    for number, fig in enumerate(figures, start=1):
        views = place.figures[fig.label]
        if not list_unrun and not any(sd is not None for sd, _ in views):
            continue  # no store draws it: no empty section
        site.sections.append(_figure_section(site, used, rows, number, fig, views, audit=audit))
    if place.studies:
        parts, children = _views(site, used, place.studies)
        parts.append(f"<div class='view'>{site.guarded('honest tolerances', lambda: combined_honesty(place.studies))}"
                     "</div>")
        children.append(("honest-tolerances", "Honest tolerances"))
        site.sections.append(Section(_anchor(used, "studies"), "Studies",
                                     "<h2>Studies: accuracy, stiffness and honest tolerances</h2>" + "\n".join(parts),
                                     "scene", children))
    if place.others:
        parts, children = _views(site, used, place.others)
        site.sections.append(Section(_anchor(used, "others"), "Other stores", "<h2>Other stores</h2>" + "\n".join(parts),
                                     "scene", children))
    have = {sd.name for sd in loaded}
    site.list_unrun = list_unrun
    if list_unrun:
        for name, e in shipped.items():
            if name not in have:
                site.add_not_run({**e, "command": f"python -m pipeline run {e['file']}"})
    index = site.write()
    if audit:
        write_audit_json(rows, index.parent / AUDIT_JSON)
    else:
        (index.parent / AUDIT_JSON).unlink(missing_ok=True)  # no audit: none left from an earlier build
    return index
