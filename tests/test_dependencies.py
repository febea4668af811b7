"""Every third-party module the package imports is a declared runtime dependency.

A module imported anywhere in ``solver/``, ``pipeline/`` or ``reports/`` (at the top of a file
or inside a function: both run on a user's machine) must come from a distribution listed in
``[project].dependencies``: an optional extra is not installed by ``pip install -e .``, and the
README's main command crashed on ``xarray``, which only the test extra provided (issue 20).
"""

from __future__ import annotations

import ast
import importlib.metadata as md
import re
import sys
import tomllib
from pathlib import Path

REPO = Path(__file__).resolve().parent.parent
PACKAGES = ("solver", "pipeline", "reports", "workflows")


def normalise(name: str) -> str:
    """A distribution name in PEP 503 normal form (``Foo_bar`` -> ``foo-bar``)."""
    return re.sub(r"[-_.]+", "-", name).lower()


def declared_dependencies(pyproject: Path) -> set[str]:
    """Normalised distribution names of ``[project].dependencies`` (no extras)."""
    deps = tomllib.loads(pyproject.read_text())["project"].get("dependencies", [])
    return {normalise(re.split(r"[\s<>=!~;\[(@]", d, maxsplit=1)[0]) for d in deps}


def imported_modules(path: Path) -> set[str]:
    """Top-level names of the absolute imports in the Python file ``path``."""
    tree = ast.parse(path.read_text(encoding="utf-8"), filename=str(path))
    names = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            names.update(alias.name.split(".")[0] for alias in node.names)
        elif isinstance(node, ast.ImportFrom) and node.level == 0 and node.module:
            names.add(node.module.split(".")[0])
    return names


def undeclared_imports(root: Path, packages, declared: set[str],
                       distributions: dict[str, list[str]] | None = None) -> list[str]:
    """``"module (file)"`` for every third-party import under ``root/<package>`` that no
    declared distribution provides.

    Standard-library modules (``sys.stdlib_module_names``) and the packages themselves are
    skipped; an import name maps to its distributions by ``distributions`` (default
    ``importlib.metadata.packages_distributions()``), and a name no installed distribution
    provides is taken as its own distribution name.
    """
    if distributions is None:
        distributions = md.packages_distributions()
    local = set(packages)
    out = []
    for package in packages:
        for path in sorted((root / package).rglob("*.py")):
            for name in sorted(imported_modules(path)):
                if name in sys.stdlib_module_names or name in local:
                    continue
                provided = {normalise(d) for d in distributions.get(name, [name])}
                if not provided & declared:
                    out.append(f"{name} ({path.relative_to(root)})")
    return out


def test_every_third_party_import_is_a_runtime_dependency():
    declared = declared_dependencies(REPO / "pyproject.toml")
    assert undeclared_imports(REPO, PACKAGES, declared) == []


def test_checker_flags_an_undeclared_import(tmp_path):
    """The check can fail: a planted import of a test-only or unknown distribution is named,
    whether at the top of a file or inside a function, and a declared one is not."""
    pkg = tmp_path / "solver" / "sub"
    pkg.mkdir(parents=True)
    (tmp_path / "solver" / "__init__.py").write_text("import numpy\nfrom . import sub\nfrom solver import sub\n")
    (pkg / "__init__.py").write_text("import os, json\n\ndef f():\n    import mpmath.libmp\n"
                                     "    from not_a_distribution_xyz import thing\n")
    declared = {"numpy"}
    found = undeclared_imports(tmp_path, ("solver",), declared,
                               distributions={"numpy": ["numpy"], "mpmath": ["mpmath"]})
    assert found == ["mpmath (solver/sub/__init__.py)", "not_a_distribution_xyz (solver/sub/__init__.py)"]
    # declaring them clears the finding; import names map to distributions (PIL -> Pillow)
    (pkg / "__init__.py").write_text("from PIL import Image\n")
    assert undeclared_imports(tmp_path, ("solver",), {"numpy", "pillow"},
                              distributions={"PIL": ["Pillow"]}) == []
    assert undeclared_imports(tmp_path, ("solver",), {"numpy"},
                              distributions={"PIL": ["Pillow"]}) == ["PIL (solver/sub/__init__.py)"]


def test_declared_names_are_parsed_without_versions(tmp_path):
    py = tmp_path / "pyproject.toml"
    py.write_text('[project]\ndependencies = ["numpy>=1.26,<2.5", "Zarr_Python [extra] ~= 3.1", '
                  '"dask; python_version >= \'3.11\'"]\n')
    assert declared_dependencies(py) == {"numpy", "zarr-python", "dask"}
