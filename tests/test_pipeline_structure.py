"""The pipeline's modules import each other without cycles and without private names.

A name another module imports is public (it may live in a private module, as scipy's
``_ivp``): ``from ._store import _create`` is a hidden contract.  Imports inside functions
count: they are how a cycle used to be hidden (``_run`` <-> ``_optima`` / ``_study``, issue 20).
"""

from __future__ import annotations

import ast
from pathlib import Path

REPO = Path(__file__).resolve().parent.parent


def _private(name: str) -> bool:
    return name.startswith("_") and not name.startswith("__")


def sibling_imports(package_dir: Path) -> dict[str, dict[str, set[str]]]:
    """{module: {imported sibling module: names imported from it}} over ``package_dir/*.py``
    (relative and absolute imports, at any depth of the file)."""
    package = package_dir.name
    modules = {p.stem for p in package_dir.glob("*.py")}
    graph: dict[str, dict[str, set[str]]] = {m: {} for m in modules}
    for path in sorted(package_dir.glob("*.py")):
        for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
            if isinstance(node, ast.ImportFrom):
                if node.level == 1:
                    parts = node.module.split(".") if node.module else []
                elif node.level == 0 and node.module and node.module.split(".")[0] == package:
                    parts = node.module.split(".")[1:]
                else:
                    continue
                if parts and parts[0] in modules:
                    graph[path.stem].setdefault(parts[0], set()).update(a.name for a in node.names)
                elif not parts:  # from . import _store, _scene
                    for a in node.names:
                        if a.name in modules:
                            graph[path.stem].setdefault(a.name, set())
            elif isinstance(node, ast.Import):
                for a in node.names:
                    parts = a.name.split(".")
                    if parts[0] == package and len(parts) > 1 and parts[1] in modules:
                        graph[path.stem].setdefault(parts[1], set())
    return graph


def import_cycles(graph) -> list[list[str]]:
    """Every cycle of the module graph found by depth-first search (each as a closed path)."""
    cycles, state = [], {}

    def visit(m, path):
        state[m] = "open"
        for n in sorted(graph.get(m, {})):
            if n == "__init__" or n == m:
                continue
            if state.get(n) == "open":
                cycles.append(path[path.index(n):] + [n])
            elif n not in state:
                visit(n, path + [n])
        state[m] = "done"

    for m in sorted(graph):
        if m not in state and m != "__init__":
            visit(m, [m])
    return cycles


def private_imports(graph) -> list[str]:
    """``module: from sibling import _name`` for every private name crossing modules."""
    return [f"{m}: from {n} import {name}" for m, deps in sorted(graph.items()) for n, names in sorted(deps.items())
            for name in sorted(names) if _private(name)]


def test_pipeline_has_no_import_cycles():
    assert import_cycles(sibling_imports(REPO / "pipeline")) == []


def test_pipeline_imports_no_private_names_across_modules():
    assert private_imports(sibling_imports(REPO / "pipeline")) == []


def test_the_checks_fail_on_a_planted_cycle_and_private_name(tmp_path):
    pkg = tmp_path / "pipeline"
    pkg.mkdir()
    (pkg / "__init__.py").write_text("from ._a import run\n")
    (pkg / "_a.py").write_text("from ._b import helper\n\ndef run():\n    return helper()\n")
    (pkg / "_b.py").write_text("def helper():\n    from ._a import _secret\n    return _secret\n")
    (pkg / "_c.py").write_text("import pipeline._a\nfrom pipeline import _b\n")
    graph = sibling_imports(pkg)
    assert import_cycles(graph) == [["_a", "_b", "_a"]]
    assert private_imports(graph) == ["_b: from _a import _secret"]
    assert set(graph["_c"]) == {"_a", "_b"}


def test_each_kind_keeps_its_schema_apart_and_the_shared_parser_knows_no_kind():
    """Every kind has the same shape (issue 34): its scene's schema in a ``_<kind>_scene``
    module, its compute and steps in another; the shared parser (``_scene``: errors, value
    checks, axes, hashing) imports no sibling, so no kind's schema can hide in it."""
    from pipeline import KINDS, load_scene

    assert sibling_imports(REPO / "pipeline")["_scene"] == {}
    shipped = {"grid": "quick", "optima": "fourier_optima", "accuracy": "accuracy", "stiffness": "stiffness"}
    assert set(shipped) == set(KINDS)
    for kind, name in shipped.items():
        scene = load_scene(REPO / "workflows" / f"{name}.toml")
        schema, compute = type(scene).__module__, type(KINDS[kind]).__module__
        assert scene.kind == kind
        assert schema.startswith("pipeline._") and schema.endswith("_scene") and schema != "pipeline._scene", schema
        assert compute != schema, (kind, compute)


#: the libraries whose file format the package must reach only through their public API
#: (issue 46: the store format code once imported zarr's internals)
FORMAT_LIBRARIES = ("zarr", "numcodecs")
#: private attributes of zarr objects the package once used (``ZstdCodec(...)._zstd_codec``,
#: ``MemoryStore._store_dict``): named here, as an import check cannot see an attribute
PRIVATE_ATTRIBUTES = ("_zstd_codec", "_store_dict")


def private_library_uses(package_dir: Path) -> list[str]:
    """``file:line: what`` for every import of ``zarr.core`` or of an underscore name (module
    or member) of :data:`FORMAT_LIBRARIES`, and every use of :data:`PRIVATE_ATTRIBUTES`, in
    the modules of ``package_dir`` (at any depth of the file and of the package)."""
    found = []
    for path in sorted(package_dir.rglob("*.py")):
        rel = path.relative_to(package_dir.parent)
        for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
            modules, members = [], []
            if isinstance(node, ast.Import):
                modules = [a.name for a in node.names]
            elif isinstance(node, ast.ImportFrom) and node.level == 0 and node.module:
                modules, members = [node.module], [a.name for a in node.names]
            elif isinstance(node, ast.Attribute) and node.attr in PRIVATE_ATTRIBUTES:
                found.append(f"{rel}:{node.lineno}: .{node.attr}")
            for m in modules:
                parts = m.split(".")
                if parts[0] not in FORMAT_LIBRARIES:
                    continue
                if parts[:2] == ["zarr", "core"] or any(_private(p) for p in parts):
                    found.append(f"{rel}:{node.lineno}: import {m}")
                found += [f"{rel}:{node.lineno}: from {m} import {n}" for n in members if _private(n)]
    return found


def test_no_package_reaches_into_zarrs_internals():
    """Issue 46: no module of the packages imports ``zarr.core`` or an underscore name of zarr
    or numcodecs (only the ``zarr>=3.1,<3.2`` pin protected such code)."""
    for package in ("pipeline", "reports", "solver", "workflows"):
        assert private_library_uses(REPO / package) == [], package


def test_the_internals_check_finds_each_planted_use(tmp_path):
    pkg = tmp_path / "pkg"
    (pkg / "sub").mkdir(parents=True)
    (pkg / "a.py").write_text("import zarr\nfrom zarr.core.sync import sync\nimport zarr.core.group\n")
    (pkg / "sub" / "b.py").write_text("def f(z):\n    from numcodecs import _shuffle\n    return z._store_dict\n")
    (pkg / "c.py").write_text("from zarr.storage import LocalStore\nfrom zarr import open_array\n")
    assert private_library_uses(pkg) == ["pkg/a.py:2: import zarr.core.sync", "pkg/a.py:3: import zarr.core.group",
                                         "pkg/sub/b.py:2: from numcodecs import _shuffle",
                                         "pkg/sub/b.py:3: ._store_dict"]
