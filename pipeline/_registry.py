"""The scene kinds by name, and reading a scene file of any kind.

``[scene] kind`` selects the kind (``grid`` when absent): its parser validates the file, and
the driver (``pipeline._run``) runs the scene through the kind's skeleton, chunk task and steps.
"""

from __future__ import annotations

from pathlib import Path

from ._kind import SceneKind
from ._optima import OPTIMA
from ._scene import ParseContext, read_scene_file, read_toml
from ._study import STUDY
from ._grid_kind import GRID

__all__ = ["KINDS", "kind_of", "load_scene", "parse_scene"]

#: every scene kind by its ``[scene] kind`` name
KINDS: dict[str, SceneKind] = {name: kind for kind in (GRID, OPTIMA, STUDY) for name in kind.names}


def kind_of(scene) -> SceneKind:
    """The kind that runs ``scene`` (a parsed scene of any kind)."""
    return KINDS[scene.kind]


def parse_scene(text: str, file: str = "<scene>"):
    """Parse and validate scene TOML ``text`` of any kind; ``file`` is used in error messages.

    Raises :class:`~pipeline.SceneError` (file, key and reason on one line).
    """
    ctx = ParseContext(file)
    doc = read_toml(text, ctx)
    head = doc.get("scene")
    kind = head.get("kind", "grid") if isinstance(head, dict) else "grid"
    return KINDS[ctx.string(kind, "scene.kind", tuple(KINDS))].parse(doc, ctx, text)


def load_scene(path: str | Path):
    """Read and validate a scene file of any kind. Raises :class:`~pipeline.SceneError`."""
    return parse_scene(read_scene_file(path), str(path))
