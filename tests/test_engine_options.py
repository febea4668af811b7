"""The engine's options passed at run time (``solve_periodic(..., options=EngineOptions(...))``,
``periodic.options``; issue 37): the defaults give the same bits as no options, another
value reaches the kernels (the steps change) on the same compiled kernels, and bad options
are refused by name.
"""
from __future__ import annotations

import numpy as np
import pytest

import solver
from solver.periodic import driver
from solver.tools.bench import draw_points, solution_error

RTOL = 1e-4


@pytest.fixture(scope="module")
def points():
    kin, phys, _ = draw_points(40, np.random.default_rng(3))
    return kin, phys


def _fields(res):
    return [np.asarray(getattr(res, f)) for f in ("U", "P", "status", "error_estimate", "n_tau",
                                                    "iterations", "force_evaluations")]


def test_the_default_options_are_the_defaults_bit_for_bit(points):
    kin, phys = points
    none = solver.solve_periodic(kin, phys, rtol=RTOL)
    given = solver.solve_periodic(kin, phys, rtol=RTOL, options=solver.EngineOptions())
    for a, b in zip(_fields(none), _fields(given)):
        assert np.array_equal(a, b, equal_nan=True)


def test_another_controller_reaches_the_steps_on_the_same_kernels(points):
    """A smaller largest step growth (max_factor 1.5, default 3) changes the step sequences
    (so the option is read by the kernels, not the module constant), keeps the results
    within 10 rtol of the default solve's (both judged by the same estimate), and compiles
    nothing new: ``solve_lane`` keeps one signature for both values."""
    kin, phys = points
    default = solver.solve_periodic(kin, phys, rtol=RTOL)
    slow = solver.solve_periodic(kin, phys, rtol=RTOL, options=solver.EngineOptions(
        control=solver.ControlOptions(max_factor=1.5)))
    assert default.converged.all() and slow.converged.all()
    assert not np.array_equal(default.n_tau, slow.n_tau)
    assert slow.force_evaluations.sum() > default.force_evaluations.sum()  # more steps
    error = solution_error(slow.U, slow.P, default.U, default.P, phys.period,
                           solver.kinematic_speed(kin))
    assert np.nanmax(error) <= 10 * RTOL
    # an int is normalised to a float: the same type, the same kernels
    solver.solve_periodic(kin, phys, rtol=RTOL, options=solver.EngineOptions(
        control=solver.ControlOptions(max_factor=2)))
    assert len(driver.solve_lane.signatures) == 1


@pytest.mark.parametrize("options,words", [
    (solver.EngineOptions(control=solver.ControlOptions(max_factor=0.5)),
     "options.control.max_factor: must lie in [1"),
    (solver.EngineOptions(control=solver.ControlOptions(safety=0.0)),
     "options.control.safety: must lie in (0"),
    (solver.EngineOptions(control=solver.ControlOptions(min_factor="x")),
     "options.control.min_factor: expected a number"),
    (solver.EngineOptions(control=(0.9, 0.2, 3.0)), "options.control: expected a ControlOptions"),
    ({"control": {}}, "options: expected an EngineOptions"),
])
def test_bad_options_are_refused_by_name(points, options, words):
    kin, phys = points
    with pytest.raises(ValueError) as info:
        solver.solve_periodic(kin.take(np.arange(1)), phys.take(np.arange(1)), rtol=RTOL,
                              options=options)
    assert words in str(info.value), str(info.value)


def test_options_are_for_the_periodic_engine_only(points):
    kin, phys = points
    with pytest.raises(ValueError, match="options: the engine's options are for method 'periodic'"):
        solver.solve_periodic(kin.take(np.arange(1)), phys.take(np.arange(1)), rtol=RTOL,
                              method="march", options=solver.EngineOptions())


def test_a_point_option_reaches_the_solve(points):
    """``PointOptions.first_step`` (default 1/16) starts the loose shooting: 1/4 changes the
    loose passes' steps and so the evaluations, within 10 rtol of the default results; an
    integral float is taken for an int option (max_rounds 4.0), a fraction is refused."""
    kin, phys = points
    default = solver.solve_periodic(kin, phys, rtol=RTOL)
    other = solver.solve_periodic(kin, phys, rtol=RTOL, options=solver.EngineOptions(
        point=solver.PointOptions(first_step=0.25, max_rounds=4.0)))
    assert other.converged.all()
    assert not np.array_equal(default.force_evaluations, other.force_evaluations)
    error = solution_error(other.U, other.P, default.U, default.P, phys.period,
                           solver.kinematic_speed(kin))
    assert np.nanmax(error) <= 10 * RTOL
    assert len(driver.solve_lane.signatures) == 1
    with pytest.raises(ValueError, match="options.point.max_rounds: expected an integer"):
        solver.periodic.checked_options(solver.EngineOptions(point=solver.PointOptions(
            max_rounds=1.5)))


def test_a_trap_option_reaches_the_steps_next_to_turning_points(points):
    """``TrapOptions.share`` (default 0.1) caps the steps next to turning points of phi (the
    bench's motions have them): a tenth of it adds steps there, within 10 rtol of the
    default results, on the same kernels."""
    kin, phys = points
    default = solver.solve_periodic(kin, phys, rtol=RTOL)
    tight = solver.solve_periodic(kin, phys, rtol=RTOL, options=solver.EngineOptions(
        traps=solver.TrapOptions(share=0.01)))
    assert tight.converged.all()
    assert tight.n_tau.sum() > default.n_tau.sum()
    error = solution_error(tight.U, tight.P, default.U, default.P, phys.period,
                           solver.kinematic_speed(kin))
    assert np.nanmax(error) <= 10 * RTOL
    assert len(driver.solve_lane.signatures) == 1


def test_a_stop_option_reaches_the_kinematic_stops(points):
    """``StopOptions.tangency_share`` (default 0.1) decides which minima of |omega| are
    near-tangencies (stops) and which stops are turning points: 0.3 makes more of both on
    the bench's motions, so the steps change; results within 10 rtol of the default's."""
    kin, phys = points
    default = solver.solve_periodic(kin, phys, rtol=RTOL)
    wide = solver.solve_periodic(kin, phys, rtol=RTOL, options=solver.EngineOptions(
        stops=solver.StopOptions(tangency_share=0.3)))
    assert wide.converged.all()
    assert not np.array_equal(default.n_tau, wide.n_tau)
    error = solution_error(wide.U, wide.P, default.U, default.P, phys.period,
                           solver.kinematic_speed(kin))
    assert np.nanmax(error) <= 10 * RTOL
    assert len(driver.solve_lane.signatures) == 1


def test_an_event_option_reaches_the_cuts(points):
    """``EventOptions.max_cuts`` (default 4): 0 never cuts a step at a state event (each
    is then judged by the error estimate inside its step), so the steps change; results
    within 10 rtol of the default's, on the same kernels."""
    kin, phys = points
    default = solver.solve_periodic(kin, phys, rtol=RTOL)
    uncut = solver.solve_periodic(kin, phys, rtol=RTOL, options=solver.EngineOptions(
        events=solver.EventOptions(max_cuts=0)))
    assert uncut.converged.all()
    assert not np.array_equal(default.n_tau, uncut.n_tau)
    error = solution_error(uncut.U, uncut.P, default.U, default.P, phys.period,
                           solver.kinematic_speed(kin))
    assert np.nanmax(error) <= 10 * RTOL
    assert len(driver.solve_lane.signatures) == 1


def test_a_step_option_reaches_the_pass(points):
    """``StepOptions.stretch`` (default 1.25): 1 never stretches a proposed step to a stop
    just past it, so the steps change; results within 10 rtol of the default's, on the same
    kernels."""
    kin, phys = points
    default = solver.solve_periodic(kin, phys, rtol=RTOL)
    unstretched = solver.solve_periodic(kin, phys, rtol=RTOL, options=solver.EngineOptions(
        steps=solver.StepOptions(stretch=1.0)))
    assert unstretched.converged.all()
    assert not np.array_equal(default.n_tau, unstretched.n_tau)
    error = solution_error(unstretched.U, unstretched.P, default.U, default.P, phys.period,
                           solver.kinematic_speed(kin))
    assert np.nanmax(error) <= 10 * RTOL
    assert len(driver.solve_lane.signatures) == 1


def _option_constants() -> set[str]:
    """The module constants of ``periodic/options.py`` that are an EngineOptions field's
    default (``name: type = CONSTANT`` in a role's NamedTuple)."""
    import ast
    from pathlib import Path

    tree = ast.parse((Path(solver.__file__).parent / "periodic" / "options.py").read_text())
    return {node.value.id for cls in tree.body if isinstance(cls, ast.ClassDef)
            for node in cls.body if isinstance(node, ast.AnnAssign)
            and isinstance(node.value, ast.Name)}


def _imported_from_options(source: str) -> set[str]:
    import ast

    return {a.name for node in ast.walk(ast.parse(source)) if isinstance(node, ast.ImportFrom)
            and node.module == "options" and node.level == 1 for a in node.names}


def test_no_kernel_reads_a_run_time_option_as_a_global():
    """A constant that is an EngineOptions default must reach the kernels through the
    options only: no engine module but ``options`` imports it (it would be frozen at
    compile time, and a caller's value silently ignored)."""
    from pathlib import Path

    passed = _option_constants()
    assert {"MAX_FACTOR", "TRAP_SHARE", "EVENT_BAND", "MIN_STEP", "TANGENCY_SHARE"} <= passed
    folder = Path(solver.__file__).parent / "periodic"
    leaks = {p.stem: _imported_from_options(p.read_text()) & passed
             for p in folder.glob("*.py") if p.stem != "options"}
    assert {k: v for k, v in leaks.items() if v} == {}
    # negative control: the controller's import before the options were passed through
    old = "from .options import MAX_FACTOR, MIN_FACTOR, SAFETY\n"
    assert _imported_from_options(old) & passed == {"MAX_FACTOR", "MIN_FACTOR", "SAFETY"}
