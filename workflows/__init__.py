"""The shipped scene files (``*.toml``, described in this folder's ``README.md``), as package data.

They install with the package (``pip install .`` copies them beside ``solver``, ``pipeline`` and
``reports``), so ``python -m pipeline paper`` and the report's list of shipped scenes find them
from any directory and without the checkout: ``DIRECTORY`` is this folder wherever it was
installed (``importlib.resources``; a regular or editable install or the checkout on
``PYTHONPATH``). ``python -m pipeline paper --workflows DIR`` reads the scenes from another folder.
"""

from __future__ import annotations

from importlib.resources import files
from pathlib import Path

__all__ = ["DIRECTORY", "scene_file", "scene_path"]

#: The folder of the shipped ``*.toml`` scene files.
DIRECTORY = Path(str(files(__name__)))


def scene_file(name: str) -> Path:
    """Path of the shipped scene ``name`` (e.g. ``"quick"`` -> ``.../workflows/quick.toml``)."""
    return DIRECTORY / f"{name}.toml"


def scene_path(arg: str) -> str:
    """A command line's scene argument as a path: ``arg`` itself where it names a file (or has a
    folder or a ``.toml`` suffix: then it is a path, found or not), else the shipped scene of that
    name where there is one (``python -m pipeline run quick`` from any directory), else ``arg``
    unchanged (the scene parser then says it cannot read it)."""
    if Path(arg).exists() or arg.endswith(".toml") or "/" in arg or "\\" in arg:
        return arg
    shipped = scene_file(arg)
    return str(shipped) if shipped.is_file() else arg
