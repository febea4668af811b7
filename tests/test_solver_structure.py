"""The solver's modules import each other without cycles and without private names (the rule
and the checks of ``test_pipeline_structure``, applied to ``solver/``)."""

from test_pipeline_structure import REPO, import_cycles, private_imports, sibling_imports


def test_solver_has_no_import_cycles():
    assert import_cycles(sibling_imports(REPO / "solver")) == []


def test_solver_imports_no_private_names_across_modules():
    assert private_imports(sibling_imports(REPO / "solver")) == []
