"""Events of F along the solution (``solver._events``) and the error control that relies on them."""
import numpy as np
import pytest

import solver
from references import reference
from solver._events import event_times, place_events
from solver.bench import relative_u_error
from solver._solve import MAX_BISECTIONS, U_FLOOR_FRACTION, bisect, refinement_levels


def test_kinematic_event_located_to_rounding():
    """cos(phi) = 0 where A0 + A1 cos(2 pi tau) = pi/2: located exactly from any grid."""
    A0, A1 = 1.2, 0.6
    kin = solver.Harmonic([A0], [A1])
    code, params = kin.kernel_encoding()
    grid = np.linspace(0.0, 1.0, 41)[None, :]
    u = np.full((1, 40), 0.3)
    found = event_times(code, params, grid, np.array([40]), u, np.ones(1), np.ones(1),
                        np.ones(1), np.zeros(1), np.full(1, 1e-5), kin.corners())[0][0]
    exact = np.arccos((np.pi / 2 - A0) / A1) / (2 * np.pi)
    assert np.nanmin(np.abs(found - exact)) < 1e-12
    assert np.nanmin(np.abs(found - (1 - exact))) < 1e-12


def test_place_events_moves_near_nodes_and_keeps_corners():
    grid = np.array([0.0, 0.25, 0.5, 0.75, 1.0])
    corners = np.array([0.0, 0.5])
    out = place_events(grid, np.array([0.26, 0.49, 0.6, np.nan]), corners, 1e-9)
    assert 0.26 in out and 0.25 not in out          # moved: within a quarter step
    assert 0.5 in out and 0.49 in out               # a corner is never moved: inserted
    assert 0.6 in out and out.size == grid.size + 2
    assert np.all(np.diff(out) > 0)


def _true_errors(kin, phys, rtols):
    ref = reference(kin, phys)
    assert ref.converged.all()
    scale = np.maximum(np.abs(ref.mean_u), U_FLOOR_FRACTION * solver.kinematic_speed(kin))
    for rtol in rtols:
        res = solver.solve_periodic(kin, phys, rtol=rtol)
        assert res.converged.all()
        err = np.maximum(np.abs(res.mean_u - ref.mean_u) / scale, np.abs(res.P - ref.P) / ref.P)
        yield rtol, err, res.error_estimate


# A point where a corner of F sat in a blind spot of the step/bisection pair and the estimate
# accepted a grid whose error was 70x rtol (without events); and one where the stop right
# after the corner at tau = 0 was misplaced by the secant of the node values (24x rtol).
BLIND_SPOT_CASES = {
    "harmonic, kink leaves the link near a turning point": (
        solver.Harmonic([0.958], [0.649 * 0.958]),
        solver.Physics.from_scaled(2 ** -0.72, 0.414, p=0.0, delta=1e-5)),
    "power law, stop right after the corner at tau = 0": (
        solver.PowerLaw([1.1644793019715023], [0.8434785270895884], [0.46192329623999384],
                        [3.0], [False], [1.0], [False]),
        solver.Physics.from_scaled(2 ** 6.934710276918857, 2.513750234504831, p=0.0,
                                   delta=1e-5)),
}


@pytest.mark.parametrize("name", list(BLIND_SPOT_CASES))
def test_corner_events_keep_the_estimate_honest(name):
    kin, phys = BLIND_SPOT_CASES[name]
    for rtol, err, estimate in _true_errors(kin, phys, [1e-4, 1e-5, 1e-6]):
        assert err[0] <= rtol and err[0] <= estimate[0] + 1e-9, (rtol, err[0], estimate[0])


def test_place_events_never_leaves_a_step_below_the_gap():
    """Nearly coincident events (two event functions vanishing together) give one node."""
    grid = np.linspace(0.0, 1.0, 9)
    gap = 1e-7
    out = place_events(grid, np.array([0.3, 0.3 + 0.5 * gap, 0.251, 0.25 + 0.1 * gap]),
                       np.array([0.0, 0.5]), gap)
    assert np.all(np.diff(out) > gap)
    assert out[0] == 0.0 and out[-1] == 1.0 and 0.5 in out


def test_place_events_keeps_refinement_finer_than_the_gap():
    """Only an inserted node can be dropped for closeness: steps refined below the gap
    elsewhere in the grid survive an event placed far from them."""
    gap = 1e-7
    fine = 0.5 + 0.25 * gap * np.arange(1, 9)
    grid = np.concatenate([np.linspace(0.0, 0.5, 5), fine, [0.75, 1.0]])
    out = place_events(grid, np.array([0.26]), np.array([0.0, 0.25]), gap)
    assert np.all(np.isin(fine, out)) and 0.26 in out and out.size == grid.size + 1


def test_bisect_and_refinement_levels_match_their_definitions():
    rng = np.random.default_rng(4)
    grid = np.sort(np.concatenate([[0.0, 1.0], rng.uniform(0, 1, 30)]))
    h = np.diff(grid)
    levels = rng.integers(0, 4, h.size)
    out = bisect(grid, levels)
    expected = np.concatenate([np.linspace(a, b, 2 ** k, endpoint=False)
                               for a, b, k in zip(grid[:-1], grid[1:], levels)] + [[1.0]])
    assert np.allclose(out, expected, rtol=0, atol=1e-15) and out.size == expected.size
    # over its share 0.5 rtol h: ceil(log2(ratio) / order) bisections, at most MAX_BISECTIONS
    rtol, order = 1e-4, 3
    indicators = 0.5 * rtol * h * 10.0 ** rng.uniform(-2, 6, h.size)
    ratio = indicators / (0.5 * rtol * h)
    want = np.where(ratio > 1, np.minimum(np.ceil(np.log2(ratio) / order), MAX_BISECTIONS), 0)
    assert np.array_equal(refinement_levels(indicators, h, rtol, order), want)
    # none over its share: the largest indicators holding half the total, once (Doerfler)
    small = 0.1 * 0.5 * rtol * h * rng.uniform(0, 1, h.size)
    marked = refinement_levels(small, h, rtol, order)
    top = np.argsort(-small)
    count = np.searchsorted(np.cumsum(small[top]), 0.5 * small.sum()) + 1
    assert set(np.flatnonzero(marked)) == set(top[:count]) and marked.max() == 1


def test_a_stop_between_shared_nodes_is_not_hidden_from_the_estimate():
    """A stop (u decelerating to rest, then sticking) at tau 0.0096 sat inside a step at the
    same 2.5e-4 from a node of the grid and of its bisection: both lost the same triangle of
    u before it, and rtol 1e-5 was accepted 3.7 rtol off with an estimate of 0.32 rtol (its
    int u agreed with scipy's Radau at tol 1e-11 to 1e-9 where the grids resolve the stop,
    as at rtol 1e-8 here)."""
    kin = solver.PowerLaw(1.0064810055487958, 0.13924241292100864, 0.17119305099346455,
                          10.0, False, 3.0, True)
    phys = solver.Physics.from_scaled(0.0565007951085289, 4.8261221947868265, p=0.0,
                                      delta=1e-8)
    ref = reference(kin, phys)
    assert ref.status[0] == 0
    for rtol in (1e-4, 1e-5):
        res = solver.solve_periodic(kin, phys, rtol=rtol)
        assert res.status[0] == 0
        error = abs(res.mean_u[0] - ref.mean_u[0]) / abs(ref.mean_u[0])
        assert error <= rtol and error <= 2 * res.error_estimate[0]


def test_unresolved_events_weigh_the_jump_of_u_prime_by_the_squared_distance():
    """J d^2 / 2 per event off the nodes (J the change of T^(2-p) F over its step), none for
    an event within the gap of a node or on a row that is not checked."""
    from solver._events import unresolved_events
    from solver._force import force_and_slope
    kin = solver.Harmonic([1.0, 1.0], [0.4, 0.4])
    code, params = kin.kernel_encoding()
    grid = np.tile(np.linspace(0.0, 1.0, 9), (2, 1))
    u = np.tile(np.linspace(-0.1, 0.2, 8), (2, 1))
    events = np.full((2, 4), np.nan)
    events[:, 0] = 0.3      # in step [0.25, 0.375]: d = 0.05
    events[:, 1] = 0.5 + 1e-12  # on a node
    kappa, mu_n, mu_s, p, dtau = 2.0, 0.5, 1.0, 0.0, 1e-5
    estimate, steps = unresolved_events(
        code, params, grid, np.array([8, 0]), u, events, np.full((2, 4), -1),
        np.full(2, kappa), np.full(2, mu_n),
        np.full(2, mu_s), np.zeros(2), np.full(2, dtau), np.full(2, 0.5), 1e-9,
        np.zeros((0, 0)), np.zeros((0, 0)), 1e-12, False)
    phi0, phi1 = kin.angle(np.array([0.25, 0.375]))[0]
    om = -2 * np.pi * 0.4 * np.sin(2 * np.pi * np.array([0.25, 0.375]))
    F0 = force_and_slope(u[0, 2], phi0, om[0], mu_n, mu_s, p, dtau)[0]
    F1 = force_and_slope(u[0, 3], phi1, om[1], mu_n, mu_s, p, dtau)[0]
    assert np.isclose(estimate[0], 0.5 * kappa * abs(F1 - F0) * 0.05 ** 2 / 0.5, rtol=1e-12)
    assert list(steps[0]) == [2, -1, -1, -1] and estimate[1] == 0 and np.all(steps[1] == -1)


@pytest.mark.parametrize("A0,A1,ratio,scaled_period,rtol", [
    (0.5145897604110815, 0.27657883466906485, 202.24583056219387, 0.26835620019215956, 1e-5),
    (1.1333585399822783, 1.054069901106421, 97.92991888688162, 0.4221571958585374, 1e-4),
])
def test_a_corner_of_u_prime_at_a_stale_node_is_not_hidden_from_the_estimate(
        A0, A1, ratio, scaled_period, rtol):
    """Where g = u + omega S / 4 crosses zero u'' jumps; that event sat 2.8e-4 (1.8e-4) past a
    node placed from an older pass, both stages of the step past it in G and in B(G): both
    lost the same J2 d^2 / 2, and these were accepted 3.69 (1.48) rtol off with estimates of
    0.64 (0.52) rtol (the rtol 1e-9 reference agrees with scipy's Radau at 1e-12 to 1e-10)."""
    kin = solver.Harmonic([A0], [A1])
    phys = solver.Physics.from_scaled(ratio, scaled_period, p=0.0, delta=1e-5)
    ref = reference(kin, phys)
    res = solver.solve_periodic(kin, phys, rtol=rtol)
    assert ref.status[0] == 0 and res.status[0] == 0
    scale = max(abs(ref.mean_u[0]), U_FLOOR_FRACTION * solver.kinematic_speed(kin)[0])
    error = abs(res.mean_u[0] - ref.mean_u[0]) / scale
    assert error <= rtol and error <= res.error_estimate[0], (error, res.error_estimate[0])


def test_a_stop_that_keeps_the_sign_of_g_is_found():
    """During a dwell of phi (omega ~ 0) u decelerates to rest and sticks at g ~ -5e-15, on the
    slipping side: g never changes sign, so no event was found, and the stop sat 4.6e-4 from a
    node shared by the grid and its bisection; rtol 1e-4 was accepted 7.4 rtol off with an
    estimate of 0.04.  Steps whose g ends in the friction's band are probed for the stop."""
    kin = solver.PowerLaw(A0=1.11706477, A1=0.07002536, duty_cycle=0.17588923,
                          closing_exponent=10.0, closing_concave_up=False, opening_exponent=3.0,
                          opening_concave_up=True)
    phys = solver.Physics(period=4.86911806, mu_n=0.18494962, mu_s=5.40687788, p=0.0,
                          delta=1e-8)
    ref = reference(kin, phys)
    res = solver.solve_periodic(kin, phys, rtol=1e-4)
    assert ref.status[0] == 0 and res.status[0] == 0
    assert abs(res.mean_u[0] - ref.mean_u[0]) / abs(ref.mean_u[0]) <= 1e-4


# mu_n/mu_s 3,020, scaled period 56: u slides to a stop from 4.2 at a deceleration of ~390
# per unit tau, and the stuck force range (up to mu_n) is far wider than that
SPURIOUS_STOP_CASE = (
    solver.PowerLaw([1.8500986326845215], [1.2483753329829477], [0.2919403621941638],
                    [6.321938411908913], [False], [3.0930357998761355], [True]),
    solver.Physics.from_scaled(3019.633740089039, 56.29317468157276, p=0.0, delta=1e-5))


def test_misplaced_stop_error_against_an_independent_integration():
    """On 256 steps (uniform in each phase) a stage sticks on a spurious root 3 steps before
    the stop: the nodes cross zero in step 9, u's extrapolation in step 12, where
    ``_locate`` now puts the event.  ``misplaced_stop_error`` (the steps re-solved in 8
    sub-steps each) against scipy's Radau at rtol 1e-12 from the same u, with the same node
    weight."""
    from cases import radau_reference
    from solver._events import misplaced_stop_error
    from solver._kinematics import period_grid
    from solver._periodic import solve_point_on_grid
    kin, phys = SPURIOUS_STOP_CASE
    code, params = kin.kernel_encoding()
    physics = tuple(float(x[0]) for x in (
        phys.inertia_factor, phys.mu_n, phys.mu_s, phys.p, phys.delta_tau))
    grid = period_grid(kin, 256)[0]
    N = grid.size - 1
    nodes, step_u, step_pi, step_m, weights, q = (np.empty(N) for _ in range(6))
    stages = np.empty(2 * N)
    status = solve_point_on_grid(code, params[0], grid, N, *physics, 0.0,
                                 solver.kinematic_speed(kin)[0], 1e-10, nodes, step_u, step_pi, step_m,
                                 stages, None, None, weights, q)[3]
    assert status == 0
    times, origins = (a[0] for a in event_times(
        code, params, grid[None], np.array([N]), nodes[None], *(np.array([x]) for x in physics),
        kin.corners()))
    followed = np.flatnonzero(origins >= 0)
    assert followed.size >= 1
    stop = times[followed[0]]
    first = origins[followed[0]]
    k = int(np.searchsorted(grid, stop)) - 1
    # the reference's stop is at 0.05625 (the secant of the nodes: 0.0438), a step is 4.6e-3
    assert abs(stop - 0.05625) < 0.25 * (grid[k + 1] - grid[k]) and 0 <= first < k
    params = params[0]
    estimate = misplaced_stop_error(code, params, grid, first, stop, k, nodes[first], stages,
                                    weights[k + 1], *physics, 1e-12)

    int_u, u_end = radau_reference(code, params, physics, grid[first], grid[k + 1], nodes[first])
    h = np.diff(grid[first:k + 2])
    discrete = np.sum(h * (0.75 * stages[2 * first:2 * k + 2:2]
                           + 0.25 * stages[2 * first + 1:2 * k + 2:2]))
    exact = int_u - discrete + weights[k + 1] * (u_end - stages[2 * k + 1])
    assert abs(exact) > 0.05  # a tenth of int u: the early stop is no small error
    assert abs(estimate - exact) <= 1e-2 * abs(exact), (estimate, exact)


# a neighbour (found by a reviewer in 300 points around it): there the extrapolation's zero,
# 2.97 steps past the crossing step, lay in a step ending 4.25 steps past it (the steps
# after the crossing were 1.5x longer), and following only whole steps within 4 missed it:
# 2.83 rtol off at rtol 1e-3 with an estimate of 0.44
SPURIOUS_STOP_NEIGHBOUR = (
    solver.PowerLaw([1.8730589450843962], [1.228801695952612], [0.23469493023743124],
                    [7.122139834770227], [False], [3.0398580342139843], [True]),
    solver.Physics.from_scaled(7971.722214334097, 55.08018350081435, p=0.0, delta=1e-5))


@pytest.mark.parametrize("case", [SPURIOUS_STOP_CASE, SPURIOUS_STOP_NEIGHBOUR],
                         ids=["ratio_3020", "ratio_7972"])
def test_a_stop_forced_early_by_a_spurious_stage_root_is_counted(case):
    """A stage stuck on a spurious root stopped u 1.8e-3 before the stop, on the grid and on
    its bisection alike: rtol 1e-3 was accepted 1.74 rtol off with an estimate of 0.39 (found
    by a 400-point stress sweep).  The event is now placed where u's extrapolation stops,
    and the steps from the nodes' crossing to it are re-solved for the estimate."""
    kin, phys = case
    ref = reference(kin, phys)
    res = solver.solve_periodic(kin, phys, rtol=1e-3)
    assert ref.status[0] == 0 and res.status[0] == 0
    error = abs(res.mean_u[0] - ref.mean_u[0]) / abs(ref.mean_u[0])
    assert error <= 1e-3, (error / 1e-3, res.error_estimate[0] / 1e-3)


@pytest.mark.xfail(strict=True, reason="known: linearised node weights of 1e30..inf make the "
                                       "event and turning-point estimates astronomic")
def test_events_check_with_astronomic_node_weights_converges():
    """mu_n/mu_s = 2^-12, scaled period 0.156, exponents 12.7 and 16.9, delta 1e-10 (found by
    a stress sweep): node weights of 1e30 and more, the linearised sensitivity where the
    anisotropic law amplifies far outside its range of validity, give event-check estimates
    of 1e30 .. inf on the grids of 680 to 1,480 steps, and refinement stops with
    TOLERANCE_NOT_REACHED at rtol 1e-3; at 1e-4 .. 1e-6 the same point converges, 0.07 ..
    0.11 rtol off.  The turning-point check's resolved weights (``_turning``) explode there
    too: for a while this test passed on another refinement path, which the check's
    dropping of sub-tolerance defects had opened.  A bound for the weights is still
    missing."""
    kin = solver.PowerLaw([2.140821131266869], [0.4551214451394598], [0.8234659386173878],
                          [12.737713075549333], [True], [16.902916202304617], [False])
    phys = solver.Physics.from_scaled(2.0 ** -12, 0.1556322615226379, p=0.0, delta=1e-10)
    res = solver.solve_periodic(kin, phys, rtol=1e-3)
    assert res.converged[0], solver.STATUS_REASONS[int(res.status[0])]
    ref = solver.solve_periodic(kin, phys, rtol=1e-7)
    assert relative_u_error(res.U, ref.U, phys.period, solver.kinematic_speed(kin))[0] <= 1e-3
    assert abs(res.P[0] - ref.P[0]) / ref.P[0] <= 1e-3
