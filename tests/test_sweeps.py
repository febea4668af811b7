"""Warm starts along sweeps (``solve_periodic(..., sweeps=...)``, ``periodic.point.warm_start``).

A warm result is judged by the same estimate as a cold one, so it must be as honest; a sweep's
results depend on its own points only (not on the other sweeps of the batch, nor on the
threads); warm starts do skip the loose shooting; and bad ``sweeps`` are refused by name.
"""
from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings, strategies as st

import solver
from solver.periodic import driver, point
from solver.tools import bench_sweep
from solver.tools.bench import solution_error


def _grid(n=8, family="harmonic", ratio=16.0, scaled_period=0.5):
    """An n x n grid in A0 x A1/A0, in snake order, as (kinematics, physics): the bench's."""
    return bench_sweep.grid(family, ratio, scaled_period, n)


def _runs(n, length):
    return solver.sweep_runs(n, length)


@pytest.mark.parametrize("family,ratio,scaled_period,rtol", [
    ("harmonic", 16.0, 0.5, 1e-4), ("harmonic", 2.0 ** -6, 4.0, 1e-6),
    ("power_law", 2.0 ** -4, 2.0, 1e-4), ("power_law", 8.0, 0.3, 1e-6)])
def test_warm_results_are_as_honest_as_cold_ones(family, ratio, scaled_period, rtol):
    """Against references at rtol 1e-10 (cold): every warm result within 10 rtol, >= 99 %
    within rtol, as the harness demands of cold solves; most points really start warm."""
    kin, phys = _grid(8, family, ratio, scaled_period)
    n = len(kin)
    warm = solver.solve_periodic(kin, phys, rtol=rtol, sweeps=_runs(n, 32))
    ref = solver.solve_periodic(kin, phys, rtol=1e-10)
    assert ref.converged.all() and warm.converged.all()
    error = solution_error(warm.U, warm.P, ref.U, ref.P, phys.period,
                           solver.kinematic_speed(kin)) / rtol
    assert np.max(error) <= 10.0
    assert np.mean(error <= 1.0) >= 0.99
    assert np.all(warm.error_estimate <= rtol)
    assert np.count_nonzero(warm.start == point.START_WARM) >= n - 2 * 2  # all but 2 runs' firsts
    # a warm start skips the loose shooting
    loose = warm.force_evaluations[:, point.COST_LOOSE]
    assert np.all(loose[warm.start == point.START_WARM] == 0)
    assert np.all(loose[warm.start == point.START_COLD] > 0)


def test_a_sweep_depends_on_its_own_points_only():
    """A sweep solved alone, within a batch of other sweeps, and on one or two threads gives
    bit-identical results; its first point equals the cold solve."""
    kin, phys = _grid(6)
    n = len(kin)
    runs = _runs(n, 12)
    both = solver.solve_periodic(kin, phys, rtol=1e-5, sweeps=runs)
    k = 1  # the second sweep, alone
    idx = np.arange(runs[k], runs[k + 1])
    alone = solver.solve_periodic(kin.take(idx), phys.take(idx), rtol=1e-5,
                                  sweeps=np.array([0, idx.size]))
    for name in ("U", "P", "error_estimate", "n_tau", "status"):
        np.testing.assert_array_equal(getattr(alone, name), getattr(both, name)[idx])
    cold = solver.solve_periodic(kin.take(idx[:1]), phys.take(idx[:1]), rtol=1e-5)
    np.testing.assert_array_equal(cold.U, alone.U[:1])
    code, params = kin.kernel_encoding()
    from solver.model.limits import fast_limit_velocity
    points = driver.Points(code, params, kin.corners(), phys.inertia_factor, phys.mu_n,
                           phys.mu_s, phys.p, phys.delta_tau,
                           fast_limit_velocity(kin, phys,
                                               solver.EngineOptions().batch.guess_steps))
    one, _ = driver.solve_points(points, 1e-5, 2 ** 17, runs, 1)
    two, _ = driver.solve_points(points, 1e-5, 2 ** 17, runs, 2)
    for a, b in zip(one, two):
        np.testing.assert_array_equal(a, b)


def test_cold_batches_are_unchanged_by_the_sweep_machinery():
    """Every point its own sweep (the default) equals sweeps of one point each."""
    kin, phys = _grid(4)
    n = len(kin)
    default = solver.solve_periodic(kin, phys, rtol=1e-5)
    singles = solver.solve_periodic(kin, phys, rtol=1e-5, sweeps=np.arange(n + 1))
    for name in ("U", "P", "error_estimate", "n_tau", "status"):
        np.testing.assert_array_equal(getattr(default, name), getattr(singles, name))
    assert np.all(default.start == point.START_COLD)


def test_series_of_a_sweep_are_its_final_steps():
    kin, phys = _grid(4)
    n = len(kin)
    r = solver.solve_periodic(kin, phys, rtol=1e-5, sweeps=_runs(n, 8), return_series=True)
    assert [len(u) for u in r.u] == list(r.n_tau + 1)  # the period closed: tau = 1 too
    for u, tau in zip(r.u, r.tau):
        assert tau[0] == 0.0 and tau[-1] == 1.0 and np.all(np.diff(tau) > 0) and np.isfinite(u).all()


@pytest.mark.parametrize("sweeps,what", [
    (np.array([0, 3]), "rise strictly from 0 to n_points"),
    (np.array([1, 16]), "rise strictly from 0 to n_points"),
    (np.array([0, 8, 8, 16]), "rise strictly from 0 to n_points"),
    (np.array([0.0, 16.0]), "integer"),
    (np.array([[0, 16]]), "integer"),
])
def test_bad_sweeps_are_refused_by_name(sweeps, what):
    kin, phys = _grid(4)
    with pytest.raises(ValueError, match=f"^sweeps: .*{what}"):
        solver.solve_periodic(kin, phys, rtol=1e-4, sweeps=sweeps)


def test_the_march_refuses_sweeps():
    kin, phys = _grid(4)
    with pytest.raises(ValueError, match="^sweeps: only method 'periodic'"):
        solver.solve_periodic(kin, phys, method="march", rtol=1e-3, sweeps=np.array([0, 16]))


@settings(max_examples=40, deadline=None)
@given(st.lists(st.integers(1, 5), min_size=1, max_size=4))
def test_snake_order_visits_every_point_once_through_neighbours(shape):
    shape = tuple(shape)
    order = solver.snake_order(shape)
    assert sorted(order.tolist()) == list(range(int(np.prod(shape))))
    coords = np.array(np.unravel_index(order, shape)).T
    if len(order) > 1:
        steps = np.abs(np.diff(coords, axis=0))
        assert np.all(steps.sum(axis=1) == 1)  # one step along one axis


def test_a_neighbour_from_another_regime_does_not_loosen_the_stages():
    """short_period_harmonic point 78 (scaled period 0.0094), swept as in ``honesty
    --sweeps`` (positions 320 .. 363 of its ``neighbour_order``) after a point of scaled
    period 0.089: with the neighbour's stage tolerance it took 51 steps and returned an error
    of 41 rtol under an estimate of 0.84 rtol (``WARM_ATOL_SLACK``)."""
    from solver.tools.honesty import SETS, neighbour_order

    kin, phys = SETS["short_period_harmonic"].sample(None)
    order = neighbour_order(kin, phys)
    run = order[320:364]
    assert run[-1] == 78
    kin, phys = kin.take(run), phys.take(run)
    warm = solver.solve_periodic(kin, phys, rtol=1e-3, sweeps=np.array([0, run.size]))
    ref = solver.solve_periodic(kin.take([run.size - 1]), phys.take([run.size - 1]), rtol=1e-8)
    assert ref.converged.all() and warm.converged.all()
    assert warm.start[-1] == point.START_WARM
    error = solution_error(warm.U[-1:], warm.P[-1:], ref.U, ref.P, phys.period[-1:],
                           solver.kinematic_speed(kin.take([run.size - 1])))
    assert error[0] <= 1e-3
