"""The solver's modules import each other without cycles and without private names, across
its subpackages (the rule and the checks of ``test_pipeline_structure``, applied to
``solver/`` and every folder in it), and its layout shows its architecture: one folder per
concept."""
from __future__ import annotations

import ast
from pathlib import Path

from test_pipeline_structure import REPO, import_cycles, private_imports

#: the subpackages of solver/ and the modules each must hold (a newcomer finds the step
#: kernel, the controller, the events, the estimator and the driver by their file names)
LAYOUT = {
    "model": {"kinematics", "force", "physics", "limits"},
    "periodic": {"radau", "defect", "control", "steps", "record", "switching", "events", "traps",
                 "integrator", "estimators", "global_error", "shooting", "point", "driver",
                 "options", "tolerances"},
    "march": {"heun", "driver"},
    "adjoint": {"gradient", "optimize"},
    "tools": {"bench", "bench_ab", "bench_optimize", "bench_sweep", "honesty"},
}


def package_imports(package_dir: Path) -> dict[str, dict[str, set[str]]]:
    """{module: {imported module: names imported from it}} over every ``*.py`` under
    ``package_dir``, modules named by their dotted path inside the package ("periodic.sweep",
    "solve"), relative imports of any level and absolute ones resolved, at any depth of the
    file.  ``from .pkg import module`` counts as an import of that module."""
    package = package_dir.name
    paths = sorted(package_dir.rglob("*.py"))

    def dotted(path):
        parts = list(path.relative_to(package_dir).with_suffix("").parts)
        return ".".join(parts)

    modules = {dotted(p) for p in paths}
    graph: dict[str, dict[str, set[str]]] = {m: {} for m in modules}
    for path in paths:
        me = dotted(path)
        here = me.split(".")[:-1] if not me.endswith("__init__") else me.split(".")[:-1]
        for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
            if isinstance(node, ast.ImportFrom):
                if node.level:
                    base = here[:len(here) - (node.level - 1)] if node.level > 1 else here
                    target = base + (node.module.split(".") if node.module else [])
                elif node.module and node.module.split(".")[0] == package:
                    target = node.module.split(".")[1:]
                else:
                    continue
                name = ".".join(target)
                if name in modules:
                    graph[me].setdefault(name, set()).update(a.name for a in node.names)
                else:  # from .pkg import module
                    for a in node.names:
                        sub = ".".join(target + [a.name])
                        if sub in modules:
                            graph[me].setdefault(sub, set())
            elif isinstance(node, ast.Import):
                for a in node.names:
                    parts = a.name.split(".")
                    if parts[0] == package and ".".join(parts[1:]) in modules:
                        graph[me].setdefault(".".join(parts[1:]), set())
    return {m: {n: names for n, names in deps.items() if not n.endswith("__init__")}
            for m, deps in graph.items()}


def test_solver_has_no_import_cycles():
    assert import_cycles(package_imports(REPO / "solver")) == []


def test_solver_imports_no_private_names_across_modules():
    assert private_imports(package_imports(REPO / "solver")) == []


def test_solver_is_laid_out_by_concept():
    for folder, modules in LAYOUT.items():
        present = {p.stem for p in (REPO / "solver" / folder).glob("*.py")} - {"__init__"}
        assert present == modules, (folder, present ^ modules)
        assert (REPO / "solver" / folder / "__init__.py").read_text().startswith('"""')


def test_the_checks_walk_subpackages(tmp_path):
    """A cycle and a private name planted across two subpackages are found."""
    pkg = tmp_path / "solver"
    (pkg / "a").mkdir(parents=True)
    (pkg / "b").mkdir()
    for d in (pkg, pkg / "a", pkg / "b"):
        (d / "__init__.py").write_text("")
    (pkg / "a" / "x.py").write_text("from ..b.y import helper\n")
    (pkg / "b" / "y.py").write_text("def helper():\n    from ..a.x import _secret\n")
    (pkg / "top.py").write_text("from .a import x\nimport solver.b.y\n")
    graph = package_imports(pkg)
    assert import_cycles(graph) == [["a.x", "b.y", "a.x"]]
    assert private_imports(graph) == ["b.y: from a.x import _secret"]
    assert set(graph["top"]) == {"a.x", "b.y"}


#: no module of the engine longer than this (issue 37: a module holds one role; scipy's
#: ``integrate/_ivp/radau.py`` is ~570 lines with its dense output)
MAX_ENGINE_MODULE_LINES = 550


def test_engine_modules_hold_one_role_each():
    long = {p.name: n for p in (REPO / "solver" / "periodic").glob("*.py")
            if (n := len(p.read_text(encoding="utf-8").splitlines())) > MAX_ENGINE_MODULE_LINES}
    assert long == {}


def _record_rows() -> set[str]:
    """The row constants of the step record (``periodic.record``: integer assignments)."""
    tree = ast.parse((REPO / "solver" / "periodic" / "record.py").read_text(encoding="utf-8"))
    return {t.id for node in tree.body if isinstance(node, ast.Assign)
            and isinstance(node.value, ast.Constant) and type(node.value.value) is int
            for t in node.targets if isinstance(t, ast.Name)}


def test_only_the_record_indexes_its_rows():
    rows = _record_rows()
    assert {"T", "U", "STAGE", "SENS", "N_FIELDS"} <= rows  # the check sees the layout
    leaks = {module: names & rows
             for module, deps in package_imports(REPO / "solver").items()
             if module != "periodic.record"
             for target, names in deps.items() if target == "periodic.record" and names & rows}
    assert leaks == {}


def _names_from_the_engine(folder: str) -> dict[str, set[str]]:
    """{engine module imported: names} over the files of ``solver/<folder>`` (``from ..periodic
    import x`` is the package's boundary, "periodic"; ``from .. import periodic``, "periodic"
    with the name "periodic")."""
    found: dict[str, set[str]] = {}
    for path in (REPO / "solver" / folder).glob("*.py"):
        for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
            if not isinstance(node, ast.ImportFrom):
                continue
            module = (node.module or "").split(".")
            if node.level == 0 and module[0] == "solver":
                module = module[1:]
            elif node.level != 2:
                continue
            names = {a.asname or a.name for a in node.names}
            if module and module[0] == "periodic":
                found.setdefault(".".join(module), set()).update(names)
            elif not module and "periodic" in names:
                found.setdefault("periodic", set()).add("periodic")
    return found


#: the most names ``adjoint/`` takes from the engine (issue 37: the engine's public boundary
#: instead of its internals, which it took 33 of)
MAX_ADJOINT_ENGINE_NAMES = 12


def test_the_adjoint_uses_the_engines_public_boundary():
    found = _names_from_the_engine("adjoint")
    assert set(found) == {"periodic"}, found  # the package, none of its modules
    assert 0 < len(found["periodic"]) <= MAX_ADJOINT_ENGINE_NAMES, found


def test_the_march_needs_nothing_from_the_engine():
    assert _names_from_the_engine("march") == {}


def _secant_functions(source: str) -> set[str]:
    """Functions of ``source`` (module level) that take a regula falsi (secant) point of a
    bracket, ``(a * fb - b * fa) / (fb - fa)`` in any names: a BinOp Div whose denominator
    is a difference of two names and whose numerator is a difference of two products."""
    found = set()
    for fn in ast.parse(source).body:
        if not isinstance(fn, ast.FunctionDef):
            continue
        for node in ast.walk(fn):
            if (isinstance(node, ast.BinOp) and isinstance(node.op, ast.Div)
                    and isinstance(node.right, ast.BinOp) and isinstance(node.right.op, ast.Sub)
                    and all(isinstance(x, ast.Name) for x in (node.right.left, node.right.right))
                    and isinstance(node.left, ast.BinOp) and isinstance(node.left.op, ast.Sub)
                    and all(isinstance(x, ast.BinOp) and isinstance(x.op, ast.Mult)
                            for x in (node.left.left, node.left.right))):
                found.add(fn.name)
    return found


def test_the_engine_has_one_root_finder():
    """Issue 37: the kinematic stops, the held body's exits and the state events are located
    by one Illinois loop (``periodic.switching.illinois_root``), not three copies."""
    found = {(p.stem, name) for p in (REPO / "solver" / "periodic").glob("*.py")
             for name in _secant_functions(p.read_text(encoding="utf-8"))}
    assert found == {("switching", "illinois_root")}
    # negative control: the three loops before (one shown) are each found
    old = ("def locate_exit(a, b, fa, fb):\n    c = (a * fb - b * fa) / (fb - fa)\n"
           "def _refine_root(a, b, f_a, f_b):\n    c = (a * f_b - b * f_a) / (f_b - f_a)\n")
    assert _secant_functions(old) == {"locate_exit", "_refine_root"}
