"""Adjoint gradients of the discretised problem against central differences of the same problem.

The discretisation is the order-5 engine's 3-stage Radau IIA on a fixed grid (uniform, or
the step sequence of the engine's converged solve).  The differences are taken on the same
FixedGrid (which moves with tau0 for the power law), with nonlinear tolerances at rounding
level, along random directions, and Richardson-extrapolated (steps eps and eps/2) so that
their own error (~1e-10) is far below the asserted 1e-6.
"""
import dataclasses
import math

import mpmath as mp
import numpy as np
import pytest

import solver
from solver.periodic import driver as periodic_driver
from solver.model.physics import PointPhysics
from solver.periodic.radau import RADAU5_C
from solver.adjoint.gradient import (POWER_ROOT_RTOL, FixedGrid, adaptive_grid, discrete_objective,
                              discrete_solution,
                              family_parameters, force_partials, force_partials_quadrature,
                              objective_gradient,
                              speed_at_power, with_family_parameters, with_period)

MU_N, MU_S = 0.3, 1.7


def _hard_inputs(rng, n):
    """(u, phi, omega): kink inside the link, apex at rest (c = 0), tiny and large omega."""
    out = []
    for k in range(n):
        phi = rng.uniform(-1.0, 4.0)
        omega = rng.normal() * [1e-6, 1e-2, 1.0, 10.0][k % 4]
        u = rng.normal() * [1e-6, 1e-2, 1.0][k % 3]
        if k % 5 == 0:
            u = -omega * math.sin(phi) / 4 + 1e-7 * rng.normal()  # c ~ 0: kink at s = 0
        if k % 3 == 1:
            s_kink = rng.uniform(0.02, 0.48)  # v_n = 0 at an interior point of the link
            u = (omega * s_kink - omega * math.sin(phi) ** 2 / 4) / math.sin(phi)
        out.append((u, phi, omega))
    return out


# -- the partial derivatives of F and Pi -------------------------------------------------------


@pytest.mark.parametrize("p", [0.0, 0.5, 1.0, 1.5])
@pytest.mark.parametrize("delta_tau", [1e-2, 1e-5, 1e-9])
def test_force_partials_match_the_graded_quadrature(p, delta_tau):
    # every entry of force_partials (closed-form link moments, as force_and_slope's) against
    # force_partials_quadrature (graded Gauss-Legendre over the link, no closed forms)
    rng = np.random.default_rng(int(10 * p) + int(-math.log10(delta_tau)))
    for u, phi, omega in _hard_inputs(rng, 60):
        P = force_partials(u, phi, omega, MU_N, MU_S, p, delta_tau)
        Q = force_partials_quadrature(u, phi, omega, MU_N, MU_S, p, delta_tau)
        F, dF = solver.force_and_slope(u, phi, omega, MU_N, MU_S, p, delta_tau)
        force_scale = MU_N * abs(math.sin(phi)) + MU_S * abs(math.cos(phi))
        assert abs(P[0] - Q[0]) <= 1e-11 * (abs(Q[0]) + force_scale), (u, phi, omega)
        assert abs(P[1] - Q[1]) <= 1e-10 * abs(Q[1]) + 1e-12 * force_scale, (u, phi, omega)
        assert abs(P[5] - Q[5]) <= 1e-11 * abs(Q[5]) + 1e-300, (u, phi, omega)
        # and force_partials is the force kernel's F and dF/du
        assert abs(P[0] - F) <= 1e-12 * (abs(F) + force_scale), (u, phi, omega)
        assert abs(P[1] - dF) <= 1e-11 * abs(dF) + 1e-13 * force_scale, (u, phi, omega)


def _richardson(fun, x, k, step):
    def central(h):
        xp, xm = list(x), list(x)
        xp[k] += h
        xm[k] -= h
        return (fun(*xp) - fun(*xm)) / (2 * h)
    return (4 * central(step / 2) - central(step)) / 3


def _force_and_power(u, phi, omega, mu_n, mu_s, p, dtau):
    return np.array([solver.force_and_slope(u, phi, omega, mu_n, mu_s, p, dtau)[0],
                     solver.power_density(u, phi, omega, mu_n, mu_s, p, dtau)])


@pytest.mark.parametrize("p", [0.0, 0.5, 1.5])
def test_force_partials_match_differences(p):
    # phi, omega and delta_tau derivatives against differences of force_and_slope / power_density
    rng = np.random.default_rng(3)
    dtau = 1e-2
    for _ in range(40):
        u, phi, omega = rng.normal(), rng.uniform(-1, 4), 3 * rng.normal()
        x = [u, phi, omega, MU_N, MU_S, p, dtau]
        P = force_partials(*x)
        e = math.hypot(math.cos(phi) * (u + omega * math.sin(phi) / 4), dtau)
        scale = np.array([MU_N + MU_S, abs(P[5]) + 1e-300])
        for k, cols in ((1, (2, 7)), (2, (3, 8)), (6, (4, 9))):
            step = 1e-3 * (dtau if k == 6 else min(e, 1.0))
            fd = _richardson(_force_and_power, x, k, step)
            # the differences' own error: truncation ~ (step/e)^4, rounding ~ 1e-16 / step
            tol = 1e-7 * (np.abs(fd) + scale) + 1e-14 * scale / step
            assert np.all(np.abs(P[list(cols)] - fd) <= tol), (x, k, P[list(cols)], fd)


def _reference_partials(u, phi, omega, mu_n, mu_s, p, dtau, index):
    """2 int_0^{1/2} of the differentiated integrand by mpmath, split around the kink (20 digits)."""
    with mp.workdps(20):
        return _reference_partials_mp(u, phi, omega, mu_n, mu_s, p, dtau, index)


def _reference_partials_mp(u, phi, omega, mu_n, mu_s, p, dtau, index):
    u, phi, omega, mu_n, mu_s, p, dtau = map(mp.mpf, (u, phi, omega, mu_n, mu_s, p, dtau))
    S, C = mp.sin(phi), mp.cos(phi)
    a = -u * S - omega * S * S / 4
    c = C * (u + omega * S / 4)
    if index == 2:  # d/dphi
        c_v = -S * u + omega * (C * C - S * S) / 4
        w_v_of = lambda s: -u * C - omega * S * C / 2
        N_v_of = lambda w, w_v: mu_n * (C * w + S * w_v) - mu_s * (-S * c + C * c_v)
    else:  # d/domega
        c_v = C * S / 4
        w_v_of = lambda s: s - S * S / 4
        N_v_of = lambda w, w_v: mu_n * S * w_v - mu_s * C * c_v

    def integrand(s):
        w = a + omega * s
        w_v = w_v_of(s)
        r2 = w * w + c * c + dtau * dtau
        g0 = r2 ** ((p - 1) / 2)
        g1 = (p - 1) * g0 / r2
        N = mu_n * S * w - mu_s * C * c
        return N_v_of(w, w_v) * g0 + N * g1 * (w * w_v + c * c_v)

    pts = [mp.mpf(0), mp.mpf(1) / 2]
    if omega != 0 and 0 < -a / omega < pts[1]:
        k = -a / omega
        eta = mp.sqrt(c * c + dtau * dtau) / abs(omega)
        inner = [x for x in (k - 10 * eta, k - eta, k, k + eta, k + 10 * eta) if 0 < x < pts[1]]
        pts = sorted(set(pts + inner))
    return (float(2 * mp.quad(integrand, pts)),
            float(2 * mp.quad(lambda s: abs(integrand(s)), pts)))


def test_force_partials_match_high_precision_reference():
    # the near-singular cases: Coulomb friction, tiny delta, kink inside the link
    rng = np.random.default_rng(11)
    for u, phi, omega in _hard_inputs(rng, 6):
        for dtau in (1e-5, 1e-9):
            P = force_partials(u, phi, omega, MU_N, MU_S, 0.0, dtau)
            for index in (2, 3):  # F_phi, F_omega
                ref, size = _reference_partials(u, phi, omega, MU_N, MU_S, 0.0, dtau, index)
                # relative to the integral of |integrand| (the quantity itself can cancel), and
                # at u ~ 0 F_omega vanishes pointwise (F is homogeneous of degree 0 in (u, omega)
                # at p = 0): there against its natural scale mu / |omega|
                natural = (MU_N + MU_S) * (1.0 if index == 2 else 1.0 / (abs(omega) + abs(u)))
                assert abs(P[index] - ref) <= 1e-11 * (abs(ref) + size) + 1e-15 * natural, (
                    u, phi, omega, dtau)


@pytest.mark.parametrize("p", [0.0, 0.5, 1.0, 1.5, 1.9])
def test_closed_form_partials_match_quadrature(p):
    # force_partials (closed forms; omega by homogeneity) against the graded quadrature,
    # on the hard inputs, where both the closed forms and the omega fallback are taken
    rng = np.random.default_rng(int(10 * p))
    fallbacks = 0
    for dtau in (1e-2, 1e-5, 1e-9):
        for u, phi, omega in _hard_inputs(rng, 200):
            P = force_partials(u, phi, omega, MU_N, MU_S, p, dtau)
            Q = force_partials_quadrature(u, phi, omega, MU_N, MU_S, p, dtau)
            fallbacks += P[3] == Q[3]
            e = math.hypot(math.cos(phi) * (u + omega * math.sin(phi) / 4), dtau)
            speed = abs(omega) + abs(u) + dtau
            # natural scales: mu for F, F_phi; mu / e for F_u (the kink's slope); / speed for
            # the omega partials (degree-0 homogeneity at p = 0); |Pi| for the power columns
            force = (MU_N + MU_S) * np.array([1.0, 1.0 / e, 1.0, 1.0 / speed, 1.0 / e])
            power = (abs(Q[5]) + 1e-300) * np.array([1.0, 1.0 / e, 1.0, 1.0 / speed, 1.0 / e])
            scale = np.concatenate([force, power])
            assert np.all(np.abs(P - Q) <= 1e-11 * (np.abs(Q) + scale)), (u, phi, omega, dtau)
    assert 0 < fallbacks < 600  # both branches of the omega partials are exercised


def test_partials_at_rest_apex_without_regularisation():
    # c = 0 and delta_tau = 0 (p > 0): e is floored, the quadrature fallback must not divide by 0
    phi, omega = 0.6845872936468235, 1.3
    u = -0.25 * omega * math.sin(phi)
    P = force_partials(u, phi, omega, MU_N, MU_S, 1.5, 0.0)
    assert np.all(np.isfinite(P))
    assert np.all(np.isfinite(force_partials_quadrature(u, phi, omega, MU_N, MU_S, 1.5, 0.0)))


# -- gradients of the discretised objective ------------------------------------------------------


def _clapping():
    # phi passes through 0 (min ~ -1.0, max ~ 1.6): the halves clap and reverse
    return solver.Fourier([[0.3, 1.1, 0.0, 0.2]], [[0.0, -0.1, 0.05]])


def _sticking():
    # closing down:10 / opening up:10 at mu_n/mu_s = 2^-8: long phases with T^2 dF/du ~ 1e6
    return solver.PowerLaw(1.0, 0.5, 0.3, 10.0, False, 10.0, True)


GRADIENT_CASES = {
    "harmonic": (lambda: solver.Harmonic(1.2, 0.4), -4),
    "power_law": (lambda: solver.PowerLaw(1.0, 0.5, 0.3, 3.0, False, 2.0, True), 2),
    "fourier_clapping": (_clapping, -3),
}


def _extrapolated_slope(J, eps):
    """J'(0) from central differences with steps eps and eps/2, Richardson-extrapolated."""
    d1 = (J(eps) - J(-eps)) / (2 * eps)
    d2 = (J(eps / 2) - J(-eps / 2)) / eps
    return (4 * d2 - d1) / 3


def directional_check(kinematics, physics, grid, *, objective="efficiency", seed=0, eps=1e-4):
    """(adjoint, Richardson central difference) along a random, parameter-scaled direction."""
    res = objective_gradient(kinematics, physics, grid, objective=objective)
    assert res.status == 0
    _, x = family_parameters(kinematics)
    full = np.append(x, physics.period[0])
    rng = np.random.default_rng(seed)
    v = rng.normal(size=full.size) * np.maximum(np.abs(full), 0.1)
    v /= np.linalg.norm(v)

    def J(step):
        y = full + step * v
        return discrete_objective(with_family_parameters(kinematics, y[:-1]),
                                  with_period(physics, y[-1]), grid, objective=objective,
                                  u0=res.u0)[0]

    return float(res.gradient @ v), _extrapolated_slope(J, eps)


@pytest.mark.parametrize("p", [0.0, 0.5, 1.5])
@pytest.mark.parametrize("case", sorted(GRADIENT_CASES))
def test_gradient_matches_central_differences(case, p):
    make, ratio_log2 = GRADIENT_CASES[case]
    kinematics = make()
    physics = solver.Physics.from_scaled(2.0 ** ratio_log2, 2.0, p=p)
    grid = FixedGrid.uniform(kinematics, 64)
    # the clapping case sticks at p = 0 (delta_tau 2e-5): its curvature changes over
    # parameter steps of 1e-4 (the Richardson differences there were 3e-5 off in A3, exact
    # at 1e-5), so its differences take the smaller step
    eps = 1e-5 if (case, p) == ("fourier_clapping", 0.0) else 1e-4
    for seed in range(2):
        adjoint, fd = directional_check(kinematics, physics, grid, seed=seed, eps=eps)
        assert abs(adjoint - fd) <= 1e-6 * abs(fd), (adjoint, fd)


def test_gradient_sticking_case_on_the_adaptive_grid():
    kinematics, physics = _sticking(), solver.Physics.from_scaled(2.0 ** -8, 2.0)
    # the engine's step sequence: nonuniform fractions in both phases, state events as nodes
    grid = adaptive_grid(kinematics, physics, rtol=1e-5)
    # it does stick: the friction rate T^2 dF/du is ~1e6 over a long part of the period
    sol = discrete_solution(kinematics, physics, grid)
    u, phi, omega = sol.stages[2::3], sol.stage_kinematics[0, 2::3], sol.stage_kinematics[1, 2::3]
    rate = np.array([solver.force_and_slope(a, b, c, physics.mu_n[0], physics.mu_s[0], 0.0,
                                            physics.delta_tau[0])[1]
                     for a, b, c in zip(u, phi, omega)]) * physics.inertia_factor[0]
    h = np.diff(grid.nodes(kinematics))
    assert h[np.abs(rate) > 1e5].sum() > 0.2
    for seed in range(3):
        adjoint, fd = directional_check(kinematics, physics, grid, seed=seed)
        assert abs(adjoint - fd) <= 1e-6 * abs(fd), (adjoint, fd)


@pytest.mark.parametrize("objective", ["speed", "power"])
def test_gradient_of_speed_and_power(objective):
    kinematics = _clapping()
    physics = solver.Physics.from_scaled(2.0 ** 3, 1.0, p=0.5)
    grid = FixedGrid.uniform(kinematics, 64)
    adjoint, fd = directional_check(kinematics, physics, grid, objective=objective, seed=5)
    assert abs(adjoint - fd) <= 1e-6 * abs(fd), (adjoint, fd)


def test_clapping_case_passes_through_zero():
    phi = _clapping().angle(np.linspace(0, 1, 1001))[0]
    assert phi.min() < -0.5 and phi.max() > 0.5


def test_fixed_grid_moves_with_duty_cycle():
    kinematics = _sticking()
    grid = FixedGrid.uniform(kinematics, 64)
    nodes = grid.nodes(kinematics)
    np.testing.assert_allclose(nodes, solver.period_grid(kinematics, 64)[0], rtol=0, atol=1e-15)
    moved = with_family_parameters(kinematics, [1.0, 0.5, 0.4, 10.0, 10.0])
    new = grid.nodes(moved)
    assert new.size == nodes.size and 0.4 in new


def _engine_fixed_grid(kinematics, physics, nodes, rtol=1e-13):
    """The order-5 engine's own fixed-grid solve (``fixed_grid_point``) on ``nodes``."""
    code, params = kinematics.kernel_encoding()
    phys = PointPhysics(physics.inertia_factor[0], physics.mu_n[0], physics.mu_s[0],
                        physics.p[0], physics.delta_tau[0])
    return periodic_driver.fixed_grid_point(code, params[0], nodes, phys, rtol,
                                          solver.kinematic_speed(kinematics)[0],
                                          solver.fast_limit_velocity(kinematics, physics)[0],
                                          solver.periodic.checked_options(None))


@pytest.mark.parametrize("case", ["fourier_clapping", "power_law"])
def test_discrete_objective_matches_the_solver_on_one_grid(case):
    # the same discretisation as the engine's fixed-grid solve, so the gradient is of the
    # solver's numbers: on a uniform grid and on the engine's own adaptive step sequence
    make, ratio_log2 = GRADIENT_CASES[case]
    kinematics, physics = make(), solver.Physics.from_scaled(2.0 ** ratio_log2, 2.0)
    for grid in (FixedGrid.uniform(kinematics, 64), adaptive_grid(kinematics, physics)):
        nodes = grid.nodes(kinematics)
        iu, ip, st = _engine_fixed_grid(kinematics, physics, nodes)
        res = objective_gradient(kinematics, physics, grid)
        assert st == 0 and res.status == 0
        np.testing.assert_allclose(res.U, iu / physics.period[0], rtol=1e-12)
        np.testing.assert_allclose(res.P, ip * physics.period[0] ** -1.0, rtol=1e-12)
    # ... and the adaptive grid is the engine's converged solve: its integrals agree with it
    # to its nonlinear tolerances (1e-3 rtol of V)
    out = periodic_driver.solve(kinematics, physics, 1e-6, 2 ** 17, False)
    assert out["n_tau"][0] == grid.n_steps
    np.testing.assert_allclose(res.U * physics.period[0], out["int_u"][0], rtol=1e-7)


def test_with_period_checks_the_period_and_keeps_the_rest():
    physics = solver.Physics.from_scaled(2.0 ** -4, 1.5, p=0.5, delta=1e-4)
    moved = with_period(physics, 3.0)
    assert moved.period.tolist() == [3.0]
    for name in ("mu_n", "mu_s", "p", "delta"):
        assert getattr(moved, name).tolist() == getattr(physics, name).tolist()
    assert moved.inertia_factor[0] == 3.0 ** 1.5
    for bad in (0.0, -1.0, math.nan, math.inf, [1.0, 2.0]):
        with pytest.raises(ValueError, match="period"):
            with_period(physics, bad)
    moved.mu_n[0] = 7.0  # its own arrays: the source is untouched
    assert physics.mu_n[0] != 7.0


def test_gradient_from_a_stored_solution_uses_its_stage_kinematics():
    # the optimiser's line search solves first and differentiates only the accepted point;
    # the adjoint then takes phi and dphi/dtau at the stages from the stored solution
    kinematics = solver.Harmonic(1.2, 0.4)
    physics = solver.Physics.from_scaled(2.0 ** -4, 1.5)
    grid = FixedGrid.uniform(kinematics, 128)
    stored = discrete_solution(kinematics, physics, grid)
    nodes = grid.nodes(kinematics)
    h = np.diff(nodes)
    t = (nodes[:-1, None] + RADAU5_C[None, :] * h[:, None]).ravel()  # the 3 stages of each step
    assert stored.stages.shape == (3 * 128,) and stored.stage_kinematics.shape == (4, 3 * 128)
    np.testing.assert_allclose(stored.stage_kinematics[0], 1.2 + 0.4 * np.cos(2 * np.pi * t),
                               rtol=0, atol=1e-14)
    np.testing.assert_allclose(stored.stage_kinematics[1],
                               -0.4 * 2 * np.pi * np.sin(2 * np.pi * t), rtol=0, atol=1e-13)
    phi = stored.stage_kinematics[0]
    np.testing.assert_allclose(stored.stage_kinematics[2], np.sin(phi), rtol=0, atol=1e-15)
    np.testing.assert_allclose(stored.stage_kinematics[3], np.cos(phi), rtol=0, atol=1e-15)
    again = objective_gradient(kinematics, physics, grid, solution=stored)
    fresh = objective_gradient(kinematics, physics, grid)
    np.testing.assert_array_equal(again.gradient, fresh.gradient)
    assert stored.outputs() == (fresh.U, fresh.P, fresh.efficiency)
    # a solution stored with phi and dphi/dtau only (the layout before sin and cos were kept)
    two_rows = dataclasses.replace(stored, stage_kinematics=stored.stage_kinematics[:2].copy())
    older = objective_gradient(kinematics, physics, grid, solution=two_rows)
    np.testing.assert_allclose(older.gradient, fresh.gradient, rtol=1e-13, atol=0.0)


# -- U at fixed P: the gradient along the constraint ---------------------------------------------


def constrained_check(kinematics, physics, grid, power, *, seed=0, eps=1e-4):
    """(adjoint along P = power, Richardson central difference of U(theta, T(theta)))."""
    res = speed_at_power(kinematics, physics, grid, power)
    assert res.status == 0
    _, x = family_parameters(kinematics)
    rng = np.random.default_rng(seed)
    v = rng.normal(size=x.size) * np.maximum(np.abs(x), 0.1)
    v /= np.linalg.norm(v)
    start = with_period(physics, res.period)

    def J(step):
        # every difference point solves its own period root (to rounding) from the optimum's
        return speed_at_power(with_family_parameters(kinematics, x + step * v), start, grid,
                              power, u0=res.u0).value

    return float(res.gradient @ v), _extrapolated_slope(J, eps), res


@pytest.mark.parametrize("p", [0.0, 0.5, 1.5])
@pytest.mark.parametrize("case", sorted(GRADIENT_CASES))
def test_speed_at_power_gradient_matches_central_differences(case, p):
    make, ratio_log2 = GRADIENT_CASES[case]
    kinematics = make()
    physics = solver.Physics.from_scaled(2.0 ** ratio_log2, 2.0, p=p)
    grid = FixedGrid.uniform(kinematics, 64)
    # a target 30% above the start's power: the root has to move the period
    power = 1.3 * objective_gradient(kinematics, physics, grid).P
    # (the clapping case sticks at p = 0: see test_gradient_matches_central_differences)
    eps = 1e-5 if (case, p) == ("fourier_clapping", 0.0) else 1e-4
    adjoint, fd, res = constrained_check(kinematics, physics, grid, power, seed=1, eps=eps)
    assert abs(adjoint - fd) <= 1e-6 * abs(fd), (adjoint, fd)
    assert abs(res.at.P / power - 1.0) <= 10 * POWER_ROOT_RTOL
    assert res.period != physics.period[0] and res.root_iterations >= 1


def test_speed_at_power_gradient_is_tangent_to_the_constraint():
    """Moving theta by eps v and T by eps dT, dT = -(P_theta . v) / P_T, keeps P to first order
    (its change shrinks like eps^2, measured by re-solving) and changes U at the rate g . v
    (g the constrained gradient, against a central difference along that path)."""
    kinematics, physics = _clapping(), solver.Physics.from_scaled(2.0 ** 3, 1.0, p=0.5)
    grid = FixedGrid.uniform(kinematics, 64)
    res = speed_at_power(kinematics, physics, grid, objective_gradient(kinematics, physics, grid).P)
    at = res.at
    _, x = family_parameters(kinematics)
    rng = np.random.default_rng(2)
    v = rng.normal(size=x.size) * np.maximum(np.abs(x), 0.1)
    v /= np.linalg.norm(v)
    T = float(physics.period[0])
    dT = -(at.grad_P[:x.size] @ v) / at.grad_P[x.size]

    def solve(eps):
        _, U, P, _, status, _ = discrete_objective(
            with_family_parameters(kinematics, x + eps * v), with_period(physics, T + eps * dT),
            grid, u0=at.u0)
        assert status == 0
        return U, P

    U0, P0 = solve(0.0)
    eps = 1e-3
    drift = [abs(solve(e)[1] - P0) / P0 for e in (eps, eps / 2)]
    free_drift = abs(discrete_objective(with_family_parameters(kinematics, x + eps * v), physics,
                                        grid, u0=at.u0)[2] - P0) / P0
    assert drift[0] < 1e-2 * free_drift, (drift, free_drift)  # the first-order change is gone
    assert 3.0 < drift[0] / drift[1] < 5.0, drift  # what is left is second order
    slope = _extrapolated_slope(lambda e: solve(e)[0], 1e-4)
    assert abs(res.gradient @ v - slope) <= 1e-6 * abs(slope), (res.gradient @ v, slope)


def test_speed_at_power_rejects_bad_target():
    kinematics, physics = _clapping(), solver.Physics.from_scaled(1.0, 1.0)
    with pytest.raises(ValueError):
        speed_at_power(kinematics, physics, FixedGrid.uniform(kinematics, 64), 0.0)
