"""The engine's options passed at run time (``solve_periodic(..., options=EngineOptions(...))``,
``periodic.options``; issue 37): the defaults give the same bits as no options, another
value reaches the kernels (the steps change) on the same compiled kernels, and bad options
are refused by name.
"""
from __future__ import annotations

import numpy as np
import pytest

import solver
from solver.periodic import driver, point
from solver.status import NOT_PERIODIC
from solver.tools import bench_sweep
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
    (solver.EngineOptions(stage=solver.StageOptions(max_iterations=0)),
     "options.stage.max_iterations: must lie in [1"),
    (solver.EngineOptions(stage=solver.StageOptions(first_correction_share=2.0)),
     "options.stage.first_correction_share: must lie in [0, 1]"),
    (solver.EngineOptions(defect=solver.DefectOptions(variable_slope_limit=64.0)),
     "options.defect.variable_slope_limit: must lie in [0, 32]"),
    (solver.EngineOptions(defect=solver.DefectOptions(fit=-1.0)),
     "options.defect.fit: must lie in [0"),
    (solver.EngineOptions(tolerances=solver.ToleranceOptions(loose_rtol=1.0)),
     "options.tolerances.loose_rtol: must lie in (0, 1)"),
    (solver.EngineOptions(tolerances=solver.ToleranceOptions(u_norm_floor=0.0)),
     "options.tolerances.u_norm_floor: must lie in (0, 1]"),
    (solver.EngineOptions(point=solver.PointOptions(max_frozen_passes=2.5)),
     "options.point.max_frozen_passes: expected an integer"),
    (solver.EngineOptions(batch=solver.BatchOptions(guess_steps=2)),
     "options.batch.guess_steps: must lie in [4"),
    (solver.EngineOptions(batch=solver.BatchOptions(start_capacity=None)),
     "options.batch.start_capacity: expected an integer"),
    (solver.EngineOptions(tolerances=solver.StageOptions()),
     "options.tolerances: expected a ToleranceOptions"),
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


def _close_to_default(res, default, kin, phys):
    """Converged everywhere and within 10 rtol of the default solve's results (both judged
    by the same estimate, each within rtol of the truth)."""
    assert res.converged.all()
    error = solution_error(res.U, res.P, default.U, default.P, phys.period,
                           solver.kinematic_speed(kin))
    assert np.nanmax(error) <= 10 * RTOL


def test_a_stage_option_reaches_the_stage_solve(points):
    """``StageOptions.first_correction_share`` (default 0.1) lets the loose passes keep
    Newton's first correction where the carried constant predicts the next below that share
    of the tolerance: 0 never does, so the loose shooting evaluates F more often (measured
    21,163 -> 23,437 on these 40 points); results within 10 rtol, on the same kernels."""
    kin, phys = points
    default = solver.solve_periodic(kin, phys, rtol=RTOL)
    fresh = solver.solve_periodic(kin, phys, rtol=RTOL, options=solver.EngineOptions(
        stage=solver.StageOptions(first_correction_share=0.0)))
    loose = point.COST_LOOSE
    assert fresh.force_evaluations[:, loose].sum() > default.force_evaluations[:, loose].sum()
    _close_to_default(fresh, default, kin, phys)
    assert len(driver.solve_lane.signatures) == 1


def test_a_defect_option_reaches_the_estimate(points):
    """``DefectOptions.fit`` (default 0.5): at 0.1 more steps' defect model counts as not
    fitting, and those are judged by the larger of the defect and the embedded estimates,
    so the target passes take more steps; results within 10 rtol, on the same kernels."""
    kin, phys = points
    default = solver.solve_periodic(kin, phys, rtol=RTOL)
    strict = solver.solve_periodic(kin, phys, rtol=RTOL, options=solver.EngineOptions(
        defect=solver.DefectOptions(fit=0.1)))
    assert strict.n_tau.sum() > default.n_tau.sum()
    _close_to_default(strict, default, kin, phys)
    assert len(driver.solve_lane.signatures) == 1


def test_a_tolerance_option_reaches_the_tolerances(points):
    """``ToleranceOptions.target_share`` (default 0.8): the passes aiming at 0.4 rtol take
    more steps; results within 10 rtol of the default's, on the same kernels."""
    kin, phys = points
    default = solver.solve_periodic(kin, phys, rtol=RTOL)
    tight = solver.solve_periodic(kin, phys, rtol=RTOL, options=solver.EngineOptions(
        tolerances=solver.ToleranceOptions(target_share=0.4)))
    assert tight.n_tau.sum() > default.n_tau.sum()
    _close_to_default(tight, default, kin, phys)
    assert len(driver.solve_lane.signatures) == 1


def test_a_frozen_pass_limit_reaches_the_rounds(points):
    """``PointOptions.max_frozen_passes`` (default 30): at most 2 frozen Newton passes per
    round cut some rounds' Newton short, so more passes are made in all (the next round
    starts from Newton's best u(0)); results within 10 rtol, on the same kernels."""
    kin, phys = points
    default = solver.solve_periodic(kin, phys, rtol=RTOL)
    short = solver.solve_periodic(kin, phys, rtol=RTOL, options=solver.EngineOptions(
        point=solver.PointOptions(max_frozen_passes=2)))
    assert short.iterations.sum() > default.iterations.sum()
    _close_to_default(short, default, kin, phys)
    assert len(driver.solve_lane.signatures) == 1


def test_the_options_reach_the_fixed_grid_path(points):
    """The fixed-grid solve (``solve_fixed_grid``: ``periodic.shooting.frozen_orbit``, the
    adjoint's forward solve) takes the options too: a looser stage tolerance
    (``ToleranceOptions.stage_share`` 1e-2, default 1e-5) moves the discrete solution by
    less than rtol V, not by nothing; one frozen Newton pass (``max_frozen_passes`` 1) does
    not reach the fixed point from the fast limit (NOT_PERIODIC at every point); one
    compiled signature for all."""
    kin, phys = points
    rtol = 1e-6
    default = solver.solve_fixed_grid(kin, phys, 64, rtol=rtol)
    loose = solver.solve_fixed_grid(kin, phys, 64, rtol=rtol, options=solver.EngineOptions(
        tolerances=solver.ToleranceOptions(stage_share=1e-2)))
    assert (default[2] == 0).all() and (loose[2] == 0).all()
    assert not np.array_equal(default[0], loose[0])
    assert np.max(np.abs(loose[0] - default[0]) / solver.kinematic_speed(kin)) <= rtol
    once = solver.solve_fixed_grid(kin, phys, 64, rtol=rtol, options=solver.EngineOptions(
        point=solver.PointOptions(max_frozen_passes=1)))
    assert (once[2] == NOT_PERIODIC).all()
    assert len(driver._fixed_grid_lane.signatures) == 1
    with pytest.raises(ValueError, match="options: the engine's options are for method"):
        solver.solve_fixed_grid(kin, phys, 64, method="march", options=solver.EngineOptions())


def test_a_batch_option_reaches_the_sweeps(points):
    """``BatchOptions``: ``in_line_share`` 0 (default 1e-9) never takes a sweep's points as
    lying on a line, so u(0) is not extrapolated along it and the warm solves change;
    ``guess_steps`` 64 (default 8) moves the fast limit's u that starts the cold solves;
    both within 10 rtol.  ``start_capacity`` 1 (default 512) only makes the step record
    grow from one step: bit-identical results."""
    kin, phys = bench_sweep.grid("harmonic", 16.0, 0.5, 8)
    runs = solver.sweep_runs(len(kin), 32)
    default = solver.solve_periodic(kin, phys, rtol=RTOL, sweeps=runs)
    unlined = solver.solve_periodic(kin, phys, rtol=RTOL, sweeps=runs, options=solver.EngineOptions(
        batch=solver.BatchOptions(in_line_share=0.0)))
    assert not np.array_equal(default.force_evaluations, unlined.force_evaluations)
    _close_to_default(unlined, default, kin, phys)
    kin, phys = points
    default = solver.solve_periodic(kin, phys, rtol=RTOL)
    finer = solver.solve_periodic(kin, phys, rtol=RTOL, options=solver.EngineOptions(
        batch=solver.BatchOptions(guess_steps=64)))
    assert not np.array_equal(default.force_evaluations, finer.force_evaluations)
    _close_to_default(finer, default, kin, phys)
    small = solver.solve_periodic(kin, phys, rtol=RTOL, return_series=True,
                                  options=solver.EngineOptions(
                                      batch=solver.BatchOptions(start_capacity=1)))
    for a, b in zip(_fields(default), _fields(small)):
        assert np.array_equal(a, b, equal_nan=True)
    assert len(driver.solve_lane.signatures) == 1


def test_the_result_records_its_options(points):
    """``SolveResult.options``: the defaults where none were given, else the checked
    options (an integral float normalised to the int it stands for); None for the march.
    ``periodic.engine_options`` lists them flat, one entry per field of every role."""
    kin, phys = points
    one_k, one_p = kin.take(np.arange(1)), phys.take(np.arange(1))
    assert solver.solve_periodic(one_k, one_p, rtol=RTOL).options == solver.EngineOptions()
    given = solver.EngineOptions(stage=solver.StageOptions(max_iterations=20.0))
    used = solver.solve_periodic(one_k, one_p, rtol=RTOL, options=given).options
    assert used.stage.max_iterations == 20 and isinstance(used.stage.max_iterations, int)
    assert solver.solve_periodic(one_k, one_p, rtol=RTOL, method="march").options is None
    flat = solver.periodic.engine_options(used)
    assert flat["stage.max_iterations"] == 20 and flat["control.max_factor"] == 3.0
    assert len(flat) == sum(len(group) for group in solver.EngineOptions())


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


def _constants_not_passed(namespace: dict, passed: set[str]) -> set[str]:
    return {name for name, value in namespace.items() if name.isupper()
            and isinstance(value, (int, float)) and not isinstance(value, bool)} - passed


def test_every_tuning_constant_is_an_option():
    """Every number defined at module level in ``periodic/options.py`` is the default of an
    EngineOptions field (what defines the method, the Radau tableau and the defect
    estimate's samples, lives in its own module), and no engine module reads
    ``options.NAME`` either; the fields' defaults are those constants."""
    import re
    from pathlib import Path

    from solver.periodic import defect, options

    passed = _option_constants()
    assert _constants_not_passed(vars(options), passed) == set()
    assert len(passed) == sum(len(group) for group in options.DEFAULT_OPTIONS)
    for role, group in zip(options.EngineOptions._fields, options.DEFAULT_OPTIONS):
        for name, value in zip(group._fields, group):
            assert value == solver.periodic.engine_options()[f"{role}.{name}"]
    assert (defect.THETA_MID, defect.THETA_LATE) == (0.5, 0.85)
    folder = Path(solver.__file__).parent / "periodic"
    reads = {p.stem: re.findall(r"\boptions\.[A-Z][A-Z_]+\b", p.read_text())
             for p in folder.glob("*.py") if p.stem != "options"}
    assert {k: v for k, v in reads.items() if v} == {}
    # negative control: a constant that is no field's default is found
    assert _constants_not_passed({"MAX_FACTOR": 3.0, "NEW_KNOB": 2, "TABLE": [1.0]},
                                 {"MAX_FACTOR"}) == {"NEW_KNOB"}
