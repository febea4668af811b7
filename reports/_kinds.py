"""The one registry of section renderers, keyed by a store's scene kind.

A renderer is ``render(site, store, anchor) -> html``: the view of one store (or of a part of
it, see :mod:`reports._paper`) with its title as an ``h3`` carrying ``anchor`` and its parts
below. The pipeline never imports the reports; a new scene kind adds one entry here.
"""

from __future__ import annotations

from ._grid import grid_section
from ._optima import optima_section
from ._study import study_section

__all__ = ["SECTION_RENDERERS", "STUDY_KINDS", "scene_kind", "render_view"]

SECTION_RENDERERS = {
    "grid": grid_section,
    "optima": optima_section,
    "accuracy": study_section,
    "stiffness": study_section,
}
#: Kinds shown after the paper's figures, under "Studies".
STUDY_KINDS = frozenset({"accuracy", "stiffness"})


def scene_kind(sd) -> str:
    """The store's scene kind (``pipeline.kind`` attribute; "grid" when absent)."""
    return sd.meta.get("kind", "grid")


def render_view(site, sd, anchor: str) -> str:
    """The HTML of ``sd``'s view through the renderer of its kind (an error box for an unknown kind)."""
    kind = scene_kind(sd)
    render = SECTION_RENDERERS.get(kind)
    if render is None:
        def unknown():
            raise ValueError(f"no report section for scene kind {kind!r} "
                             f"(known: {', '.join(sorted(SECTION_RENDERERS))})")
        return f"<h3 id='{anchor}'>{sd.name}</h3>" + site.guarded(sd.name, unknown)
    return render(site, sd, anchor)
