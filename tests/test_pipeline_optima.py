"""Scene kind "optima": parsing, the distinct-optima reduction against brute force, a small run."""
from __future__ import annotations

import math
import subprocess
from dataclasses import replace
import sys
import warnings

import numpy as np
import pytest

import solver
from pipeline import SceneError, parse_scene, run_scene
from pipeline._optima import (STOP_CODES, distinct_optima, fourier_samples, reduce_optima,
                              reflect_about_half_pi)
from pipeline._store import StoreMismatch

from pipeline_cases import REPO

TINY = """
[scene]
kind = "optima"
name = "tiny_optima"
title = "optima test scene"

[axes]
anisotropy_ratio = {{ values = [0.0625, 16.0] }}
max_wavenumber = [1]
p = {p}

[starts]
num = 4
seed = 3

[optimizer]
max_iterations = 60

[keep]
best = 3
n_tau = 32

[execution]
starts_per_task = 2
scheduler = "synchronous"
"""


def tiny(p="[0.0]"):
    return parse_scene(TINY.format(p=p), "tiny.toml")


# -- the reduction against a brute-force reference ---------------------------------------------


def _same_brute_force(a, b, period_a, period_b, phi_tol, period_tol):
    """Equal optima by loops over every shift, both signs and every sample."""
    if abs(period_a - period_b) > period_tol * max(period_a, period_b):
        return False
    n = len(a)
    for sign in (1.0, -1.0):
        for shift in range(n):
            if max(abs(a[i] - sign * b[(i + shift) % n]) for i in range(n)) <= phi_tol:
                return True
    return False


def _reference(phi, period, score, best, phi_tol, period_tol):
    order = sorted((i for i in range(len(score)) if np.isfinite(score[i])),
                   key=lambda i: (-score[i], i))
    kept, counts = [], []
    for i in order:
        for j, k in enumerate(kept):
            if _same_brute_force(phi[k], phi[i], period[k], period[i], phi_tol, period_tol):
                counts[j] += 1
                break
        else:
            if len(kept) < best:
                kept.append(i)
                counts.append(1)
    return kept, counts


def _planted_ensemble(rng, n_distinct=7, n=40, n_tau=24, kmax=3):
    """Random series, then copies shifted by tau = j/n_tau, negated, or slightly perturbed."""
    base = rng.normal(size=(n_distinct, 2 * kmax + 1)) * 0.5
    periods = rng.uniform(1.0, 5.0, n_distinct)
    phi, period = [], []
    for _ in range(n):
        k = rng.integers(n_distinct)
        samples = fourier_samples(base[k], n_tau)
        samples = np.roll(samples, rng.integers(n_tau)) * rng.choice([1.0, -1.0])
        samples = samples + rng.normal(scale=rng.choice([1e-4, 0.05]), size=n_tau)
        phi.append(samples)
        period.append(periods[k] * (1 + rng.choice([1e-4, 0.05]) * rng.normal()))
    score = rng.uniform(0, 1, n)
    score[rng.integers(n, size=3)] = np.nan  # not eligible
    return np.array(phi), np.array(period), score


@pytest.mark.parametrize("seed", range(6))
def test_distinct_optima_matches_brute_force(seed):
    rng = np.random.default_rng(seed)
    phi, period, score = _planted_ensemble(rng)
    for best in (3, 10):
        found = distinct_optima(phi, period, score, best=best, phi_tolerance=0.02,
                                period_tolerance=0.01)
        kept, counts = _reference(phi, period, score, best, 0.02, 0.01)
        assert found.index.tolist() == kept
        assert found.multiplicity.tolist() == counts
    # planted copies were recognised: some kept optimum stands for several starts
    assert found.multiplicity.max() > 1


def test_fourier_samples_match_the_solver_family():
    rng = np.random.default_rng(0)
    A, B = rng.normal(size=(1, 4)), rng.normal(size=(1, 3))
    samples = fourier_samples(np.concatenate([A[0], B[0]]), 16)
    np.testing.assert_allclose(samples, solver.Fourier(A, B).angle(np.arange(16) / 16)[0],
                               atol=1e-13)
    np.testing.assert_allclose(fourier_samples(reflect_about_half_pi(
        np.concatenate([A[0], B[0]])), 16), math.pi - samples, atol=1e-13)


def test_reduction_orients_optima_backwards_and_skips_unconverged():
    scene = tiny()
    n_r, n_k, n_p, n_s = scene.shape
    rng = np.random.default_rng(1)
    coefficients = np.zeros(scene.shape + (3,))
    coefficients[..., 0] = rng.uniform(0.2, 1.0, scene.shape)
    coefficients[..., 1] = rng.uniform(0.2, 1.0, scene.shape)
    U = rng.choice([-1.0, 1.0], scene.shape)
    rel = U * rng.uniform(0.1, 0.5, scene.shape)
    status = np.zeros(scene.shape, dtype=np.int8)
    status[0, 0, 0, 0] = STOP_CODES["max_iterations"]
    data = {"status": status, "U": U, "efficiency": 3 * rel, "relative_efficiency": rel,
            "scaled_period": rng.uniform(1, 4, scene.shape), "coefficients": coefficients,
            "gradient_norm": np.full(scene.shape, 1e-3),
            "period_at_bound": np.zeros(scene.shape, dtype=np.int8)}
    data["period_at_bound"][1, 0, 0, 2] = 1
    out = reduce_optima(scene, data)
    assert 0 not in out["optimum_start"][0, 0, 0]  # unconverged start is not kept
    assert 2 not in out["optimum_start"][1, 0, 0]  # nor one whose period ran to its bound
    for cell in np.ndindex(n_r, n_k, n_p):
        for rank, start in enumerate(out["optimum_start"][cell]):
            if start < 0:
                continue
            expected = coefficients[cell][start]
            if U[cell][start] > 0:
                expected = reflect_about_half_pi(expected)
            np.testing.assert_allclose(out["optimum_coefficients"][cell][rank], expected)
            # the start's own efficiency, oriented backwards
            assert out["optimum_efficiency"][cell][rank] == -abs(data["efficiency"][cell][start])
    best = out["optimum_relative_efficiency"]
    assert np.all(np.diff(best, axis=-1)[np.isfinite(np.diff(best, axis=-1))] <= 0)
    # an unconverged start with a gradient below accept_gradient_norm becomes eligible
    data["gradient_norm"][0, 0, 0, 0] = 1e-6
    data["relative_efficiency"][0, 0, 0, 0] = -0.9  # the best of its cell
    loose = reduce_optima(replace(scene, keep=replace(scene.keep, accept_gradient_norm=1e-5)), data)
    assert loose["optimum_start"][0, 0, 0, 0] == 0


# -- scenes --------------------------------------------------------------------------------------


@pytest.mark.parametrize("edit, key", [
    (("max_wavenumber = [1]", "max_wavenumber = [3, 1]"), "axes.max_wavenumber"),
    (("num = 4", "num = 0"), "starts.num"),
    (("max_iterations = 60", "max_iterations = 60\nobjective = \"fastest\""), "optimizer.objective"),
    (("max_iterations = 60", "max_iterations = 60\nobjective = \"speed_at_power\""),
     "optimizer.power"),
    (("best = 3", "best = 3\nsimilar = 1"), "keep.similar"),
    (("kind = \"optima\"", "kind = \"optimum\""), "scene.kind"),
    (("max_iterations = 60", "max_iterations = 60\ncertify_tolerance = 0"), "optimizer.certify_tolerance"),
    (("max_iterations = 60", "max_iterations = 60\ncertify_rounds = -1"), "optimizer.certify_rounds"),
    (("max_iterations = 60", "max_iterations = 60\nfidelity = 0.5"), "optimizer.fidelity"),
])
def test_bad_optima_scene_names_the_key(edit, key):
    with pytest.raises(SceneError) as info:
        parse_scene(TINY.format(p="[0.0]").replace(*edit), "bad.toml")
    assert info.value.key == key


def test_bad_optima_scene_exits_2_and_writes_nothing(tmp_path):
    scene = tmp_path / "bad.toml"
    scene.write_text(TINY.format(p="[2.5]"))
    store = tmp_path / "bad.zarr"
    run = subprocess.run([sys.executable, "-m", "pipeline", "run", str(scene), "--store", str(store)],
                         capture_output=True, text=True, cwd=REPO, timeout=60)
    assert run.returncode == 2
    assert "axes.p" in run.stderr and len(run.stderr.strip().splitlines()) == 1
    assert not store.exists()


@pytest.mark.parametrize("name", ["fourier_optima", "force_laws"])
def test_shipped_optima_scenes_and_their_quick_variants(name):
    from pipeline.__main__ import quick_variant
    from pipeline import load_scene

    full = load_scene(REPO / "workflows" / f"{name}.toml")
    quick = quick_variant(REPO / "workflows" / f"{name}.toml")
    assert full.kind == quick.kind == "optima"
    assert quick.hash != full.hash
    assert quick.n_points < full.n_points and quick.n_starts <= full.n_starts
    assert max(quick.max_wavenumbers) < max(full.max_wavenumbers)


# -- a small run through the pipeline -----------------------------------------------------------


def _open(store):
    import xarray as xr

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return xr.open_zarr(str(store), consolidated=False).load()


def test_small_run_resumes_and_refuses_another_scene(tmp_path):
    scene = tiny()
    store = tmp_path / "tiny.zarr"
    first = run_scene(scene, store, progress=False)
    assert first.computed_points == scene.n_points and first.total_chunks == 4
    ds = _open(store)
    from pipeline import read_record

    assert read_record(ds.attrs)["kind"] == "optima"
    assert np.all(ds.status.values >= 0) and np.all(ds.ill_conditioned.values >= 0)
    converged = ds.status.values == STOP_CODES["gradient_tolerance"]
    assert converged.sum() >= scene.n_points // 2
    assert np.all(ds.gradient_norm.values[converged] < 1e-7)
    assert np.all(ds.iterations.values <= 3 * 60)  # max_iterations per grid round, 3 rounds
    # the reduction in the store is the reduction of the stored starts
    data = {k: ds[k].values for k in ("status", "U", "efficiency", "relative_efficiency",
                                      "scaled_period", "gradient_norm", "period_at_bound",
                                      "coefficients")}
    again = reduce_optima(scene, data)
    np.testing.assert_array_equal(ds.optimum_start.values, again["optimum_start"])
    best = ds.optimum_relative_efficiency.values[..., 0]
    assert np.all(best > 0)
    # a second run does nothing; a lost marker recomputes exactly that chunk
    assert run_scene(scene, store, progress=False).computed_points == 0
    import zarr

    zarr.open_array(store=str(store), path="pipeline_state/chunk_done", mode="r+")[1, 0, 0, 1] = 0
    resumed = run_scene(scene, store, progress=False)
    assert resumed.computed_chunks == 1 and resumed.computed_points == 2
    np.testing.assert_allclose(_open(store).relative_efficiency.values,
                               ds.relative_efficiency.values, rtol=1e-9)
    with pytest.raises(StoreMismatch):
        run_scene(parse_scene(TINY.format(p="[0.5]"), "other.toml"), store, progress=False)


@pytest.mark.slow
def test_an_optima_store_exports_to_netcdf(tmp_path):
    """Issue 34: an optima store through ``pipeline.to_netcdf`` reads back equal."""
    from pipeline_cases import assert_exports_to_netcdf

    store = tmp_path / "tiny.zarr"
    run_scene(tiny(), store, progress=False)
    assert_exports_to_netcdf(store, tmp_path)


def test_near_p_two_is_flagged_not_looped(tmp_path):
    # p = 1.95: lambda nearly invariant under T; every start ends, flagged where ill-conditioned
    scene = tiny("[1.95]")
    run_scene(scene, tmp_path / "p2.zarr", progress=False)
    ds = _open(tmp_path / "p2.zarr")
    assert np.all(ds.status.values >= 0)
    assert np.all(ds.iterations.values <= 3 * 60)
    # T runs to its box there (measured: every start), and such a start is never kept as an
    # optimum (that it is flagged ill-conditioned follows from the stop rule itself)
    at_bound = ds.period_at_bound.values == 1
    assert at_bound.any()
    kept = ds.optimum_start.values
    for cell in np.ndindex(kept.shape[:3]):
        assert not np.any(at_bound[cell][kept[cell][kept[cell] >= 0]])


def test_a_start_ending_at_rest_is_no_optimum():
    """Issue 28: minimising the signed lambda, starts that move forwards can end at the
    zero-amplitude stationary point (phi constant, lambda = 0, gradient ~1e-8). Each such start
    sat at its own constant phi, so the reduction kept every one as another "distinct optimum"
    (6 at 2^-4, Kmax 1 with 48 starts, where the paper finds one). A motion spanning no more
    than STILL_AMPLITUDE is not kept; a real optimum with a small amplitude is."""
    from pipeline._optima import STILL_AMPLITUDE

    scene = tiny()
    scene = replace(scene, keep=replace(scene.keep, best=scene.n_starts))  # room for every start
    coefficients = np.zeros(scene.shape + (3,))
    coefficients[..., 0] = np.linspace(0.3, 2.9, scene.shape[-1])  # every start at its own A0
    coefficients[..., 1] = 0.5
    coefficients[..., 0, 1] = 1e-4  # start 0 at rest: phi spans 2e-4 rad (as measured: 3e-5 .. 2e-4)
    coefficients[..., 1, 1] = 0.02                   # start 1 a small but real motion (0.04 rad)
    rel = np.full(scene.shape, -0.2)
    rel[..., 0] = -1e-9
    data = {"status": np.zeros(scene.shape, dtype=np.int8), "U": np.full(scene.shape, -1.0),
            "efficiency": 3 * rel, "relative_efficiency": rel,
            "scaled_period": np.full(scene.shape, 2.0), "coefficients": coefficients,
            "gradient_norm": np.full(scene.shape, 1e-8), "period_at_bound": np.zeros(scene.shape, dtype=np.int8)}
    assert 2e-4 < STILL_AMPLITUDE < 0.04
    out = reduce_optima(scene, data)
    for cell in np.ndindex(*scene.shape[:3]):
        kept = set(out["optimum_start"][cell][out["optimum_start"][cell] >= 0].tolist())
        assert 0 not in kept and 1 in kept


def test_the_store_holds_certified_optima_and_their_cost(tmp_path):
    """Issue 47: every start stores certified, at_rest, cpu_seconds, solves, coarse_iterations,
    certify_rounds; no kept optimum has a grid error above the scene's certify_tolerance (1e-4);
    and the reduction keeps no uncertified start, even the best of its cell (the control)."""
    scene = tiny()
    store = tmp_path / "tiny.zarr"
    run_scene(scene, store, progress=False)
    ds = _open(store)
    done = ds.status.values != STOP_CODES["error"]
    for name in ("certified", "at_rest"):
        assert set(np.unique(ds[name].values[done])) <= {0, 1}
    assert np.all(ds.cpu_seconds.values[done] > 0) and np.all(ds.solves.values[done] > 0)
    assert np.all(ds.coarse_iterations.values == 0)  # fidelity off by default
    assert np.all((ds.certify_rounds.values >= 0) & (ds.certify_rounds.values <= 2))
    floor = np.maximum(1.0, 1e-6 / np.abs(ds.relative_efficiency.values[done]))  # STILL_EFFICIENCY
    np.testing.assert_array_equal(ds.certified.values[done] == 1,
                                  ds.grid_error.values[done] <= 1e-4 * floor)
    kept = ds.optimum_start.values
    assert (kept >= 0).any()
    for cell in np.ndindex(kept.shape[:3]):
        starts = kept[cell][kept[cell] >= 0]
        assert np.all(ds.grid_error.values[cell][starts] <= 1e-4)
    data = {k: ds[k].values.copy() for k in ("status", "U", "efficiency", "relative_efficiency",
                                             "scaled_period", "gradient_norm", "period_at_bound",
                                             "certified", "coefficients")}
    best = int(kept[0, 0, 0, 0])
    data["certified"][0, 0, 0, best] = 0
    assert best not in reduce_optima(scene, data)["optimum_start"][0, 0, 0]


def test_a_store_of_the_former_kind_version_is_refused_by_name(tmp_path):
    """A store whose per-start values mean something else (kind_version 2: uncertified optima)
    is not resumed; the refusal names the kind version, not just "a different scene"."""
    from pipeline._attrs import read_record, record_text
    import zarr

    scene = tiny()
    store = tmp_path / "tiny.zarr"
    run_scene(scene, store, progress=False)
    g = zarr.open_group(str(store), mode="r+")
    record = read_record(dict(g.attrs))
    assert record["kind_version"] == 3
    g.attrs["pipeline"] = record_text({**record, "kind_version": 2})
    with pytest.raises(StoreMismatch, match="kind_version 2.*kind_version 3"):
        run_scene(scene, store, progress=False)
