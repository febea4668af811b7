"""Both periodic solvers: order of accuracy, mutual agreement, the paper's invariances and limits."""
import math

import numpy as np
import pytest

import solver
from references import reference
from cases import AGREEMENT_CASES, Case

#: the march's order here; the engine's (5) is tests/test_radau5.py's
METHOD_ORDERS = {"march": 2}


ORDER_CASES = [
    Case("harmonic_p1", solver.Harmonic(1.2, 0.3), solver.Physics(1.0, 0.0625, 1.0, 1.0, 0.0)),
    Case("harmonic_p0", solver.Harmonic(1.2, 0.3), solver.Physics(1.0, 0.0625, 1.0, 0.0, 1e-1)),
    Case("powerlaw_corners_p0", solver.PowerLaw(1.0, 0.4, 0.3, 3.0, False, 3.0, True),
         solver.Physics(1.0, 0.25, 1.0, 0.0, 1e-1)),
    Case("powerlaw_corners_p1.5", solver.PowerLaw(1.0, 0.4, 0.3, 3.0, False, 3.0, True),
         solver.Physics(1.0, 0.25, 1.0, 1.5, 1e-2)),
]


@pytest.mark.parametrize("method", ["march"])
@pytest.mark.parametrize("case", ORDER_CASES, ids=lambda c: c.name)
def test_order_of_accuracy(case, method):
    """Slope of log(error) against log(N) (diffrax-style order test)."""
    grids = [128, 256, 512, 1024]
    ref_u, ref_p, st = solver.solve_fixed_grid(case.kinematics, case.physics, grids[-1] * 32, method=method)
    assert st[0] == 0
    errors = []
    for n in grids:
        mean_u, mean_pi, st = solver.solve_fixed_grid(case.kinematics, case.physics, n, method=method)
        assert st[0] == 0
        errors.append(abs(mean_u[0] - ref_u[0]) + abs(mean_pi[0] - ref_p[0]))
    slope = -np.polyfit(np.log(grids), np.log(errors), 1)[0]
    assert abs(slope - METHOD_ORDERS[method]) < 0.5, (slope, errors)


@pytest.mark.parametrize("case", AGREEMENT_CASES, ids=lambda c: c.name)
def test_methods_agree_within_rtol(case):
    rtol = 1e-5
    a = solver.solve_periodic(case.kinematics, case.physics, method="periodic", rtol=rtol)
    b = solver.solve_periodic(case.kinematics, case.physics, method="march", rtol=rtol)
    assert a.converged[0], solver.STATUS_REASONS[int(a.status[0])]
    if case.stiff and not b.converged[0]:
        assert np.isnan(b.U[0])  # a failing march says so, never returns a number
        return
    assert b.converged[0], solver.STATUS_REASONS[int(b.status[0])]
    scale_u = max(abs(a.U[0]), solver._solve.U_FLOOR_FRACTION * solver.kinematic_speed(case.kinematics)[0] / case.physics.period[0])
    # each is within rtol of the truth (estimated), so they agree within 2 rtol
    assert abs(a.U[0] - b.U[0]) <= 2 * rtol * scale_u
    assert abs(a.P[0] - b.P[0]) <= 2 * rtol * a.P[0]


@pytest.mark.parametrize("rtol", [1e-3, 1e-5])
@pytest.mark.parametrize("case", AGREEMENT_CASES, ids=lambda c: c.name)
def test_error_estimate_is_honest_against_a_fine_reference(case, rtol):
    """The returned estimate bounds the true error, in the solver's norm (max of U's error
    relative to max(|U T|, 1e-3 V) and P's relative error), and is below rtol.  Reference:
    the former order-3 engine at rtol 1e-9 (``tests/references.py``; its own error, <= 1e-9,
    is 1e-4 of the smallest compared; the methods' agreement is
    ``test_methods_agree_within_rtol``'s)."""
    res = solver.solve_periodic(case.kinematics, case.physics, rtol=rtol)
    ref = reference(case.kinematics, case.physics)
    assert res.converged[0] and ref.converged[0]
    T = case.physics.period[0]
    scale_u = max(abs(ref.U[0]) * T, 1e-3 * solver.kinematic_speed(case.kinematics)[0])
    error = max(abs(res.U[0] - ref.U[0]) * T / scale_u, abs(res.P[0] - ref.P[0]) / ref.P[0])
    assert error <= res.error_estimate[0] + 2e-9, (error, res.error_estimate[0])
    assert res.error_estimate[0] <= rtol


def test_reflection_flips_U():
    """phi -> pi - phi reverses the motion: U -> -U, P unchanged."""
    A = np.array([[1.1, 0.5, 0.1, -0.05]])
    B = np.array([[0.0, 0.2, 0.03]])
    phys = solver.Physics.from_scaled(2.0 ** -3, 1.5)
    a = solver.solve_periodic(solver.Fourier(A, B), phys, rtol=1e-7)
    mirrored = np.concatenate([np.pi - A[:, :1], -A[:, 1:]], axis=1)
    b = solver.solve_periodic(solver.Fourier(mirrored, -B), phys, rtol=1e-7)
    np.testing.assert_allclose(b.U, -a.U, rtol=1e-6)
    np.testing.assert_allclose(b.P, a.P, rtol=1e-6)


@pytest.mark.parametrize("p", [0.0, 0.5, 1.5])
def test_depends_on_T_and_mu_only_through_T_power_mu(p):
    """u(tau) depends on (T, mu_n, mu_s) only through T^(2-p) mu_n, T^(2-p) mu_s (delta_tau fixed)."""
    kin = solver.Harmonic([1.0, 1.0], [0.5, 0.5])
    T = np.array([1.0, 2.7])
    factor = T ** (2 - p)
    phys = solver.Physics(period=T, mu_n=0.3 / factor, mu_s=1.1 / factor, p=p, delta=1e-4 / T)
    res = solver.solve_periodic(kin, phys, rtol=1e-7)
    np.testing.assert_allclose(res.mean_u[1], res.mean_u[0], rtol=1e-6)
    # P = T^-(p+1) int Pi, and Pi is proportional to mu ~ T^-(2-p): P T^3 is invariant
    np.testing.assert_allclose(res.P[1] * T[1] ** 3, res.P[0] * T[0] ** 3, rtol=1e-6)


@pytest.mark.parametrize("p", [0.0, 1.0, 1.5])
def test_scaled_quantities_depend_only_on_ratio_and_scaled_period(p):
    kin = solver.Harmonic([1.2] * 3, [0.4] * 3)
    scales = np.array([0.05, 1.0, 7.0])  # sqrt(mu_n mu_s)
    T, mu_n, mu_s = solver.physical_from_scaled(2.0 ** -2, 1.7, p, scales)
    phys = solver.Physics(period=T, mu_n=mu_n, mu_s=mu_s, p=p, delta=1e-6 / T)  # same delta_tau
    res = solver.solve_periodic(kin, phys, rtol=1e-7)
    for name in ("scaled_speed", "scaled_power", "scaled_efficiency", "relative_efficiency"):
        values = getattr(res, name)
        np.testing.assert_allclose(values, values[1], rtol=1e-5, err_msg=name)
    ratio, scaled_period = solver.scaled_from_physical(T, mu_n, mu_s, p)
    np.testing.assert_allclose(ratio, 0.25)
    np.testing.assert_allclose(scaled_period, 1.7)


def test_relative_efficiency_below_one_as_delta_vanishes():
    rng = np.random.default_rng(3)
    n = 24
    kin = solver.PowerLaw(rng.uniform(0.2, 1.5, n), rng.uniform(0.05, 0.6, n), rng.uniform(0.05, 0.95, n),
                          rng.choice([1.0, 3.0, 10.0], n), rng.random(n) < 0.5,
                          rng.choice([1.0, 3.0, 10.0], n), rng.random(n) < 0.5)
    phys = solver.Physics.from_scaled(2.0 ** rng.uniform(-8, 8, n), 2.0 ** rng.uniform(-2, 3, n),
                                      p=rng.choice([0.0, 0.5, 1.5], n), delta=1e-8)
    res = solver.solve_periodic(kin, phys, rtol=1e-4)
    ok = res.converged
    assert ok.mean() > 0.9
    assert np.all(np.abs(res.relative_efficiency[ok]) <= 1.0)


def test_isotropic_linear_law_does_not_move():
    kin = solver.Fourier([[0.9, 0.5, 0.1]], [[0.0, 0.3]])
    res = solver.solve_periodic(kin, solver.Physics(1.3, 0.7, 0.7, p=1.0, delta=0.0), rtol=1e-8)
    assert res.converged[0]
    assert abs(res.U[0]) <= 1e-9 * solver.kinematic_speed(kin)[0]
    # U = 0: the estimate is P's, and refinement must follow P's changes (marking by u's
    # rounding noise once split 19,541 steps and left the one holding P's error)
    assert res.n_tau[0] < 2 ** 13


def test_slow_limit_is_quasi_static_and_does_not_move():
    """T -> infinity: u(tau) -> the quasi-static solution u_qs, whose mean is 0, so U T -> 0.
    With u' = kappa F(u, tau), kappa = T^(2-p), the first correction is u_qs' / (kappa F_u):
    |U T| falls like kappa^-1, i.e. like Ts^-(2-p) = Ts^-1.5 here."""
    kin = solver.Harmonic(1.0, 0.5)
    tau = np.linspace(0, 1, 64, endpoint=False)
    scaled_periods = np.array([4.0, 16.0, 64.0])
    ratios, means = [], []
    for Ts in scaled_periods:
        phys = solver.Physics.from_scaled(2.0 ** -3, Ts, p=0.5, delta=1e-7 / Ts)
        res = solver.solve_periodic(kin, phys, rtol=1e-6, return_series=True)
        u_qs = solver.quasi_static_velocity(kin, phys, res.tau[0])[0]
        ratios.append(np.max(np.abs(res.u[0] - u_qs)) / np.max(np.abs(u_qs)))
        means.append(abs(res.mean_u[0]))
    assert ratios[0] > ratios[1] > ratios[2]
    assert ratios[2] < 0.05
    assert means[0] > means[1] > means[2]
    slope = -np.polyfit(np.log(scaled_periods), np.log(means), 1)[0]
    assert 1.1 < slope < 1.9, (slope, means)
    u_qs = solver.quasi_static_velocity(kin, phys, tau)[0]
    assert abs(u_qs.mean()) < 1e-3 * np.abs(u_qs).max()  # the quasi-static motion has U = 0


def test_fast_limit_is_constant_velocity_with_zero_mean_force():
    kin = solver.PowerLaw(1.0, 0.5, 0.25, 1.0, False, 1.0, False)
    spreads = []
    for Ts in (2.0 ** -3, 2.0 ** -5, 2.0 ** -7):
        phys = solver.Physics.from_scaled(2.0 ** -2, Ts, p=0.0, delta=1e-3)
        res = solver.solve_periodic(kin, phys, rtol=1e-6, return_series=True)
        u_fast = solver.fast_limit_velocity(kin, phys)[0]
        spreads.append(np.max(np.abs(res.u[0] - u_fast)) / abs(u_fast))
    assert spreads[0] > spreads[1] > spreads[2]
    assert spreads[2] < 1e-2


def test_power_is_positive_for_any_moving_motion():
    rng = np.random.default_rng(5)
    n = 16
    A = rng.normal(size=(n, 4)) * 0.5
    B = rng.normal(size=(n, 3)) * 0.5
    phys = solver.Physics.from_scaled(2.0 ** rng.uniform(-6, 6, n), 2.0 ** rng.uniform(-2, 2, n),
                                      p=rng.choice([0.0, 0.5, 1.0, 1.5], n))
    res = solver.solve_periodic(solver.Fourier(A, B), phys, rtol=1e-4)
    assert np.all(res.P[res.converged] > 0)
    assert res.converged.mean() > 0.9


def test_constant_angle_is_reported_not_divided_by_zero():
    res = solver.solve_periodic(solver.Harmonic([1.0, 1.0], [0.0, 0.3]), solver.Physics(1.0, 1.0, 2.0))
    assert res.status[0] == 7 and res.U[0] == 0 and np.isnan(res.efficiency[0])
    assert res.converged[1]


def test_bad_arguments_name_themselves():
    with pytest.raises(ValueError, match="mu_n"):
        solver.Physics(1.0, -1.0, 1.0)
    with pytest.raises(ValueError, match="p"):
        solver.Physics(1.0, 1.0, 1.0, p=2.0)
    with pytest.raises(ValueError, match="duty_cycle"):
        solver.PowerLaw(1.0, 0.3, 1.2, 1.0, False, 1.0, False)
    with pytest.raises(ValueError, match="method"):
        solver.solve_periodic(solver.Harmonic(1, 0.3), solver.Physics(1, 1, 1), method="rk4")


@pytest.mark.parametrize("name", ["power_law_corners_p1.5", "linear_two_phase", "clapping_fourier"])
def test_scipy_lsoda_baseline_agrees_on_every_family(name):
    """A third, independent method (scipy LSODA marching, ``solver.bench.baseline_point``,
    phi from the kinematics kernel) agrees with ``periodic`` on non-harmonic families."""
    from solver import bench

    case = {c.name: c for c in AGREEMENT_CASES}[name]
    kin, phys = case.kinematics, case.physics
    ref = reference(kin, phys)
    vscale = solver.kinematic_speed(kin)[0]
    U, P, periods, _ = bench.baseline_point(bench.family_angle(kin), phys.mu_n[0], phys.mu_s[0],
                                            phys.p[0], phys.period[0], phys.delta_tau[0], vscale,
                                            1e-8, 60.0)
    scale_u = max(abs(ref.U[0]), 1e-3 * vscale / phys.period[0])
    assert abs(U - ref.U[0]) <= 1e-5 * scale_u, (U, ref.U[0])
    assert abs(P - ref.P[0]) <= 1e-5 * ref.P[0]


def test_shooting_is_bracketed_where_the_period_map_is_not_monotone():
    """A short-period burst-and-coast point where Newton on u(0) cycled (NOT_PERIODIC on every
    grid) and, from a far start, ran off to u(0) ~ 1e23 and called it converged.  The shooting
    iteration keeps a bracket from the sign of g = Phi(u0) - u0 alone."""
    from solver._kinematics import period_grid
    from solver._periodic import solve_point_on_grid

    A0 = np.pi / 2
    kin = solver.PowerLaw([A0], [0.2 * A0], [0.5], [10.0], [True], [1.0], [False])
    phys = solver.Physics.from_scaled(2.0 ** -6, 0.125, p=0.0, delta=1e-5)
    a = solver.solve_periodic(kin, phys, rtol=1e-5)
    b = solver.solve_periodic(kin, phys, rtol=1e-5, method="march")
    assert a.converged[0] and b.converged[0]
    assert abs(a.U[0] - b.U[0]) <= 2e-5 * abs(a.U[0])
    code, params = kin.kernel_encoding()
    vscale = solver.kinematic_speed(kin)[0]
    work = [np.zeros(64) for _ in range(4)]
    mean_u, _, status = solver.solve_fixed_grid(kin, phys, 64)
    assert status[0] == 0
    u0s = []
    for start in (-0.5, -0.05, -0.02, 0.0, 0.05, 0.5, 3.0):
        out = solve_point_on_grid(code, params[0], period_grid(kin, 64)[0], 64, phys.inertia_factor[0],
                                  phys.mu_n[0], phys.mu_s[0], 0.0, phys.delta_tau[0], start, vscale, 1e-6,
                                  *work)
        # one fixed point, whatever the start: the same u(0) and int u as the default start's
        assert out[3] == 0, (start, out[:5])
        assert abs(out[0] - mean_u[0]) <= 1e-8 * vscale, (start, out[0], mean_u[0])
        u0s.append(out[2])
    assert np.ptp(u0s) <= 1e-8 * vscale, u0s


def test_bisection_guess_reproduces_the_collocation_quadratic():
    from solver._periodic import collocation_guess
    from solver._solve import bisect_all

    grid = np.array([0.0, 0.3, 1.0])
    quad = lambda t: 0.7 - 2.0 * t + 3.5 * t ** 2  # noqa: E731
    nodes = quad(grid[:-1])
    stages = quad(np.array([0.1, 0.3, 0.3 + 0.7 / 3, 1.0]))
    guess = np.empty(8)
    collocation_guess(bisect_all(grid), 4, grid, 2, nodes, stages, guess)
    fine = np.array([0.05, 0.15, 0.2, 0.3, 0.3 + 0.35 / 3, 0.65, 0.65 + 0.35 / 3, 1.0])
    assert np.allclose(guess, quad(fine), rtol=0, atol=1e-14)


def test_collocation_guess_reproduces_quadratics_across_grids():
    from solver._periodic import collocation_guess

    quad = lambda t: 0.7 - 2.0 * t + 3.5 * t ** 2  # noqa: E731
    old = np.array([0.0, 0.2, 0.45, 0.7, 1.0])
    h = np.diff(old)
    old_stages = quad(np.ravel(np.column_stack([old[:-1] + h / 3, old[1:]])))
    new = np.array([0.0, 0.1, 0.3, 0.33, 0.8, 1.0])
    guess = np.empty(10)
    collocation_guess(new, 5, old, 4, quad(old[:-1]), old_stages, guess)
    hn = np.diff(new)
    times = np.ravel(np.column_stack([new[:-1] + hn / 3, new[1:]]))
    assert np.allclose(guess, quad(times), rtol=0, atol=1e-14)


def test_paired_solves_match_independent_ones():
    """solve_pairs (the bisected grid started from its coarse partner) solves the same
    discrete problems as solve_points, to the nonlinear tolerance."""
    from solver._kinematics import period_grid
    from solver._periodic import solve_pairs, solve_points
    from solver._solve import bisect_all, pad_previous

    rng = np.random.default_rng(2)
    n = 24
    kin = solver.Harmonic(rng.uniform(0.2, 1.5, n), rng.uniform(0.05, 0.6, n))
    phys = solver.Physics.from_scaled(2.0 ** rng.uniform(-8, 8, n), 2.0 ** rng.uniform(-3, 3, n),
                                      p=0.0, delta=1e-5)
    code, params = kin.kernel_encoding()
    coarse = period_grid(kin, 48)
    rows = np.repeat(np.arange(n), 2)
    grids = np.ones((2 * n, 97))
    grids[0::2, :49] = coarse
    grids[1::2] = np.array([bisect_all(g) for g in coarse])
    steps = np.tile([48, 96], n)
    vscale = solver.kinematic_speed(kin)[rows]
    args = (code, params[rows], grids, steps, phys.inertia_factor[rows], phys.mu_n[rows],
            phys.mu_s[rows], phys.p[rows], phys.delta_tau[rows], np.zeros(2 * n), vscale, 1e-8)
    b = solve_points(*args)
    a = solve_pairs(*args, *pad_previous([None] * n))
    assert np.all(a[3] == 0) and np.all(b[3] == 0)
    assert np.allclose(a[0], b[0], rtol=0, atol=1e-9 * vscale.max())
    assert np.allclose(a[1], b[1], rtol=1e-9)
    # the coarse grids started from those solutions (another grid: the bisected one)
    previous = [(grids[2 * j + 1], a[8][2 * j + 1, :96], a[9][2 * j + 1, :192]) for j in range(n)]
    again = solve_pairs(*args, *pad_previous(previous))
    assert np.all(again[3] == 0)
    assert np.allclose(again[0], b[0], rtol=0, atol=1e-9 * vscale.max())
    assert np.allclose(again[1], b[1], rtol=1e-9)


def _polished_stages(u_n, U1, U2, h, phi1, om1, phi2, om2, kappa, mu_n, mu_s, p, dtau):
    """The Radau IIA stage equations solved to rounding by plain Newton in Python."""
    A = solver._periodic.RADAU_A
    U = np.array([U1, U2])
    for _ in range(30):
        (F1, d1), (F2, d2) = (solver.force_and_slope(U[0], phi1, om1, mu_n, mu_s, p, dtau),
                              solver.force_and_slope(U[1], phi2, om2, mu_n, mu_s, p, dtau))
        R = U - u_n - h * kappa * A @ np.array([F1, F2])
        J = np.eye(2) - h * kappa * A * np.array([d1, d2])
        U = U - np.linalg.solve(J, R)
    return U


def test_stage_newton_stops_within_its_tolerance():
    # the stage Newton may stop on the contraction estimate theta/(1 - theta)|dx| before a
    # step falls below atol: the stages it returns must still be within atol of the
    # solution of the stage equations, also where friction is stiff (h kappa |dF/du| ~ 1e6)
    from solver._periodic import radau_step
    rng = np.random.default_rng(3)
    worst = 0.0
    checked = 0
    for _ in range(300):
        u_n = rng.uniform(-1, 1)
        phi, omega = rng.uniform(-0.5, 2.0), rng.uniform(-6, 6)
        mu_n, mu_s = 2.0 ** rng.uniform(-8, 8), 1.0
        p = rng.choice([0.0, 0.5, 1.5])
        dtau = 10.0 ** rng.uniform(-8, -2)
        h, kappa = 10.0 ** rng.uniform(-4, -1), 10.0 ** rng.uniform(-1, 2)
        phi2 = phi + h * omega
        physics = (kappa, mu_n, mu_s, p, dtau)
        args = (h, np.sin(phi), np.cos(phi), omega, np.sin(phi2), np.cos(phi2), omega) + physics
        R1, R2, *_, ok_ref = radau_step(u_n, u_n, u_n, *args, 1e-15)
        if not ok_ref:
            continue
        ref = _polished_stages(u_n, R1, R2, h, phi, omega, phi2, omega, *physics)
        for atol in (1e-6, 1e-9, 1e-12):
            U1, U2, *_, ok = radau_step(u_n, u_n, u_n, *args, atol)
            assert ok
            worst = max(worst, abs(U1 - ref[0]) / atol, abs(U2 - ref[1]) / atol)
            checked += 1
    assert checked > 600
    assert worst <= 1.0, worst


def test_stage_newton_converges_at_a_singular_slope():
    """0 < p < 1 with delta = 0: at a corner of phi where omega -> 0 (exponent 3, concave up)
    and the body nearly at rest, F ~ -|u|^p sign u has an infinite slope at u = 0 and Newton
    flipped the stage's sign back and forth for 60 iterations: every grid up to 2048 steps
    failed (STAGE_SOLVE_FAILED), rtol 1e-3 ended on 8,196 steps and rtol 1e-6 failed.  The
    reference is a uniform grid of 2^16 steps (2^17 agrees to ~1e-9 of the norm)."""
    kin = solver.PowerLaw(0.51732343, 0.36901758, 0.34092877, 3.0, True, 2.0, False)
    phys = solver.Physics.from_scaled(2 ** -0.4, 2 ** 3.03, p=0.5, delta=0.0)
    mean_u, mean_pi, status = solver.solve_fixed_grid(kin, phys, 2 ** 16)
    assert status[0] == 0
    T = phys.period
    V = solver.kinematic_speed(kin)
    for rtol in (1e-3, 1e-6):
        r = solver.solve_periodic(kin, phys, rtol=rtol)
        assert r.status[0] == 0, rtol
        error_u = abs(r.U[0] - mean_u[0] / T[0]) * T[0] / max(abs(mean_u[0]), 1e-3 * V[0])
        error_p = abs(r.P[0] / (mean_pi[0] * T[0] ** -1.5) - 1.0)
        assert max(error_u, error_p) <= rtol, (rtol, error_u, error_p)
    assert solver.solve_periodic(kin, phys, rtol=1e-3).n_tau[0] <= 1000


def test_stage_newton_retries_from_rest_where_a_step_stops_the_body():
    """A burst-and-coast power law on 64 uniform steps: at the corner tau0 (omega from -8.75
    to ~0) the body stops within a step, and the stage Newton failed from the extrapolated
    collocation guess and from u_n alike (60 iterations each; STAGE_SOLVE_FAILED), while
    from rest it converges.  The solution must not depend on the nonlinear tolerance beyond
    it, and int Pi must equal the Radau rule over power_density at the returned stages."""
    from solver._gradient import FixedGrid, discrete_solution
    kin = solver.PowerLaw(1.2, 0.35, 0.8, 10.0, False, 3.0, True)
    phys = solver.Physics.from_scaled(2.0 ** -8, 2.0 ** 4, p=0.0, delta=1e-8)
    grid = FixedGrid.uniform(kin, 64)
    tight = discrete_solution(kin, phys, grid, rtol=1e-13)
    assert tight.status == 0
    loose = discrete_solution(kin, phys, grid, rtol=1e-4)
    assert loose.status == 0
    assert abs(loose.int_u - tight.int_u) <= 1e-7 * abs(tight.int_u)
    h = np.diff(tight.nodes)
    phi, omega = tight.stage_kinematics[0], tight.stage_kinematics[1]
    pi = [solver.power_density(u, a, w, phys.mu_n[0], phys.mu_s[0], 0.0, phys.delta_tau[0])
          for u, a, w in zip(tight.stages, phi, omega)]
    # (discrete_solution is the order-5 engine's 3-stage Radau IIA: weights RADAU5_B)
    from solver._radau5 import RADAU5_B
    pi = np.reshape(pi, (-1, 3))
    assert np.isclose(np.sum(h * (pi @ RADAU5_B)), tight.int_pi, rtol=1e-12, atol=0.0)


def test_stage_newton_at_an_infinite_slope_converges_to_the_roots():
    """radau_step at omega = 0 (F = -K |u|^p sign u, p = 0.5, delta = 0) from many starts,
    against the stage roots by nested brentq.  The first version of the flip cut accepted
    unconverged stages here (348 of 1064 cases the old Newton had solved, up to 6e7 atol off:
    it cut again after a cut step that had not flipped); the old Newton failed 470."""
    from scipy.optimize import brentq
    from solver._force import force_and_slope_sc
    from solver._periodic import radau_step
    S, C = math.sin(0.6), math.cos(0.6)
    mu_n, mu_s, p, dtau, kappa, atol = 2.0, 1.0, 0.5, 0.0, 1.0, 1e-10

    def force(u):
        return force_and_slope_sc(u, S, C, 0.0, mu_n, mu_s, p, dtau)[0]

    def roots(u_n, h):
        def first(U2):
            return brentq(lambda U1: U1 - u_n - h * (5 / 12 * force(U1) - force(U2) / 12),
                          -10.0, 10.0, xtol=1e-300, rtol=1e-15, maxiter=500)
        U2 = brentq(lambda U2: U2 - u_n - h * (0.75 * force(first(U2)) + 0.25 * force(U2)),
                    -10.0, 10.0, xtol=1e-300, rtol=1e-15, maxiter=500)
        return first(U2), U2

    cases = 0
    for h in (0.05, 1.0, 3.0):
        for u_n in (*np.geomspace(1e-8, 1.0, 7), *-np.geomspace(1e-8, 1.0, 7)):
            want = roots(u_n, h)
            for guess in (u_n, 0.3, -0.3, 1e-3, -1e-3):
                U1, U2, *_, ok = radau_step(u_n, guess, guess, h, S, C, 0.0, S, C, 0.0, kappa,
                                            mu_n, mu_s, p, dtau, atol)
                assert ok, (h, u_n, guess)
                assert max(abs(U1 - want[0]), abs(U2 - want[1])) <= 10 * atol, (h, u_n, guess)
                cases += 1
    assert cases == 210


@pytest.mark.parametrize("rtol", [1e-3, 1e-5])
def test_periodicity_tolerance_leaves_no_offset_in_int_u(rtol):
    """The shooting stops |u(0) - fixed point| <= 1e-3 rtol V away, a full rtol of int u's
    smallest norm 1e-3 V: the converged sweep is shifted by its pending Newton step, so on a
    fixed grid the loose and the tight iterations agree to O(offset^2).  Unshifted, this
    weakly contracting clapping point (M = 0.99) was 0.81 and 0.94 of rtol 1e-3 V off."""
    from solver._solve import solve_fixed_grid
    kin = solver.Fourier(A=[[-0.3549, 0.7815, 0.3671, -0.5895]], B=[[0.0, -0.3601, -0.3695]])
    phys = solver.Physics.from_scaled(1.324, 0.0568, p=0.0, delta=1e-5)
    V = solver.kinematic_speed(kin)[0]
    tight, _, status = solve_fixed_grid(kin, phys, 4096, rtol=1e-12)
    loose, _, status_loose = solve_fixed_grid(kin, phys, 4096, rtol=rtol)
    assert status[0] == 0 and status_loose[0] == 0
    assert abs(loose[0] - tight[0]) <= 0.05 * rtol * 1e-3 * V


def test_outputs_beyond_the_float_range_fail_loudly():
    """p = 1.99 and sqrt(mu_n mu_s) = 1e-2 put T at 1e200 (the scaling exponent is 1/(2-p) =
    100): P = T^-(p+1) int Pi underflows to 0 (1e2: overflows), which must not come back as a
    converged 0 or inf.  A large but representable scale keeps every scaled output."""
    from solver._status import OUT_OF_RANGE
    kin = solver.Harmonic(1.2, 0.3)
    unit = solver.solve_periodic(kin, solver.Physics.from_scaled(0.1, 1.0, p=1.99, delta=0.0),
                                 rtol=1e-6)
    assert unit.converged[0]
    for scale in (1e-2, 1e2):
        r = solver.solve_periodic(kin, solver.Physics.from_scaled(0.1, 1.0, p=1.99, delta=0.0,
                                                                  friction_scale=scale), rtol=1e-6)
        assert r.status[0] == OUT_OF_RANGE and not r.converged[0]
        for key in ("U", "P", "efficiency", "scaled_speed", "scaled_power", "scaled_efficiency",
                    "relative_efficiency"):
            assert np.isnan(getattr(r, key)[0]), key
    wide = solver.solve_periodic(kin, solver.Physics.from_scaled(0.1, 1.0, p=1.99, delta=0.0,
                                                                 friction_scale=0.5), rtol=1e-6)
    assert wide.converged[0]
    for key in ("scaled_speed", "scaled_power", "scaled_efficiency", "relative_efficiency"):
        np.testing.assert_allclose(getattr(wide, key), getattr(unit, key), rtol=1e-9, err_msg=key)


def test_step_floors_reach_around_the_corners():
    """CORNER_MIN_STEP on every step within CORNER_REACH of a corner (tau = 0 also at 1),
    MIN_STEP elsewhere: against the distances computed directly."""
    from solver._solve import CORNER_MIN_STEP, CORNER_REACH, MIN_STEP, step_floors

    rng = np.random.default_rng(3)
    corner = 0.4
    grid = np.unique(np.r_[0.0, rng.uniform(0, 1, 3000), corner, corner + 0.3 * CORNER_REACH,
                           1.0 - 2.0 * CORNER_REACH, 1.0])
    N = grid.size - 1
    floors = step_floors(grid, N, np.array([0.0, corner]))
    lo, hi = grid[:-1], grid[1:]
    distance = np.minimum.reduce([np.maximum.reduce([c - hi, lo - c, np.zeros(N)])
                                  for c in (0.0, corner, 1.0)])
    near = distance <= CORNER_REACH
    assert near.sum() >= 6 and (~near).sum() > 2900
    np.testing.assert_array_equal(floors, np.where(near, CORNER_MIN_STEP, MIN_STEP))
    assert np.all(step_floors(grid, N, np.zeros(0)) == MIN_STEP)  # smooth families


def test_long_period_power_law_with_singular_corners_converges():
    """Scaled period 67.8, closing and opening exponents 1.05 and 1.10 (omega ~ z^0.05 and
    z^0.1 at the corners):
    with the steps next to the corners held at MIN_STEP (2^-26) the estimate stayed at
    2.8e-6 from 11,000 to 219,000 steps and the solve failed at rtol 1e-6 (9 of 300 such
    points at 1e-6, 25 at 1e-8).  The corner steps may now be split to CORNER_MIN_STEP.
    The answer is checked against the scipy LSODA march (``solver.bench.baseline_point``,
    tol 1e-10), an independent method, which resolves U here to ~1e-7 in the solver's
    norm."""
    from solver import bench

    kin = solver.PowerLaw(1.0597919352438694, 0.49812427732542985, 0.3186763827140434,
                          1.0534083570390707, True, 1.104202936986926, False)
    phys = solver.Physics.from_scaled(13.46751615309997, 67.84639435833623, p=0.0, delta=1e-8)
    res = solver.solve_periodic(kin, phys, rtol=1e-6)
    assert res.converged[0], solver.STATUS_REASONS[int(res.status[0])]
    assert res.n_tau[0] < 50_000
    vscale = solver.kinematic_speed(kin)[0]
    U, P, _, _ = bench.baseline_point(bench.family_angle(kin), phys.mu_n[0], phys.mu_s[0], 0.0,
                                      phys.period[0], phys.delta_tau[0], vscale, 1e-10, 60.0)
    assert bench.relative_u_error(res.U[0], U, phys.period[0], vscale) <= 2e-6, (res.U[0], U)
    assert abs(res.P[0] - P) <= 2e-6 * P
