"""pipeline.polish on known functions: distinct starts, the value tolerance, the cap as a status
(never "converged"), failures, the uncertainty and the edges (issue 44, item 1)."""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pytest

from pipeline.polish import CAPPED, CONVERGED, FAILED, cell_record, distinct_starts, maximise


def test_distinct_starts_are_local_maxima_more_than_one_step_apart():
    o = np.zeros((9, 9))
    o[2, 2], o[2, 3] = 5.0, 4.9   # one basin (a neighbour of the best is not a second start)
    o[6, 6] = 3.0                  # a second basin
    o[0, 8] = 1.0                  # a third
    assert distinct_starts(o, (True, True), 3) == [2 * 9 + 2, 6 * 9 + 6, 0 * 9 + 8]
    assert distinct_starts(o, (True, True), 1) == [2 * 9 + 2]
    assert distinct_starts(np.full((3, 3), -np.inf), (True, True), 3) == []


def test_distinct_starts_keep_categories_apart():
    o = np.zeros((2, 5))
    o[0, 2], o[1, 2] = 2.0, 1.0     # same continuous index, different category: both are basins
    assert distinct_starts(o, (False, True), 2) == [2, 5 + 2]


def _quadratic(center, scale=1.0):
    def fun(x):
        v = scale * (1.0 - float(np.sum((np.asarray(x) - center) ** 2)))
        return v, {"params": {"x": float(x[0]), "y": float(x[1])}, "values": {"q": v}, "status": 0}
    return fun


@pytest.mark.parametrize("method", ["Powell", "Nelder-Mead", "compass"])
def test_maximise_reaches_the_maximum_to_the_value_tolerance(method):
    bounds = np.array([[0.0, 1.0], [0.0, 1.0]])
    res = maximise(_quadratic(np.array([0.37, 0.61])), np.array([0.5, 0.5]), bounds, np.array([0.1, 0.1]),
                   tolerance=1e-6, max_evaluations=2000, method=method)
    assert res.converged and not res.capped
    assert res.value == pytest.approx(1.0, rel=1e-5)
    assert res.evaluations < 2000


def test_the_cap_stops_a_run_and_is_never_converged():
    bounds = np.array([[0.0, 1.0], [0.0, 1.0]])
    res = maximise(_quadratic(np.array([0.37, 0.61])), np.array([0.5, 0.5]), bounds, np.array([0.1, 0.1]),
                   tolerance=1e-10, max_evaluations=4, method="Powell")
    assert res.capped and not res.converged and res.evaluations == 4


def _space(over=("x", "y")):
    """A PolishSpace stand-in over the unit box with grid step 0.1."""
    from pipeline.polish.space import PolishSpace

    s = PolishSpace.__new__(PolishSpace)
    s.r = SimpleNamespace(over=over, subsets=None)
    s.free = list(over)
    s.log = np.zeros(len(over), dtype=bool)
    s.step = np.full(len(over), 0.1)
    s.bounds = lambda subset: np.array([[0.0, 1.0]] * len(over))
    return s


def test_record_status_uncertainty_and_edges():
    space = _space()
    bounds = np.array([[0.0, 1.0], [0.0, 1.0]])
    fun = _quadratic(np.array([1.3, 0.5]))  # maximum outside the box: the arg-max is on x's upper end
    runs = [maximise(fun, np.array(x0), bounds, space.step, tolerance=1e-8, max_evaluations=500)
            for x0 in ([0.9, 0.5], [0.95, 0.45])]
    rec = cell_record(space, [{}, {}], runs, None)
    assert rec["status"] == CONVERGED
    assert rec["edges"] == {"x": 1, "y": 0}
    assert 0 <= rec["uncertainty"] < 1e-6           # both starts reached the same basin
    assert rec["evaluations"] == sum(r.evaluations for r in runs)
    capped = maximise(fun, np.array([0.2, 0.2]), bounds, space.step, tolerance=1e-8, max_evaluations=3)
    assert cell_record(space, [{}, {}, {}], runs + [capped], None)["status"] == CAPPED

    def failing(x):
        return -np.inf, {"params": {"x": x[0], "y": x[1]}, "values": {"q": np.nan}, "status": 3}
    failed = maximise(failing, np.array([0.5, 0.5]), bounds, space.step, tolerance=1e-4, max_evaluations=50)
    rec = cell_record(space, [{}], [failed], None)
    assert rec["status"] == FAILED and rec["values"] is None


def test_face_starts_add_the_best_point_of_each_face_not_near_a_taken_start():
    from pipeline.polish import face_starts

    o = np.zeros((5, 5))
    o[2, 2] = 9.0            # the interior basin (taken)
    o[0, 3] = 2.0            # best of face axis0=0
    o[4, 1], o[3, 0] = 1.0, 1.5   # best of face axis0=4 and of face axis1=0 (neighbours: one start)
    taken = [2 * 5 + 2]
    got = face_starts(o, (True, True), taken)
    assert got[0] == 0 * 5 + 3 and 3 * 5 + 0 in got and 4 * 5 + 1 not in got
    assert all(k != taken[0] for k in got)
