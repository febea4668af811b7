"""The turning-point check (``solver._turning``) and the node weights it uses."""
from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.integrate import quad

import solver
from references import reference
from solver._force import force_and_slope
from solver._kinematics import angle_and_rate, period_grid
from solver._periodic import radau_step, solve_point_on_grid
from solver._turning import grade_towards, step_defect, turning_point_estimates, window_width


def _stage_kinematics(code, params, grid):
    rows = []
    for n in range(grid.size - 1):
        t0, t1 = grid[n], grid[n + 1]
        mid = 0.5 * (t0 + t1)
        phi1, om1 = angle_and_rate(code, params, t0 + (t1 - t0) / 3.0, mid)
        phi2, om2 = angle_and_rate(code, params, t1, mid)
        rows.append((t1 - t0, math.sin(phi1), math.cos(phi1), om1, math.sin(phi2),
                     math.cos(phi2), om2))
    return rows


def _periodic_int_u_with_jump(rows, physics, node, jump, u0):
    """int u of the discrete periodic solution with u raised by ``jump`` at ``node``, by a
    shooting of our own (secant on u(0)) over ``radau_step``."""
    kappa, mu_n, mu_s, p, dtau = physics

    def sweep(start):
        u, total = start, 0.0
        for n, (h, s1, c1, o1, s2, c2, o2) in enumerate(rows):
            if n == node and n > 0:
                u += jump
            U1, U2, *_, ok = radau_step(u, u, u, h, s1, c1, o1, s2, c2, o2, kappa, mu_n, mu_s,
                                        p, dtau, 1e-15)
            assert ok
            total += h * (0.75 * U1 + 0.25 * U2)
            u = U2
        return u + (jump if node == 0 else 0.0), total

    a, b = u0, u0 + 1e-3
    ga, gb = sweep(a)[0] - a, sweep(b)[0] - b
    for _ in range(60):
        if gb == ga or abs(gb) < 1e-16:
            break
        a, b, ga = b, b - gb * (b - a) / (gb - ga), gb
        gb = sweep(b)[0] - b
    return sweep(b)[1]


@pytest.mark.parametrize("p,delta", [(0.5, 1e-3), (0.0, 1e-2)])
def test_node_weights_are_the_sensitivity_of_int_u_to_a_jump(p, delta):
    kin = solver.Harmonic(1.1, 0.6)
    phys = solver.Physics.from_scaled(0.3, 1.5, p=p, delta=delta)
    code, params = kin.kernel_encoding()
    grid = period_grid(kin, 32)[0]
    N = grid.size - 1
    physics = (phys.inertia_factor[0], phys.mu_n[0], phys.mu_s[0], phys.p[0], phys.delta_tau[0])
    out = [np.empty(N) for _ in range(5)]
    weights = np.empty(N)
    *_, u0, status, _, _ = solve_point_on_grid(code, params[0], grid, N, *physics, 0.0, 1.0, 1e-13,
                                               *out[:4], out[4].repeat(2), None, None, weights)
    assert status == 0
    rows = _stage_kinematics(code, params[0], grid)
    jump = 1e-6
    for node in (0, 5, 17, 31):
        up = _periodic_int_u_with_jump(rows, physics, node, jump, u0)
        down = _periodic_int_u_with_jump(rows, physics, node, -jump, u0)
        fd = (up - down) / (2 * jump)
        assert abs(weights[node] - fd) <= 1e-6 * abs(fd), (node, weights[node], fd)


def _step_integrals_by_quad(code, params, t0, t1, un, U1, U2, tz, physics, window):
    """(D_n, T^(2-p) int dF/du) along the step's collocation polynomial by adaptive quad."""
    kappa, mu_n, mu_s, p, dtau = physics
    h = t1 - t0

    def along(t, which):
        x = (t - t0) / h
        u = 3 * (x - 1 / 3) * (x - 1) * un - 4.5 * x * (x - 1) * U1 + 1.5 * x * (x - 1 / 3) * U2
        phi, om = angle_and_rate(code, params, t, t0 + 0.5 * h)
        return force_and_slope(u, phi, om, mu_n, mu_s, p, dtau)[which]

    points = [t for t in (tz - 10 * window, tz - window, tz, tz + window, tz + 10 * window)
              if t0 < t < t1]
    edges = [t0, *points, t1]
    force, slope = (sum(quad(along, a, b, args=(which,), limit=400, epsabs=1e-14,
                             epsrel=1e-10)[0] for a, b in zip(edges[:-1], edges[1:]))
                    for which in (0, 1))
    return (U2 - un) - kappa * force, kappa * slope


HARMONIC = solver.Harmonic(1.06, 0.54)
# omega = -2 pi (A1 sin x + 3 A3 sin 3x), x = 2 pi tau: with A3 = -A1 / 9 its zero at tau = 1/2
# is triple (omega ~ (tau - 1/2)^3), where the window is far wider than |u| / |omega'| says
TRIPLE_ZERO = solver.Fourier(np.array([[1.06, 0.54, 0.0, -0.06]]), np.zeros((1, 3)))


@pytest.mark.parametrize("kin,t0,t1,un,U1,U2", [
    (HARMONIC, 0.5 - 1 / 64, 0.5, 1e-3, 6e-4, 1e-9),        # the body stopped on the turning point
    (HARMONIC, 0.5 - 1 / 64, 0.5, 7e-4, 6.8e-4, 6.6e-4),    # passing it (window ~3e-5)
    (HARMONIC, 0.5 - 1 / 128, 0.5 + 1 / 128, -2e-4, 1e-6, 3e-4),  # the turning point inside
    (HARMONIC, 0.5, 0.5 + 1 / 32, 0.0, 2e-5, 8e-5),
    (HARMONIC, 0.5 - 1 / 64 - 1e-5, 0.5 - 1e-5, 1e-3, 6e-4, 1e-6),  # the zero beyond its end
    (TRIPLE_ZERO, 0.5 - 1 / 64, 0.5, 1e-5, 6e-6, 1e-9),
    (TRIPLE_ZERO, 0.5 - 1 / 128, 0.5 + 1 / 128, -1e-5, 1e-7, 2e-5),
])
def test_step_defect_resolves_the_window_at_a_turning_point(kin, t0, t1, un, U1, U2):
    phys = solver.Physics.from_scaled(0.119, 0.088, p=0.0, delta=1e-8)
    code, params = kin.kernel_encoding()
    physics = (phys.inertia_factor[0], phys.mu_n[0], phys.mu_s[0], phys.p[0], phys.delta_tau[0])
    x = (0.5 - t0) / (t1 - t0)
    u_z = 3 * (x - 1 / 3) * (x - 1) * un - 4.5 * x * (x - 1) * U1 + 1.5 * x * (x - 1 / 3) * U2
    window = window_width(code, params[0], 0.5, max(abs(u_z), physics[4]))
    got, log_factor, panels, _ = step_defect(code, params[0], t0, t1, un, U1, U2, 0.5, window,
                                          *physics, False)
    want, want_log_factor = _step_integrals_by_quad(code, params[0], t0, t1, un, U1, U2, 0.5,
                                                    physics, window)
    # relative to the trapped defect kappa mu h (or to D itself): the kinks of F in the window
    # (the zero of the link's velocity crossing its ends) inside a panel limit the Gauss rule
    # to ~1e-6 of kappa mu h at a simple zero, and to ~6e-4 of D at the triple zero
    scale = physics[0] * max(physics[1], physics[2]) * (t1 - t0)
    assert abs(got - want) <= 1e-5 * scale + 1e-3 * abs(want), (got, want)
    # the resolved factor m = exp(T^(2-p) int dF/du) enters lambda through 1 - M, so its
    # absolute error counts: measured 2e-5 relative at the simple zeros, and 1-3 % in the log
    # at the triple zero, where m ~ 1e-5 .. 1e-16
    m, want_m = math.exp(log_factor), math.exp(want_log_factor)
    assert abs(m - want_m) <= 1e-5 + 1e-4 * want_m, (m, want_m)
    assert panels <= 120
    # collocated: the stage Newton's residual R = U2 - u_n - kappa h (3 F(U1) + F(U2)) / 4 is
    # left out, so D - R is what remains (here the stages are arbitrary, R is large)
    mid = 0.5 * (t0 + t1)
    stage_forces = [force_and_slope(U, *angle_and_rate(code, params[0], t, mid), *physics[1:])[0]
                    for U, t in ((U1, t0 + (t1 - t0) / 3), (U2, t1))]
    residual = (U2 - un) - physics[0] * (t1 - t0) * (0.75 * stage_forces[0]
                                                     + 0.25 * stage_forces[1])
    quadrature_error = step_defect(code, params[0], t0, t1, un, U1, U2, 0.5, window, *physics,
                                   True)[0]
    assert abs(quadrature_error - (got - residual)) <= 1e-12 * max(abs(got), abs(residual))


def test_window_width_is_where_omega_reaches_the_level():
    code, params = HARMONIC.kernel_encoding()
    for level in (1e-9, 1e-4, 1e-1):
        w = window_width(code, params[0], 0.5, level)
        # omega = -2 pi A1 sin(2 pi tau): |omega(1/2 +- w)| = 2 pi A1 sin(2 pi w)
        assert abs(2 * math.pi * 0.54 * math.sin(2 * math.pi * w) - level) <= 0.03 * level
    code, params = TRIPLE_ZERO.kernel_encoding()
    w = window_width(code, params[0], 0.5, 1e-6)
    assert abs(abs(angle_and_rate(code, params[0], 0.5 + w, 0.5 + w / 2)[1]) - 1e-6) <= 0.05 * 1e-6
    assert w > 5e-4  # a simple zero's |u| / |omega'| would be ~1e-6 / 21


def test_grade_towards_adds_geometric_nodes_around_the_turning_point():
    grid = np.linspace(0.0, 1.0, 33)
    flagged = np.full((4, 3), np.nan)
    flagged[0] = (0.5, 1e-6, 1 / 32 + 1 / 32)
    flagged[1] = (0.0, 1e-5, 1 / 32)  # wraps around the period
    out = grade_towards(grid, flagged, 1e-9)
    assert out[0] == 0.0 and out[-1] == 1.0 and np.all(np.diff(out) > 1e-9)
    assert set(grid) <= set(out)
    steps = np.diff(out)
    near = np.abs(0.5 * (out[:-1] + out[1:]) - 0.5)
    # every step within reach is at most twice its distance to tau_z (or the target)
    within = near < 1 / 32
    assert np.all(steps[within] <= 2 * np.maximum(near[within], 1e-6) + 1e-15)
    assert steps.min() >= 1e-6 * (1 - 1e-9) and out[1] <= 1e-5 * (1 + 1e-9)
    assert 1 - out[-2] <= 1e-5 * (1 + 1e-9)
    assert np.array_equal(grade_towards(grid, np.full((4, 3), np.nan), 1e-9), grid)


def test_turning_point_estimate_sees_the_trap_and_not_a_resolved_solution():
    """The solution on a 64-step grid of the session-4 case is trapped (U off by ~50 %): the
    check sees a large error there and a small one on the adaptive grid of rtol 1e-5; both
    errors are measured against the march."""
    kin = solver.Harmonic(1.059879, 0.540691)
    phys = solver.Physics.from_scaled(0.119099, 0.088041, p=0.0, delta=1e-8)
    code, params = kin.kernel_encoding()
    physics = (phys.inertia_factor[0], phys.mu_n[0], phys.mu_s[0], phys.p[0], phys.delta_tau[0])
    V = solver.kinematic_speed(kin)[0]
    ref = solver.solve_periodic(kin, phys, method="march", rtol=1e-6)
    assert ref.status[0] == 0
    adaptive = solver.solve_periodic(kin, phys, rtol=1e-5, return_series=True)
    estimates = []
    for grid in (period_grid(kin, 64)[0], np.r_[adaptive.tau[0], 1.0]):
        N = grid.size - 1
        nodes, step_u, step_pi, step_m, weights, q = (np.empty(N) for _ in range(6))
        stages = np.empty(2 * N)
        int_u, *_, status, _, _ = solve_point_on_grid(code, params[0], grid, N, *physics, 0.0, V, 1e-10,
                                                      nodes, step_u, step_pi, step_m, stages, None,
                                                      None, weights, q)
        assert status == 0
        scale = max(abs(int_u), 1e-3 * V)
        estimate, flagged = turning_point_estimates(
            code, params, grid[None], np.array([N]), nodes[None], stages[None], step_m[None],
            q[None], *(np.array([x]) for x in physics), np.array([scale]), 1e-4, 1e-7, True,
            kin.corners())
        estimates.append((abs(int_u - ref.mean_u[0]) / scale, estimate[0],
                          np.isfinite(flagged[0, :, 0]).sum()))
    (trapped_error, trapped_estimate, trapped_flags), (error, estimate, flags) = estimates
    assert trapped_error > 0.3 and trapped_estimate > 1e-2 and trapped_flags >= 1
    assert error < 1e-5 and estimate < 1e-6 and flags == 0


# A clapping Fourier point with six turning points of phi, at each of which the solution
# passes at |u| 3.5e-7 .. 2.6e-5 (windows of 1.7e-9 .. 1.1e-7): the march's grids were
# trapped there (16 rtol off at rtol 1e-7, 20 at 1e-6) until it ran the check too.
CLAPPING_A = [-0.3549, 0.7815, 0.3671, -0.5895]
CLAPPING_B = [0.0, -0.3601, -0.3695]


def _clapping_point():
    kin = solver.Fourier(A=[CLAPPING_A], B=[CLAPPING_B])
    phys = solver.Physics.from_scaled(1.324, 0.0568, p=0.0, delta=1e-5)
    return kin, phys, solver.kinematic_speed(kin)[0]


def test_march_runs_the_turning_point_check():
    """The march at rtol 1e-6 against the periodic method at 1e-7 (1.05e-8 off an
    independent DOP853 reference with nodes graded into the windows)."""
    kin, phys, V = _clapping_point()
    ref = solver.solve_periodic(kin, phys, rtol=1e-7)
    march = solver.solve_periodic(kin, phys, method="march", rtol=1e-6)
    assert ref.status[0] == 0 and march.status[0] == 0
    scale = max(abs(ref.mean_u[0]), 1e-3 * V)
    assert abs(march.mean_u[0] - ref.mean_u[0]) / scale <= 1e-6


def test_rate_slope_bound_bounds_the_rate_of_omega():
    # the turning-point search skips a step whose end values of omega keep |omega| above
    # TANGENCY |u| given this bound on |omega'|: it must hold everywhere on the period
    from solver._turning import rate_slope_bound
    rng = np.random.default_rng(5)
    tau = np.linspace(0.0, 1.0, 20001)
    for K in (1, 3, 7):
        kin = solver.Fourier(rng.normal(0.0, 0.5, (1, K + 1)), rng.normal(0.0, 0.5, (1, K)))
        code, params = kin.kernel_encoding()
        omega = np.array([angle_and_rate(code, params[0], t, t)[1] for t in tau])
        steepest = np.max(np.abs(np.diff(omega)) / np.diff(tau))
        bound = rate_slope_bound(code, params[0])
        assert steepest <= bound
        assert steepest >= 0.2 * bound  # and not uselessly loose (random phases)
    pl = solver.PowerLaw(1.2, 0.35, 0.8, 1.5, False, 3.0, True)
    code, params = pl.kernel_encoding()
    assert rate_slope_bound(code, params[0]) == np.inf  # omega' unbounded at the corner


def test_stage_residual_is_not_counted_as_a_defect():
    """A corner of phi with exponent 20 on both sides is a turning point where the body rests
    (u_n 1e-56); the steps leaving it have node weights lambda ~ 9e18 (the linearised
    sensitivity explodes where the anisotropic law amplifies), and a defect of 1e-14, the stage
    Newton's own residual, gave an estimate of 7e8: refinement stopped after 2,156 steps with
    TOLERANCE_NOT_REACHED at rtol 1e-5 (found by a stress sweep).  Defects within the stage
    tolerance are not counted; the point then converges, honestly."""
    kin = solver.PowerLaw([2.1930766425058286], [0.3106065040016449], [0.7189580800698627],
                          [20.0], [True], [20.0], [False])
    phys = solver.Physics.from_scaled(73.23732052227966, 0.035042416335456184, p=0.0,
                                      delta=1e-10)
    ref = reference(kin, phys)
    assert ref.converged[0]
    scale = max(abs(ref.mean_u[0]), 1e-3 * solver.kinematic_speed(kin)[0])
    for rtol in (1e-5, 1e-6):
        res = solver.solve_periodic(kin, phys, rtol=rtol)
        assert res.converged[0], solver.STATUS_REASONS[int(res.status[0])]
        error = max(abs(res.mean_u[0] - ref.mean_u[0]) / scale, abs(res.P[0] - ref.P[0]) / ref.P[0])
        assert error <= rtol and error <= res.error_estimate[0], (rtol, error, res.error_estimate[0])


def test_flagging_stops_at_a_share_of_zero():
    """Shares 1e30, 1e14, 0: after the first two are flagged, the rounding of their sum
    (1.4e14 of it) is still over FLAG_REST rtol, and the step target of the share-0 row was
    divided by zero: ZeroDivisionError out of the compiled check (a long-period power law at
    anisotropy 229, delta 2e-9, rtol 1e-3, whose check estimated 1e30)."""
    from solver._turning import flag_rows
    shares = np.array([1e30, 1e14, 0.0])
    estimate = float(shares[0] + shares[1] + shares[2])
    rtol = 1e-3
    assert estimate - shares[0] - shares[1] > 0.25 * rtol  # the residue the test is about
    flagged = np.full((4, 3), np.nan)
    count = flag_rows(shares, estimate, np.array([0.1, 0.2, 0.3]), np.array([1e-3, 1e-3, 1e-3]),
                      np.array([2e-3, 2e-3, 2e-3]), rtol, 2.0 ** -36, flagged)
    assert count == 2
    assert np.all(np.isfinite(flagged[:2])) and np.all(flagged[:2, 1] > 0)


def test_layer_rows_grade_forward_only():
    """A negative target (a layer row) grades from tz forward only; a positive one on both
    sides, wrapping at the period's ends."""
    grid = np.linspace(0.0, 1.0, 9)
    forward = grade_towards(grid, np.array([[0.25, -1e-3, 0.1]]), 1e-12)
    both = grade_towards(grid, np.array([[0.25, 1e-3, 0.1]]), 1e-12)
    added_forward = np.setdiff1d(forward, grid)
    added_both = np.setdiff1d(both, grid)
    assert added_forward.size >= 6 and np.all(added_forward > 0.25)
    assert np.any(added_both < 0.25) and np.any(added_both > 0.25)
    np.testing.assert_allclose(np.sort(added_forward - 0.25), 1e-3 * 2.0 ** np.arange(
        added_forward.size))


def test_each_corner_keeps_its_own_layer_steps():
    """Two corners 2^-12 apart (duty cycle 2^-12), every step stiff (u = 0, T^(2-p) 1e12,
    delta_tau 1e-12): the steps after tau = 0 stop at tau0, which starts its own list.
    (Searched 64 steps on, tau = 0 took tau0's steps as its own, so a flagged tau0 layer was
    graded toward tau = 0, or not re-solved at all.)"""
    from solver._turning import LAYER_STEPS, corner_layers
    kin = solver.PowerLaw([1.0], [0.5], [2.0 ** -12], [2.0], [False], [2.0], [False])
    tau0 = kin.duty_cycle[0]
    grid = np.concatenate([np.linspace(0.0, tau0, 3), tau0 + 2.0 ** -13 * np.arange(1, 40),
                           [0.5, 1.0]])
    N = grid.size - 1
    code, params = kin.kernel_encoding()
    steps = np.empty(2 * LAYER_STEPS, dtype=np.int64)
    widths = np.empty(2 * LAYER_STEPS)
    first = np.empty(2 * LAYER_STEPS, dtype=np.bool_)
    count = corner_layers(code, params[0], grid, N, np.zeros(N), np.zeros(2 * N),
                          kin.corners()[0], 1e12, 1.0, 1.0, 0.0, 1e-12, steps, widths, first)
    assert list(steps[:count]) == [0, 1] + list(range(2, 2 + LAYER_STEPS))
    assert list(first[:count]) == [True, False, True] + [False] * (LAYER_STEPS - 1)


def test_corner_layer_error_against_an_independent_integration():
    """The step after tau0 of a long-period power law (scaled period 113, 512 steps, rate
    times h ~ 760): its error in int u from ``corner_layer_error`` (graded Radau sub-steps)
    against scipy's Radau at rtol 1e-12 from the same u_n, with the same node weight.  The
    error is ~13 rtol at rtol 1e-3 of the norm of int u (its floor 1e-3 V here): the layer
    the step misses."""
    from cases import radau_reference
    from solver._turning import corner_layer_error, layer_rate
    kin = solver.PowerLaw([0.5729944571272555], [0.009698383749602814], [0.4888715012712118],
                          [5.0], [False], [14.468630943676835], [False])
    phys = solver.Physics.from_scaled(0.16643930643694074, 112.84102281785694, p=0.0,
                                      delta=4.39375774699564e-10)
    code, params = kin.kernel_encoding()
    params = params[0]
    physics = tuple(float(x[0]) for x in (
        phys.inertia_factor, phys.mu_n, phys.mu_s, phys.p, phys.delta_tau))
    V = solver.kinematic_speed(kin)[0]
    grid = period_grid(kin, 512)[0]
    N = grid.size - 1
    nodes, step_u, step_pi, step_m, weights, q = (np.empty(N) for _ in range(6))
    stages = np.empty(2 * N)
    status = solve_point_on_grid(code, params, grid, N, *physics, 0.0, V, 1e-10, nodes, step_u,
                                 step_pi, step_m, stages, None, None, weights, q)[3]
    assert status == 0
    n = int(np.flatnonzero(np.abs(grid - kin.duty_cycle[0]) < 1e-14)[0])
    t0, t1 = grid[n], grid[n + 1]
    side = 0.5 * (t0 + t1)
    U1, U2 = stages[2 * n], stages[2 * n + 1]
    rate = layer_rate(code, params, t0, t1, nodes[n], U1, U2, *physics)
    assert rate * (t1 - t0) > 100
    estimate, end = corner_layer_error(code, params, t0, t1, nodes[n], U1, U2, 1.0 / rate,
                                       weights[n + 1], *physics, 1e-16)
    int_u, u_end = radau_reference(code, params, physics, t0, t1, nodes[n], side)
    true = int_u - (t1 - t0) * (0.75 * U1 + 0.25 * U2) + weights[n + 1] * (u_end - U2)
    assert abs(true) > 5e-3 * (1e-3 * V)  # (5 rtol at rtol 1e-3 of the floor 1e-3 V)
    assert abs(estimate - true) <= 0.02 * abs(true), (estimate, true)
    assert abs(end - u_end) <= 1e-6 * abs(u_end)
