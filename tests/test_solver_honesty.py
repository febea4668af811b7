"""The honesty harness (``solver.tools.honesty``): its judging logic, its point sets, and a small
honesty subset of every periodic engine in ``solver.METHODS`` (but the march).

The subset: the first points of several of the harder sets (the paper's power-law grids
among them), each engine at rtol 1e-3 and 1e-5, against the frozen references
(``solver/honesty_references.npz``: the former order-3 engine at rtol 1e-9, cross-checked by
the order-5 engine at 1e-9), so that the engine never checks itself.  With 2 x 40 solves
per engine the harness's 99 % share within rtol allows no miss: every judged solve must be
within rtol (a failed solve counts as outside), none silent.  Measurement history:
``docs/validation.md``.
"""
import dataclasses
from types import SimpleNamespace

import numpy as np
import pytest

import solver
from solver.tools import bench
from solver.tools import honesty

#: (set, first points) judged against the frozen references
SUBSET = (("stress_powerlaw_22", 6), ("fourier_clapping", 6), ("harmonic_extreme", 6),
          ("p0.5_harmonic", 6), ("short_period_harmonic", 6), ("paper_powerlaw", 10))
SUBSET_RTOLS = (1e-3, 1e-5)
#: fewer judged points than this and the subset would say nothing
MIN_JUDGED = 30


# ----------------------------------------------------------------------------- judging logic

def _physics(n):
    return solver.Physics.from_scaled(np.full(n, 2.0), np.full(n, 1.0), p=0.0, delta=1e-5)


def _solves(U, P, status=None, estimate=None):
    U, P = np.asarray(U, float), np.asarray(P, float)
    status = np.zeros(U.size, dtype=np.int8) if status is None else np.asarray(status, np.int8)
    return honesty.Solves(U=U, P=P, status=status, n_tau=np.full(U.size, 64),
                          error_estimate=np.zeros(U.size) if estimate is None else estimate,
                          seconds=0.0)


def _references(U, P, vscale, ref_status=None, check=None):
    physics = _physics(len(U))
    return honesty.References.from_solves(_solves(U, P, ref_status), check, physics,
                                          np.asarray(vscale, float)), physics


def test_a_planted_error_is_counted_outside_rtol():
    """Errors of 0.5, 2 and 20 rtol planted in U (where |U T| is far above the 1e-3 V floor,
    so the norm is U's relative error) and 3 rtol in P: within rtol 1 of 4, within 10 rtol 3,
    one silent failure (20 rtol at status 0), worst 20."""
    rtol = 1e-4
    U_ref, P_ref = np.array([1.0, -2.0, 0.5, 1.0]), np.array([3.0, 1.0, 2.0, 1.0])
    references, physics = _references(U_ref, P_ref, vscale=np.full(4, 1e-2))
    U = U_ref * (1.0 + np.array([0.5, 2.0, 20.0, 0.0]) * rtol)
    P = P_ref * (1.0 + np.array([0.0, 0.0, 0.0, 3.0]) * rtol)
    outcome = honesty.judge(_solves(U, P), references, physics, rtol)
    assert outcome["solves"] == 4
    assert outcome["within_rtol"] == 1 and outcome["within_10_rtol"] == 3
    assert outcome["silent_failures"] == 1 and outcome["silent"][2]
    assert outcome["worst_over_rtol"] == pytest.approx(20.0, rel=1e-6)
    assert list(outcome["outside"]) == [False, True, True, True]


def test_the_u_norm_has_its_floor():
    """U_ref = 0: the error is |U| T / (1e-3 V), not relative to U."""
    references, physics = _references([0.0], [1.0], vscale=[1.0])
    T = physics.period[0]
    outcome = honesty.judge(_solves([0.5e-3 * 1e-3 / T], [1.0]), references, physics, 1e-3)
    assert outcome["worst_over_rtol"] == pytest.approx(0.5)


def test_a_failed_reference_is_excluded_and_counted():
    """The reference failed on point 1 (status 6): that point is not judged however wrong
    the engine's number there, and the set reports it as a failed reference."""
    references, physics = _references([1.0, np.nan, 1.0], [1.0, np.nan, 1.0], [1e-2] * 3,
                                      ref_status=[0, 6, 0])
    assert list(references.kind) == [honesty.SINGLE, honesty.FAILED, honesty.SINGLE]
    outcome = honesty.judge(_solves([1.0, 5.0, 1.0], [1.0, 5.0, 1.0]), references, physics,
                            1e-3)
    assert outcome["solves"] == 2 and outcome["within_rtol"] == 2
    assert outcome["silent_failures"] == 0 and not outcome["judged"][1]


def test_references_that_disagree_are_uncertain_at_tight_rtol_only():
    """A check 5e-6 off the reference: judged at rtol 1e-3 (agreement 0.1 rtol = 1e-4), not
    at 1e-5 (1e-6), where the point is counted uncertain; a failed check leaves one
    reference (judged)."""
    check = _solves([1.0 + 5e-6, 1.0], [1.0, 1.0], status=[0, 4])
    references, physics = _references([1.0, 1.0], [1.0, 1.0], [1e-2] * 2, check=check)
    assert list(references.kind) == [honesty.JUDGED, honesty.SINGLE]
    assert references.disagreement[0] == pytest.approx(5e-6)
    result = _solves([1.0, 1.0], [1.0, 1.0])
    loose = honesty.judge(result, references, physics, 1e-3)
    tight = honesty.judge(result, references, physics, 1e-5)
    assert loose["solves"] == 2 and loose["uncertain"] == 0
    assert tight["solves"] == 1 and tight["uncertain"] == 1


def test_failures_count_outside_rtol_and_non_finite_converged_results_are_silent():
    """status != 0 is an honest failure: outside rtol, not silent.  status 0 with a NaN is
    silent, on a judged point or not."""
    references, physics = _references([1.0, 1.0, np.nan], [1.0, 1.0, np.nan], [1e-2] * 3,
                                      ref_status=[0, 0, 6])
    result = _solves([np.nan, np.nan, np.inf], [np.nan, 1.0, 1.0], status=[6, 0, 0])
    outcome = honesty.judge(result, references, physics, 1e-3)
    assert outcome["solves"] == 2 and outcome["within_rtol"] == 0
    assert outcome["failures"] == 1 and outcome["failure_codes"] == {6: 1}
    assert list(outcome["silent"]) == [False, True, True]
    assert outcome["silent_failures"] == 2


def _counting_engine(monkeypatch):
    """Replace the engine behind ``cached_solves`` by a stub; returns the list into which it
    appends the number of points of each run."""
    calls = []

    def fake_run(kinematics, physics, method, rtol):
        calls.append(len(kinematics))
        return _solves(np.arange(len(kinematics), dtype=float), np.ones(len(kinematics)))

    monkeypatch.setattr(honesty.Solves, "run", staticmethod(fake_run))
    return calls


def test_cached_solves_are_reused_only_for_the_same_points(tmp_path, monkeypatch):
    """The cache returns the stored solves for the same points and recomputes for others
    (or with ``refresh``); the engine is not run here."""
    calls = _counting_engine(monkeypatch)
    kin, phys = solver.Harmonic([1.0, 1.1], [0.3, 0.3]), _physics(2)
    first, cached = honesty.cached_solves(kin, phys, "periodic", 1e-9, "s", tmp_path)
    again, cached_again = honesty.cached_solves(kin, phys, "periodic", 1e-9, "s", tmp_path)
    assert not cached and cached_again and calls == [2]
    np.testing.assert_array_equal(first.U, again.U)
    other = solver.Harmonic([1.0, 1.2], [0.3, 0.3])
    _, cached_other = honesty.cached_solves(other, phys, "periodic", 1e-9, "s", tmp_path)
    _, refreshed = honesty.cached_solves(kin, phys, "periodic", 1e-9, "s", tmp_path,
                                         refresh=True)
    assert not cached_other and not refreshed and calls == [2, 2, 2]


# ----------------------------------------------------------------------------- point sets

@pytest.mark.parametrize("name", sorted(honesty.SETS))
def test_sets_are_seeded_and_a_smaller_set_is_a_prefix(name):
    point_set = honesty.SETS[name]
    kin, phys = point_set.sample(7)
    kin_all, phys_all = point_set.sample()
    assert len(kin) == 7 and len(kin_all) == point_set.points
    np.testing.assert_array_equal(kin.kernel_encoding()[1], kin_all.kernel_encoding()[1][:7])
    np.testing.assert_array_equal(phys.delta, phys_all.delta[:7])
    np.testing.assert_array_equal(phys.period, phys_all.period[:7])


def test_the_bench_set_is_the_benchmarks_points():
    kin, phys = honesty.SETS["bench"].sample(50)
    bench_kin, bench_phys, _ = bench.draw_points(bench.DEFAULT_POINTS,
                                                 np.random.default_rng(bench.DEFAULT_SEED))
    np.testing.assert_array_equal(kin.A0, bench_kin.A0[:50])
    np.testing.assert_array_equal(phys.period, bench_phys.period[:50])


def test_the_clapping_set_claps():
    """phi leaves (0, pi) on about half the Fourier points (58 % of 4,000 draws)."""
    kin, _ = honesty.SETS["fourier_clapping"].sample()
    assert 0.4 <= honesty.clapping_share(kin) <= 0.8


# ----------------------------------------------------------------------------- honesty subset

@pytest.fixture(scope="module")
def subset():
    """(kinematics, physics, References) of each subset set's first points."""
    out = {}
    for name, n in SUBSET:
        kin, phys = honesty.SETS[name].sample(n)
        reference, check, _ = honesty.frozen_references(honesty.SETS[name], kin, phys)
        out[name] = (kin, phys, honesty.References.from_solves(
            reference, check, phys, solver.kinematic_speed(kin)))
    return out


@pytest.mark.parametrize("method,sweeps", [(m, False) for m in honesty.default_methods()]
                         + [("periodic", True)])
def test_honesty_subset(method, sweeps, subset):
    """The subset cold, and (``--sweeps``) as warm-started sweeps in a neighbour order."""
    judged = failed_refs = 0
    misses = []
    for name, (kin, phys, references) in subset.items():
        failed_refs += int(np.count_nonzero(references.kind == honesty.FAILED))
        order = honesty.neighbour_order(kin, phys) if sweeps else None
        for rtol in SUBSET_RTOLS:
            result = honesty.Solves.run(kin, phys, method, rtol, order)
            outcome = honesty.judge(result, references, phys, rtol)
            judged += outcome["solves"]
            assert outcome["silent_failures"] == 0, (name, rtol, outcome["error"])
            assert outcome["within_10_rtol"] == outcome["solves"], (name, rtol)
            misses += [(name, rtol, int(i), outcome["error"][i], int(result.status[i]))
                       for i in np.flatnonzero(outcome["outside"])]
    assert judged >= MIN_JUDGED * len(SUBSET_RTOLS), (judged, failed_refs)
    assert not misses, misses


def test_the_neighbour_order_walks_to_near_points():
    """``neighbour_order`` is a permutation whose steps are shorter than a random order's."""
    kin, phys = honesty.SETS["bench"].sample(300)
    order = honesty.neighbour_order(kin, phys)
    assert sorted(order.tolist()) == list(range(300)) and order[0] == 0
    _, params = kin.kernel_encoding()
    x = np.column_stack([params, np.log(phys.mu_n), np.log(phys.period)])
    step = lambda o: np.linalg.norm(np.diff(x[o], axis=0), axis=1).mean()
    assert step(order) < 0.5 * step(np.random.default_rng(0).permutation(300))


def test_references_of_an_earlier_engine_are_reused_only_when_asked(tmp_path, monkeypatch):
    """An edit in solver/ changes ``engine_digest``: the cached references are then
    recomputed, unless ``reuse``, which takes the earlier engine's file of the same points
    and says so; never another set of points."""
    calls = _counting_engine(monkeypatch)
    kin, phys = solver.Harmonic([1.0, 1.1], [0.3, 0.3]), _physics(2)
    monkeypatch.setattr(honesty, "engine_digest", lambda: "aaaa")
    _, source = honesty.cached_solves(kin, phys, "periodic", 1e-9, "s", tmp_path)
    assert source == "" and calls == [2]
    monkeypatch.setattr(honesty, "engine_digest", lambda: "bbbb")
    _, source = honesty.cached_solves(kin, phys, "periodic", 1e-9, "s", tmp_path, reuse=True)
    assert source == "reused from engine aaaa" and calls == [2]
    other = solver.Harmonic([1.0, 1.2], [0.3, 0.3])
    _, source = honesty.cached_solves(other, phys, "periodic", 1e-9, "s", tmp_path, reuse=True)
    assert source == "" and calls == [2, 2]
    _, source = honesty.cached_solves(kin, phys, "periodic", 1e-9, "s", tmp_path)
    assert source == "" and calls == [2, 2, 2]


# ----------------------------------------------------------------------------- frozen references

def test_frozen_references_hold_every_set_with_its_provenance():
    """The committed file has every set's every point, made from the sets' generators as they
    are today (their digests match), with the commit and settings that made them; the
    reference and its cross-check (independent engines at rtol 1e-9) agree to 1e-7 in the
    solver's norm wherever both converged.  The points are compared by their signature, not
    bit for bit: their last bits differ between CPUs (``test_a_set_is_known_by_its_points_
    not_by_their_last_bits``)."""
    meta = honesty.frozen_meta()
    assert meta["reference"][0] == "periodic" and meta["reference"][1] <= 1e-9
    assert meta["check"][1] <= 1e-9 and len(meta["commit"]) >= 7
    assert set(meta["sets"]) == set(honesty.SETS)
    for name, point_set in honesty.SETS.items():
        stored = meta["sets"][name]
        kin, phys = point_set.sample()
        assert stored["points"] == len(kin) and stored["seed"] == point_set.seed
        assert honesty.same_points(honesty.set_signature(kin, phys), stored["signature"]), name
        assert stored["disagreement_max"] <= 1e-7, (name, stored["disagreement_max"])


def test_a_set_is_known_by_its_points_not_by_their_last_bits():
    """``same_points`` accepts points that differ by rounding (a few ulps, as another CPU's
    ``exp`` gives) and refuses the negative controls: one point moved by 1e-6 relative, two
    points swapped, one point fewer.  (A generator that changed moves every point by O(1).)"""
    kin, phys = honesty.SETS["harmonic_extreme"].sample()
    stored = honesty.set_signature(kin, phys)
    params = kin.kernel_encoding()[1]
    assert honesty.same_points(honesty.set_signature(kin, phys), stored)

    def moved(scale, index=None):
        phys_moved = phys.take(np.arange(len(phys)))
        period = phys_moved.period.copy()
        if index is None:
            period = period * (1 + scale * np.random.default_rng(1).standard_normal(period.size))
        else:
            period[index] *= 1 + scale
        return honesty.set_signature(kin, dataclasses.replace(phys_moved, period=period))

    assert honesty.same_points(moved(4e-16), stored)           # every point, a few ulps
    assert not honesty.same_points(moved(1e-6, index=7), stored)
    order = np.arange(len(kin))
    order[[3, 4]] = order[[4, 3]]
    assert params.shape[0] == len(kin)
    assert not honesty.same_points(honesty.set_signature(kin.take(order), phys.take(order)), stored)
    assert not honesty.same_points(honesty.set_signature(kin.take(order[:-1]),
                                                         phys.take(order[:-1])), stored)


def test_freeze_round_trip(tmp_path, monkeypatch):
    """``freeze`` writes what ``frozen_references`` reads back, for a prefix of the set too;
    another set of points is refused with a message naming the set."""
    calls = _counting_engine(monkeypatch)
    point_set = honesty.PointSet("tiny", 5, lambda n, rng: (solver.Harmonic(
        rng.uniform(0.5, 1.0, n), np.full(n, 0.3)), _physics(n)), "tiny harmonic", points=3)
    monkeypatch.setitem(honesty.SETS, "tiny", point_set)
    settings = honesty.Settings(methods=("periodic",), reference_method="periodic",
                                reference_rtol=1e-9, check_method="march", check_rtol=1e-7,
                                cache_dir=tmp_path / "cache")
    path = tmp_path / "frozen.npz"
    meta = honesty.freeze(["tiny"], settings, path)
    assert calls == [3, 3] and meta["sets"]["tiny"]["points"] == 3
    kin, phys = point_set.sample(2)
    ref, check, read_meta = honesty.frozen_references(point_set, kin, phys, path)
    assert ref.U.shape == (2,) and read_meta["sets"]["tiny"]["digest"] == meta["sets"]["tiny"]["digest"]
    other = honesty.PointSet("tiny", 6, point_set.draw, "tiny harmonic", points=3)
    with pytest.raises(ValueError, match="'tiny'"):
        honesty.frozen_references(other, *other.sample(2), path)


def test_freeze_refuses_to_overwrite_the_committed_references(capsys):
    """The committed references were made by the former order-3 engine; frozen anew by
    today's engine the harness would judge the engine by itself: refused, exit 2, one line."""
    before = honesty.REFERENCE_FILE.stat().st_mtime
    assert honesty.main(["--freeze", "--set", "bench"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "--reference-file" in err[0]
    assert honesty.REFERENCE_FILE.stat().st_mtime == before
