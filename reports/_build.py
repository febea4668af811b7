"""Driver: read every store (refusing foreign ones before writing anything), compute the audit,
then build the site in the paper's order: the audit, one section per figure of the paper, the
studies, other stores, and the scenes not yet run."""

from __future__ import annotations

from pathlib import Path

from ._audit import audit_html, evaluate_claims, load_claims, write_audit_json
from ._kinds import STUDY_KINDS, render_view
from ._paper import arrange, load_figures
from ._read import open_scene_store, shipped_scenes
from ._site import Section, SiteBuilder, esc
from ._study import combined_honesty

__all__ = ["build_report", "default_stores", "AUDIT_JSON"]

AUDIT_JSON = "audit.json"
_KIND_NOTES = {
    "schematic": "A schematic: nothing to compute.",
    "limit": "The T → ∞ limit (quasi-static motions) is not computed by a shipped scene.",
    "examples": "Example motions: the report draws the motions of the optima under figure {see}.",
}


def default_stores(root: str | Path = "out") -> list[Path]:
    """Every ``*.zarr`` directly under ``root`` (sorted)."""
    root = Path(root)
    return sorted(p for p in root.glob("*.zarr") if p.is_dir()) if root.is_dir() else []


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


def build_report(stores, out, *, list_unrun: bool = True, claims_file=None) -> Path:
    """Build ``out/index.html``, ``out/plotly.min.js`` and ``out/audit.json`` from ``stores``.

    Parameters
    ----------
    stores : iterable of path
        Zarr stores written by ``python -m pipeline run``; every one must exist and be a
        pipeline store of a format this report reads.
    out : path
        Output directory.
    list_unrun : bool
        Also list the shipped scenes (``workflows/*.toml``) that have no store among ``stores``.
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
    site = SiteBuilder(Path(out))
    site.n_stores = len(loaded)
    rows = evaluate_claims(load_claims(claims_file) if claims_file else load_claims(), loaded)
    site.front = audit_html(rows)
    figures = load_figures()
    place = arrange(loaded, figures, STUDY_KINDS)
    used: set = set()
    for number, fig in enumerate(figures, start=1):
        anchor = _anchor(used, f"fig-{fig.label}")
        parts = [f"<h2>Figure {number} <span class='label'>fig:{esc(fig.label)}</span> — {esc(fig.title)}</h2>",
                 f"<p class='finding'><b>The paper:</b> {esc(fig.finding)}</p>", _verdict_line(rows, fig.label)]
        children = []
        views = place.figures[fig.label]
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
        site.sections.append(Section(anchor, f"Figure {number}: {esc(fig.title)}", "\n".join(parts), "figure",
                                     children))
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
    shipped = {e["name"]: e for e in shipped_scenes()}
    if list_unrun:
        for name, e in shipped.items():
            if name not in have:
                site.add_not_run({**e, "command": f"python -m pipeline run {e['file']}"})
    index = site.write()
    write_audit_json(rows, index.parent / AUDIT_JSON)
    return index
