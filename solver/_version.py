"""The package's version (from its installed metadata) and the solver engines' versions, for
``--version`` of the three command lines and the report's footer."""

from __future__ import annotations

import argparse
import re
from pathlib import Path

__all__ = ["DISTRIBUTION", "package_version", "engine_versions_text", "version_text", "VersionAction"]

#: The distribution name of ``pyproject.toml`` ([project].name).
DISTRIBUTION = "twolink"


def package_version() -> str:
    """The installed distribution's version (``importlib.metadata``); when the packages run from
    a checkout that is not installed, the checkout's ``pyproject.toml`` version with
    ``+source``; else ``"unknown"``."""
    import importlib.metadata as md

    try:
        return md.version(DISTRIBUTION)
    except md.PackageNotFoundError:
        pass
    pyproject = Path(__file__).resolve().parent.parent / "pyproject.toml"
    try:
        m = re.search(r'^version\s*=\s*"([^"]+)"', pyproject.read_text(encoding="utf-8"), re.MULTILINE)
    except OSError:
        m = None
    return f"{m.group(1)}+source" if m else "unknown"


def engine_versions_text() -> str:
    """``"march 2.1, periodic 5.3"``: each solver engine's version (``solver.ENGINES``)."""
    from .solve import ENGINES

    return ", ".join(ENGINES[name].label for name in sorted(ENGINES))


def version_text(prog: str) -> str:
    """One line: the program, the package version and the engine versions."""
    return f"{prog} ({DISTRIBUTION} {package_version()}; engines {engine_versions_text()})"


class VersionAction(argparse.Action):
    """``--version``: print :func:`version_text` and exit 0. The text is computed only when the
    option is given (it imports the solver)."""

    def __init__(self, option_strings, dest=argparse.SUPPRESS, default=argparse.SUPPRESS, help=None):
        super().__init__(option_strings, dest=dest, default=default, nargs=0,
                         help=help or "print the package and engine versions and exit")

    def __call__(self, parser, namespace, values, option_string=None):
        print(version_text(parser.prog))
        parser.exit(0)
