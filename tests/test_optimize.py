"""optimize_motion: convergence to gtol with counted work, phase fix, bounds, ill-conditioning."""
from types import SimpleNamespace

import numpy as np
import pytest

import solver
from solver.adjoint.gradient import (FixedGrid, discrete_objective, objective_gradient, speed_at_power,
                              with_period)
from solver.adjoint.optimize import optimize_motion


def test_harmonic_converges_to_gtol():
    physics = solver.Physics.from_scaled(2.0 ** -4, 2.0)
    res = optimize_motion(solver.Harmonic(1.0, 0.5), physics, grid=128)
    assert res.stop_reason == "gradient_tolerance" and res.converged
    assert res.gradient_norm < 1e-7
    assert res.iterations <= 60 and res.gradient_evaluations <= 150
    assert res.efficiency < 0 and not res.ill_conditioned
    # a maximum of |lambda| on this grid: no neighbour in (A0, A1, T) does better
    grid = FixedGrid.uniform(res.kinematics, 128)
    rng = np.random.default_rng(0)
    for _ in range(6):
        step = rng.normal(size=3) * 1e-3
        A0, A1, T = res.parameters * (1.0 + step)
        lam = discrete_objective(solver.Harmonic(A0, A1), with_period(res.physics, T), grid)[0]
        assert abs(lam) < abs(res.efficiency), step


def test_fourier_keeps_the_phase_and_beats_its_harmonic_start():
    physics = solver.Physics.from_scaled(2.0 ** -4, 2.0)
    A = np.array([[0.6, 0.8, 0.0, 0.0]])
    start = solver.Fourier(A, np.zeros((1, 3)))
    grid = FixedGrid.uniform(start, 128)
    first = objective_gradient(start, physics, grid)
    res = optimize_motion(start, physics, grid=grid, max_iterations=300)
    assert res.converged, res.stop_reason
    assert res.parameters[res.names.index("B1")] == 0.0
    assert abs(res.efficiency) > abs(first.efficiency)
    assert res.iterations <= 300


def test_power_law_respects_its_box():
    # at mu_n/mu_s = 2^-8 the best concave-down opening is steeper than linear: the opening
    # exponent ends on its bound 1 (box gamma >= 1), held there by an outward gradient
    physics = solver.Physics.from_scaled(2.0 ** -8, 2.0)
    start = solver.PowerLaw(1.0, 0.5, 0.3, 3.0, False, 3.0, False)
    res = optimize_motion(start, physics, grid=128)
    assert res.converged, res.stop_reason
    assert res.at_bounds == ("opening_exponent",)
    values = dict(zip(res.names, res.parameters))
    assert values["opening_exponent"] == 1.0
    assert 0.0 < values["duty_cycle"] < 1.0 and values["closing_exponent"] > 1.0
    assert values["A1"] > 0.0
    # |lambda| would grow below the bound: d|lambda|/d gamma_o < 0 there
    outward = np.sign(res.efficiency) * res.gradient[res.names.index("opening_exponent")]
    assert outward < 0 and abs(outward) > 1e3 * res.gradient_norm


def test_p_near_two_is_reported_not_chased():
    # lambda becomes invariant under T as p -> 2: the period runs to its bound, which is reported
    physics = solver.Physics.from_scaled(2.0 ** -4, 2.0, p=1.99)
    res = optimize_motion(solver.Harmonic(1.0, 0.5), physics, grid=128, max_iterations=100)
    assert res.ill_conditioned
    assert "period" in res.at_bounds
    assert res.iterations <= 100


def test_rejects_bad_start():
    physics = solver.Physics.from_scaled(1.0, 1.0)
    with pytest.raises(ValueError):
        optimize_motion(solver.Harmonic(1.0, 0.5), physics, start=[1.0, 0.5])


def test_speed_at_fixed_power_keeps_the_power_and_beats_the_start():
    physics = solver.Physics.from_scaled(2.0 ** -4, 2.0)
    start = solver.Harmonic(1.0, 0.5)
    grid = FixedGrid.uniform(start, 128)
    power = 0.8 * objective_gradient(start, physics, grid).P
    res = optimize_motion(start, physics, objective="speed_at_power", power=power, grid=grid)
    assert res.converged, res.stop_reason
    assert res.iterations <= 60 and res.gradient_evaluations <= 400
    np.testing.assert_allclose(res.P, power, rtol=1e-12)
    # the start moved onto the constraint (its own period root) is no faster
    on_constraint = speed_at_power(start, physics, grid, power)
    assert abs(res.U) > abs(on_constraint.value)
    assert res.value == res.U and np.isnan(res.gradient[-1])
    # no feasible neighbour is faster: |U| along P = power is maximal to second order
    for seed in range(2):
        v = np.random.default_rng(seed).normal(size=2) * 1e-3
        moved = solver.Harmonic(*(res.parameters[:2] + v))
        assert abs(speed_at_power(moved, res.physics, grid, power).value) <= abs(res.U)


def test_direction_negative_minimises_through_u_zero_or_keeps_the_start_sign():
    # the start moves forwards (U > 0): by default |lambda| grows with U > 0; with
    # direction=-1 lambda is minimised as in the paper, so it never ends above its start
    physics = solver.Physics.from_scaled(2.0 ** -4, 2.0)
    start = solver.Harmonic(0.2, 0.5)
    grid = FixedGrid.uniform(start, 128)
    first = objective_gradient(start, physics, grid).efficiency
    assert first > 0
    kept = optimize_motion(start, physics, grid=grid, max_iterations=100)
    assert kept.efficiency > first
    down = optimize_motion(start, physics, grid=grid, max_iterations=100, direction=-1)
    assert down.efficiency < first and down.iterations <= 100


class _WrongGradient:
    """f = x^2 + 1 with the gradient's sign flipped: no step along -g descends."""

    lower = np.array([-np.inf])
    upper = np.array([np.inf])
    solves = 0

    def solve(self, x, u0=None):
        self.solves += 1
        return float(x @ x) + 1.0, x.copy()

    def differentiate(self, x):
        return -2.0 * x, None


def test_a_direction_that_does_not_descend_fails_the_line_search():
    # halving or interpolating, the search must stop while x + alpha d still differs from
    # x: below that Armijo "holds" at f itself and the step would be taken as no progress
    from types import SimpleNamespace
    from solver.adjoint.optimize import State, optimizer_step
    x = np.array([1.0])
    state = State(x=x, f=2.0, g=np.array([-2.0]), hinv=np.eye(1),
                  result=SimpleNamespace(u0=0.0), first_gradient_norm=2.0)
    problem = _WrongGradient()
    out = optimizer_step(problem, state, max_step=0.5, newton_switch=0.0, max_condition=1e12)
    assert out.stop_reason == "line_search_failed"
    assert problem.solves <= 40


def test_a_stalled_bfgs_takes_a_newton_step_that_converges_quadratically():
    from solver.adjoint.optimize import Problem, initial_state, optimizer_step, variables
    from dataclasses import replace
    physics = solver.Physics.from_scaled(2.0 ** -4, 2.0)
    template = solver.Harmonic(1.0, 0.5)
    grid = FixedGrid.uniform(template, 128)
    best = optimize_motion(template, physics, grid=grid)
    names, full, free, lower, upper = variables(template, physics, best.parameters)
    problem = Problem(template, physics, grid, "efficiency", -1.0, free, full, lower[free],
                      upper[free])
    x_star = full[free].copy()
    x_star[-1] = np.log(full[-1])
    gnorms = []
    # (1e-3 off, the Hessian is already indefinite: the objective is stiff; measured
    # |g| -> 14 |g|^2 from 3e-3 down to 3e-6)
    for offset in (1e-5, 1e-6):
        state = initial_state(problem, x_star + offset * np.array([1.0, -0.5, 0.3]))
        gnorm = np.linalg.norm(state.g)
        # not stalled: a BFGS step (the first from the scaled identity)
        plain = optimizer_step(problem, state, max_step=0.5, newton_switch=np.inf, max_condition=1e12)
        assert plain.newton_steps == 0
        out = optimizer_step(problem, replace(state, stalled=True), max_step=0.5, newton_switch=np.inf,
                             max_condition=1e12)
        assert out.newton_steps == 1 and not out.stop_reason
        gnorms.append((gnorm, np.linalg.norm(out.g)))
    # quadratic: the gradient after the Newton step shrinks like the square of the one before
    (g1, n1), (g2, n2) = gnorms
    assert n1 < 1e-2 * g1 and n2 < 1e-3 * g2 and n2 < 50 * g2 ** 2
    assert np.log(n1 / n2) / np.log(g1 / g2) > 1.6


def test_a_failed_bfgs_step_close_to_the_optimum_asks_for_newton():
    from types import SimpleNamespace
    from solver.adjoint.optimize import State, optimizer_step
    state = State(x=np.array([1.0]), f=2.0, g=np.array([-2.0]), hinv=np.eye(1),
                  result=SimpleNamespace(u0=0.0), first_gradient_norm=2.0)
    out = optimizer_step(_WrongGradient(), state, max_step=0.5, newton_switch=np.inf, max_condition=1e12)
    assert out.stalled and not out.stop_reason and out.iteration == 0


def test_options_travel_as_one_bundle_and_keywords_still_work():
    """``OptimizerOptions`` holds the settings; a keyword of ``optimize_motion`` replaces its
    field (the pipeline's call keeps working), an unknown keyword is a TypeError, and the
    same settings either way give the same optimisation (bit for bit)."""
    from solver.adjoint.optimize import OptimizerOptions

    physics = solver.Physics.from_scaled(2.0 ** -4, 2.0)
    start = solver.Harmonic(1.0, 0.5)
    by_keyword = optimize_motion(start, physics, grid=64, gtol=1e-6, max_iterations=40,
                                 max_step=0.25)
    options = OptimizerOptions(gtol=1e-6, max_iterations=40, max_step=0.25)
    by_options = optimize_motion(start, physics, grid=64, options=options)
    overridden = optimize_motion(start, physics, grid=64,
                                 options=OptimizerOptions(gtol=1e-6, max_iterations=5),
                                 max_iterations=40, max_step=0.25)
    for res in (by_options, overridden):
        assert np.array_equal(res.parameters, by_keyword.parameters)
        assert (res.iterations, res.solves, res.stop_reason) == (
            by_keyword.iterations, by_keyword.solves, by_keyword.stop_reason)
    with pytest.raises(TypeError, match="gtool"):
        optimize_motion(start, physics, grid=64, gtool=1e-6)


class _Wall:
    """f = (x - 5)^2 with a jump of +100 from x = WALL on (exact gradient where smooth): a
    search from 0 toward 5 runs into the jump and can only creep up to it, in runs of steps
    each 10 times shorter than the run before (the line search's cuts by 0.1)."""

    WALL = 2.0 ** -0.5

    lower = np.array([-np.inf])
    upper = np.array([np.inf])

    def __init__(self):
        self.solves = 0

    def solve(self, x, u0=None):
        self.solves += 1
        return float((x[0] - 5.0) ** 2 + (100.0 if x[0] >= self.WALL else 0.0)), x.copy()

    def differentiate(self, x):
        return 2.0 * (x - 5.0), SimpleNamespace(u0=0.0)


def _walk(problem, creep_limit, steps=200):
    from solver.adjoint.optimize import State, optimizer_step
    state = State(x=np.array([0.0]), f=25.0, g=np.array([-10.0]), hinv=np.eye(1),
                  result=SimpleNamespace(u0=0.0), first_gradient_norm=10.0)
    for _ in range(steps):
        state = optimizer_step(problem, state, max_step=0.5, newton_switch=0.0,
                               max_condition=1e12, creep_limit=creep_limit)
        if state.stop_reason:
            break
    return state


def test_a_search_creeping_up_to_a_jump_stops_after_creep_limit_steps():
    """``creep_limit`` steps in a row accepted at below CREEP_FRACTION of their first trial end
    the step with the reason "creeping" (the optimiser then adapts the grid there), the last
    step taken; without the limit the same search creeps on until its line search fails."""
    limited, free = _Wall(), _Wall()
    stopped = _walk(limited, 3)
    assert stopped.stop_reason == "creeping" and stopped.creeping == 3
    assert _Wall.WALL - 5e-4 < stopped.x[0] < _Wall.WALL
    on = _walk(free, 0)
    assert on.stop_reason == "line_search_failed"
    assert on.iteration > stopped.iteration + 10 and free.solves > 2 * limited.solves


def test_the_optimum_is_solved_again_by_the_engine():
    """``engine_*`` are the final motion's outputs by the engine (its own steps, rtol
    ``CHECK_RTOL``) and ``grid_error`` the fixed grid's error against them.  On a grid re-adapted
    at the optimum (grid_rtol 1e-6, rounds until the steps stop changing) that error is within
    10 grid_rtol; on a coarse uniform fixed grid (24 steps: errors of ~1e-2 at this ratio, the
    control that must say no) it is far above, and it is exactly the two values' difference."""
    from solver.adjoint.optimize import CHECK_RTOL
    physics = solver.Physics.from_scaled(4.0, 2.0, p=0.0, delta=1e-5)
    start = solver.Fourier(np.array([[0.6, 0.4, 0.0, 0.0]]), np.zeros((1, 3)))
    fine = optimize_motion(start, physics, direction=-1, grid_rtol=1e-6, grid_rounds=5)
    coarse = optimize_motion(start, physics, direction=-1, grid=24)
    for res in (fine, coarse):
        assert res.converged
        ref = solver.solve_periodic(res.kinematics, res.physics, rtol=CHECK_RTOL)
        assert res.engine_efficiency == ref.efficiency[0] and res.engine_value == ref.efficiency[0]
        assert res.engine_U == ref.U[0] and res.engine_P == ref.P[0]
        assert res.grid_error == pytest.approx(
            abs(res.value - res.engine_value) / abs(res.engine_value), rel=1e-12)
    assert fine.grid_error <= 10 * 1e-6, fine.grid_error
    assert coarse.grid_error > 1e-3, coarse.grid_error


def _fourier_optima_start(index):
    """Start ``index`` of the shipped fourier_optima scene (seed 20190, 48 starts): (A_0, A_1)."""
    return np.random.default_rng(20190).uniform(0.0, 1.0, size=(48, 2))[index]


def test_an_optimum_the_frozen_steps_flatter_is_certified_on_finer_steps():
    """Issue 47, the Kmax 1 cell at mu_n/mu_s = 2^-8 (one optimum, two values): start 21 of
    fourier_optima stops ("no_progress", gradient 3e-7) at lambda/lambda_ub 0.234152 on the
    frozen steps adapted at rtol 1e-4, 0.233817 by the engine: grid error 1.4e-3, the search
    exploited the steps' error (measured on main).  Certified, it goes on on steps adapted at
    rtol 1e-5 to the optimum every other start reaches: the engine's value 0.2338204 (scipy BFGS
    on the engine's lambda at rtol 1e-8 from there: 0.23382040, docs/validation.md) with its
    grid error within 1e-4.  Without certification (certify_rounds 0: the control) the same
    start ends uncertified with the flattering grid value."""
    a0, a1 = _fourier_optima_start(21)
    physics = solver.Physics.from_scaled(2.0 ** -8, 2.0, p=0.0, delta=1e-5)
    start = solver.Fourier(np.array([[a0, a1]]), np.zeros((1, 1)))
    lam_ub = 1.0 / min(float(physics.mu_n[0]), float(physics.mu_s[0]))
    settings = dict(direction=-1, gtol=1e-7, max_iterations=300, grid_rtol=1e-4, grid_rounds=3)
    res = optimize_motion(start, physics, **settings)
    assert res.certified and res.grid_error <= 1e-4 and res.certify_rounds >= 1
    assert abs(res.engine_efficiency) / lam_ub == pytest.approx(0.23382040, rel=1e-6)
    assert res.cpu_seconds > 0
    raw = optimize_motion(start, physics, **settings, certify_rounds=0)
    assert not raw.certified and raw.grid_error > 1e-3 and raw.certify_rounds == 0
    assert abs(raw.efficiency) / lam_ub > 0.2341


def test_a_fixed_grid_is_reported_not_certified():
    """Certification re-adapts steps; on a fixed grid (24 uniform steps: grid error > 1e-3)
    there is none, and the optimum says it is not certified."""
    physics = solver.Physics.from_scaled(4.0, 2.0, p=0.0, delta=1e-5)
    start = solver.Fourier(np.array([[0.6, 0.4, 0.0, 0.0]]), np.zeros((1, 3)))
    coarse = optimize_motion(start, physics, direction=-1, grid=24)
    assert coarse.grid_error > 1e-3 and not coarse.certified and coarse.certify_rounds == 0


def test_the_coarse_stage_switches_at_its_gradient_norm_and_ends_certified():
    """``fidelity``: the descent starts on steps 100x coarser and leaves them once the gradient
    norm is below ``fidelity_gtol``; it counts its steps, and the end is certified as without
    it, at the same optimum (the Kmax 1 cell above has one)."""
    a0, a1 = _fourier_optima_start(0)
    physics = solver.Physics.from_scaled(2.0 ** -8, 2.0, p=0.0, delta=1e-5)
    start = solver.Fourier(np.array([[a0, a1]]), np.zeros((1, 1)))
    settings = dict(direction=-1, gtol=1e-7, max_iterations=300, grid_rtol=1e-4, grid_rounds=3)
    plain = optimize_motion(start, physics, **settings)
    coarse = optimize_motion(start, physics, **settings, fidelity=100.0, fidelity_gtol=1e-2)
    assert plain.coarse_iterations == 0 and 0 < coarse.coarse_iterations < coarse.iterations
    assert coarse.certified and coarse.converged
    assert coarse.engine_efficiency == pytest.approx(plain.engine_efficiency, rel=1e-6)


def test_a_value_at_rounding_level_is_certified_against_the_floor():
    """Isotropic friction at p = 1: lambda ~ 1e-35, noise; its relative grid error is ~1 and
    certifies nothing (force_laws: 96 of 864 starts uncertified for that alone, ratio 1, p 1).
    Against ``certify_floor`` (the pipeline's 1e-6 lambda_ub) it is certified; without the floor
    (the control) it is not."""
    physics = solver.Physics.from_scaled(1.0, 2.0, p=1.0, delta=1e-5)
    start = solver.Fourier(np.array([[0.6, 0.4]]), np.zeros((1, 1)))
    settings = dict(direction=-1, gtol=1e-7, max_iterations=60, grid_rtol=1e-4, certify_rounds=0)
    bare = optimize_motion(start, physics, **settings)
    assert abs(bare.engine_efficiency) < 1e-20 and not bare.certified
    floored = optimize_motion(start, physics, **settings, certify_floor=1e-6)
    assert floored.certified and floored.grid_error == bare.grid_error


def test_an_end_that_is_no_candidate_is_judged_but_not_searched_again():
    """``certify_gradient_norm``: start 3 of the Kmax 1 cell at 2^-8 ends ill-conditioned with a
    gradient norm of 0.03 and a grid error of 2e-4 (measured): no optimum the pipeline would keep
    (its acceptance: gradient norm <= 1e-5), so with that bound it is judged uncertified and not
    searched again; without it (the control) certification takes it on to the optimum."""
    a0, a1 = _fourier_optima_start(3)
    physics = solver.Physics.from_scaled(2.0 ** -8, 2.0, p=0.0, delta=1e-5)
    start = solver.Fourier(np.array([[a0, a1]]), np.zeros((1, 1)))
    settings = dict(direction=-1, gtol=1e-7, max_iterations=300, grid_rtol=1e-4, grid_rounds=3)
    gated = optimize_motion(start, physics, **settings, certify_gradient_norm=1e-5)
    assert gated.certify_rounds == 0 and not gated.certified and gated.gradient_norm > 1e-5
    full = optimize_motion(start, physics, **settings)
    assert full.certify_rounds >= 1 and full.certified and full.converged
