"""Study scenes (issue 6): parsing, store, fallback, observed order, honest tolerances, report.

The default tests run a tiny stiffness-kind scene end to end (synchronous scheduler, a few
seconds); the honest-tolerance check over the whole agreement registry is ``slow``.
"""

from __future__ import annotations

import math
import tomllib

import numpy as np
import pytest

import solver
from cases import AGREEMENT_CASES, by_name
from pipeline import SceneError, StoreMismatch, load_scene, parse_scene, run_scene
from pipeline.__main__ import main, quick_variant
from pipeline._study import NO_ANSWER, apply_fallback, solver_norm_errors
from pipeline_cases import REPO, write_scene
from reports._read import open_scene_store
from reports._study import fitted_order, honesty_records, honesty_summary

WORKFLOWS = REPO / "workflows"

#: Two cheap, non-stiff motions; a delta scan of two values; both methods at two tolerances.
TINY = """
[scene]
kind = "stiffness"
name = "tiny_study"

[solver]
methods = ["periodic", "march"]
rtols = [1e-3, 1e-6]
fallback = "periodic"

[reference]
check_steps = 32768

[base]
anisotropy_ratio = "2^-3"
scaled_period = 1.0

[[motions]]
name = "harmonic"
family = "harmonic"
A0 = 1.0
A1 = 0.5

[[motions]]
name = "burst"
family = "powerlaw"
A0 = 1.2
A1 = 0.35
duty_cycle = 0.8
closing_shape = "down:10"
opening_shape = "up:3"

[[scans]]
parameter = "delta"
values = [1e-3, 1e-7]

[[scans]]
parameter = "exponent"
values = [3.0]

[execution]
points_per_task = 2
"""


def _edit(old, new, text=TINY):
    assert old in text, old
    return text.replace(old, new, 1)


# ---------------------------------------------------------------------------
# Scenes
# ---------------------------------------------------------------------------


def test_shipped_study_scenes_and_quick_variants_parse():
    for name in ("accuracy", "stiffness"):
        full, quick = load_scene(WORKFLOWS / f"{name}.toml"), quick_variant(WORKFLOWS / f"{name}.toml")
        assert full.kind == quick.kind == name
        assert 0 < quick.n_points <= full.n_points and quick.hash != full.hash


def test_stiffness_points_are_every_applicable_motion_times_every_value():
    doc = tomllib.loads((WORKFLOWS / "stiffness.toml").read_text())
    powerlaw_only = {"exponent", "duty_cycle"}
    families = [m["family"] for m in doc["motions"]]
    expected = 0
    for sw in doc["scans"]:
        if "values" in sw:
            n_values = len(sw["values"])
        else:
            (a, b), = [v for k, v in sw.items() if k.endswith("range")]
            n_values = int(abs(b - a) / sw["step"] + 1e-9) + 1
        n_motions = sum(f == "powerlaw" for f in families) if sw["parameter"] in powerlaw_only else len(families)
        expected += n_values * n_motions
    assert load_scene(WORKFLOWS / "stiffness.toml").n_points == expected


def test_accuracy_cases_are_the_registry_cases():
    """The scene file repeats tests/cases.py's parameters: same kinematics and physics."""
    scene = load_scene(WORKFLOWS / "accuracy.toml")
    for case in scene.motions:
        ref = by_name(case.name)
        code, params = case.kinematics().kernel_encoding()
        ref_code, ref_params = ref.kinematics.kernel_encoding()
        assert code == ref_code
        np.testing.assert_allclose(params, ref_params, rtol=1e-14, err_msg=case.name)
        for attr in ("mu_n", "mu_s", "period", "p", "delta_tau"):
            np.testing.assert_allclose(getattr(case.physics(), attr), getattr(ref.physics, attr), rtol=1e-14,
                                       err_msg=f"{case.name}: {attr}")


def test_the_accuracy_case_set_covers_the_issue():
    scene = load_scene(WORKFLOWS / "accuracy.toml")
    families = {m.family for m in scene.motions}
    assert families == {"harmonic", "powerlaw", "fourier"}
    assert {0.0, 0.5, 1.5} <= {m.p for m in scene.motions}
    assert {2.0 ** -8, 2.0 ** 8} <= {m.anisotropy_ratio for m in scene.motions}
    assert any(m.family == "powerlaw" and abs(m.value("closing_shape")) == 10 for m in scene.motions)


BAD = [
    pytest.param(('kind = "stiffness"', 'kind = "precision"'), "scene.kind", "must be one of", id="unknown-kind"),
    pytest.param(("[solver]", "[solver]\nspeed = 3"), "solver.speed", "unknown key", id="unknown-key"),
    pytest.param(("rtols = [1e-3, 1e-6]", "rtols = [1e-3, 0.5]"), "solver.rtols", "(0, 0.1]", id="rtol-range"),
    pytest.param(('fallback = "periodic"', 'fallback = "lsoda"'), "solver.fallback", "must be one of",
                 id="fallback"),
    pytest.param(('parameter = "delta"', 'parameter = "colour"'), "scans[0].parameter", "must be one of",
                 id="scan-parameter"),
    pytest.param(("values = [1e-3, 1e-7]", "values = [1e-3, -1.0]"), "scans[0].values", "outside the domain",
                 id="scan-domain"),
    pytest.param(('closing_shape = "down:10"', 'closing_shape = "sideways:10"'), "motions[1].closing_shape",
                 "up:g", id="shape"),
    pytest.param(("duty_cycle = 0.8", "duty_cycle = 1.5"), "motions[1].duty_cycle", "(0, 1)", id="duty"),
    pytest.param(("A1 = 0.5", "A1 = 0.5\nB = [0.1]"), "motions[0].B", "not a parameter of family", id="family-key"),
    pytest.param(('anisotropy_ratio = "2^-3"\n', ""), "motions[0].anisotropy_ratio", "missing", id="missing"),
    pytest.param(("[[scans]]\nparameter = \"exponent\"\nvalues = [3.0]\n", "[cases]\nx = 1\n"), "cases",
                 "not used by a 'stiffness' scene", id="wrong-table"),
]


@pytest.mark.parametrize("edit,key,words", BAD)
def test_bad_study_scene_names_the_key(edit, key, words):
    with pytest.raises(SceneError) as info:
        parse_scene(_edit(*edit), "bad.toml")
    assert info.value.key == key and words in info.value.reason, str(info.value)
    assert "\n" not in str(info.value)


def test_bad_study_scene_exits_2_and_writes_nothing(tmp_path, capsys):
    path = write_scene(tmp_path, _edit('fallback = "periodic"', 'fallback = "lsoda"'), "bad.toml")
    store = tmp_path / "bad.zarr"
    assert main(["run", str(path), "--store", str(store), "--scheduler", "synchronous"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "solver.fallback" in err[0]
    assert not store.exists()


def test_a_study_with_the_old_sweeps_key_is_refused_naming_scans(tmp_path, capsys):
    """Issue 37: a study's ``[[sweeps]]`` became ``[[scans]]`` ("sweep" is a warm-start chain of
    points); a scene still using it gets one line naming the new key, exit 2, no store."""
    old = TINY.replace("[[scans]]", "[[sweeps]]")
    with pytest.raises(SceneError) as info:
        parse_scene(old, "old.toml")
    assert info.value.key == "sweeps" and "[[scans]]" in info.value.reason
    path = write_scene(tmp_path, old, "old.toml")
    store = tmp_path / "old.zarr"
    assert main(["run", str(path), "--store", str(store), "--scheduler", "synchronous"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "sweeps" in err[0] and "[[scans]]" in err[0], err
    assert not store.exists()
    # negative control: the same scene with the new key parses
    assert parse_scene(TINY, "new.toml").scans


# ---------------------------------------------------------------------------
# Small reductions against brute force
# ---------------------------------------------------------------------------


def test_fitted_order_recovers_a_power_law_and_ignores_the_floor():
    rng = np.random.default_rng(1)
    n = 2.0 ** np.arange(4, 12)
    for k in (1.0, 2.0, 3.0):
        e = 5.0 * n ** -k * np.exp(0.01 * rng.standard_normal(n.size))
        assert abs(fitted_order(n, e) - k) < 0.05
        floored = np.maximum(e, 1e-9)  # a reference floor must not flatten the fit
        assert abs(fitted_order(n, floored, floor=1.1e-9) - k) < 0.05
    assert math.isnan(fitted_order(n[:2], n[:2] ** -2.0))


def test_honesty_summary_matches_a_brute_force_count():
    rng = np.random.default_rng(2)
    records = [{"status": int(rng.choice([0, 0, 0, 5])), "trusted": bool(rng.random() < 0.9),
                "true_error": float(10 ** rng.uniform(-9, -3)), "rtol": 1e-5} for _ in range(400)]
    for r in records:
        r["ratio"] = r["true_error"] / r["rtol"]
    s = honesty_summary(records)
    judged = [r for r in records if r["status"] == 0 and r["trusted"]]
    assert s["judged"] == len(judged)
    assert s["within"] == sum(r["true_error"] <= r["rtol"] for r in judged)
    assert s["within10"] == sum(r["true_error"] <= 10 * r["rtol"] for r in judged)
    assert [r["ratio"] for r in s["exceptions"]] == sorted((r["ratio"] for r in judged if r["ratio"] > 1),
                                                            reverse=True)


def test_fallback_keeps_own_answer_else_the_fallback_method_else_none():
    scene = parse_scene(TINY, "tiny.toml")  # methods (periodic, march), fallback periodic
    status = np.array([[0, 0], [5, 0]])  # march failed at the first rtol only
    v = {"status": status, "U": np.array([[1.0, 2.0], [np.nan, 4.0]]), "P": np.ones((2, 2)),
         "true_error": np.array([[1e-4, 1e-7], [np.nan, 1e-7]])}
    out = apply_fallback(scene, v)
    np.testing.assert_array_equal(out["used_method"], [[0, 0], [0, 1]])
    np.testing.assert_array_equal(out["U_used"], [[1.0, 2.0], [1.0, 4.0]])
    v["status"] = np.array([[6, 0], [5, 0]])  # neither converged at the first rtol
    out = apply_fallback(scene, v)
    assert out["used_method"][0, 0] == out["used_method"][1, 0] == NO_ANSWER
    assert np.isnan(out["U_used"][:, 0]).all()


def test_solver_norm_errors_use_the_u_floor():
    e_u, e_p = solver_norm_errors([1e-9], [2.0], [0.0], [1.0], period=2.0, vscale=1.0)
    # U_ref = 0: the error is relative to 1e-3 V, not to |U_ref|
    np.testing.assert_allclose(e_u, 2e-9 / 1e-3)
    np.testing.assert_allclose(e_p, 1.0)


# ---------------------------------------------------------------------------
# End to end on the tiny scene
# ---------------------------------------------------------------------------


@pytest.fixture(scope="module")
def tiny(tmp_path_factory):
    tmp = tmp_path_factory.mktemp("study")
    scene = parse_scene(TINY, str(tmp / "tiny.toml"))
    store = tmp / "tiny.zarr"
    summary = run_scene(scene, store, scheduler="synchronous", progress=False)
    return scene, store, summary


def test_tiny_study_store_is_labelled_and_complete(tiny):
    xr = pytest.importorskip("xarray")
    scene, store, summary = tiny
    assert summary.computed_points == scene.n_points == 5  # 2 motions x 2 deltas + 1 power law x 1 exponent
    ds = xr.open_zarr(store)
    assert ds["true_error"].dims == ("point", "method", "rtol")
    from pipeline import decode_attrs

    assert decode_attrs(ds["method"].attrs)["labels"] == ["periodic", "march"]
    np.testing.assert_allclose(ds["rtol"].values, [1e-3, 1e-6])
    assert (ds["status"].values >= 0).all() and (ds["ref_status"].values == 0).all()
    np.testing.assert_allclose(sorted(set(ds["delta"].values[ds["scan"].values == 0])), [1e-7, 1e-3])
    # the stored true error is the brute-force max of the two solver-norm errors
    U, P = ds["U"].values, ds["P"].values
    T, V = ds["period"].values[:, None, None], ds["kinematic_speed"].values[:, None, None]
    U_ref, P_ref = ds["U_ref"].values[:, None, None], ds["P_ref"].values[:, None, None]
    brute = np.maximum(np.abs(U - U_ref) * T / np.maximum(np.abs(U_ref) * T, 1e-3 * V), np.abs(P - P_ref) / P_ref)
    np.testing.assert_allclose(ds["true_error"].values, brute, rtol=1e-12)
    assert (ds["seconds"].values > 0).all()


def test_tiny_study_store_exports_to_netcdf(tiny, tmp_path):
    """Issue 34: a stiffness store exports as it is (``xarray.open_zarr(store).to_netcdf``) and
    through ``pipeline.to_netcdf``; both read back equal."""
    from pipeline_cases import assert_exports_to_netcdf

    assert_exports_to_netcdf(tiny[1], tmp_path)


#: The smallest accuracy scene with every array of its kind: two methods, one rtol, two fixed
#: grids, one LSODA baseline tolerance, one case (a few seconds).
TINY_ACCURACY = """
[scene]
kind = "accuracy"
name = "tiny_accuracy"

[solver]
methods = ["periodic", "march"]
rtols = [1e-3]
fixed_steps = [32, 64]

[reference]
rtol_factor = 1e-2
check = "march"
check_rtol = 1e-6
check_steps = 4096

[baseline]
tolerances = [1e-3]
cap_seconds = 5.0

[[cases]]
name = "harmonic"
family = "harmonic"
A0 = 1.0
A1 = 0.5
anisotropy_ratio = "2^-3"
scaled_period = 1.0
"""


def test_tiny_accuracy_store_exports_to_netcdf(tmp_path):
    """Issue 34: an accuracy store (fixed grids and the baseline: the arrays a stiffness store
    lacks) exports as it is and through ``pipeline.to_netcdf``; both read back equal."""
    from pipeline_cases import assert_exports_to_netcdf

    store = tmp_path / "tiny_accuracy.zarr"
    run_scene(parse_scene(TINY_ACCURACY, str(tmp_path / "tiny_accuracy.toml")), store, scheduler="synchronous",
              progress=False)
    assert {"fixed_U", "baseline_U", "n_steps", "baseline_tol"} <= set(xr_open(store).variables)
    assert_exports_to_netcdf(store, tmp_path)


def xr_open(store):
    import warnings

    import xarray as xr

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return xr.open_zarr(str(store), zarr_format=3, consolidated=False)


def test_tiny_study_rerun_resume_and_refusal(tiny):
    import zarr

    scene, store, _ = tiny
    again = run_scene(scene, store, scheduler="synchronous", progress=False)
    assert again.computed_points == 0
    before = open_scene_store(store).ds["U_ref"].values.copy()
    zarr.open_array(store=str(store), path="pipeline_state/chunk_done", mode="r+")[1] = 0  # as if killed
    resumed = run_scene(scene, store, scheduler="synchronous", progress=False)
    assert resumed.computed_chunks == 1 and resumed.computed_points == 2
    np.testing.assert_allclose(open_scene_store(store).ds["U_ref"].values, before, rtol=1e-12)
    other = parse_scene(_edit("values = [1e-3, 1e-7]", "values = [1e-3, 1e-8]"), "other.toml")
    with pytest.raises(StoreMismatch):
        run_scene(other, store, scheduler="synchronous", progress=False)


def test_tiny_study_tolerances_are_honest(tiny):
    """The issue's targets on a small sample: >= 99 % within rtol, all within 10 rtol."""
    _, store, _ = tiny
    s = honesty_summary(honesty_records(open_scene_store(store)))
    assert s["judged"] >= 10
    assert s["fraction_within"] >= 0.99, s["exceptions"]
    assert s["fraction_within10"] == 1.0, s["exceptions"]


def test_tiny_study_report_has_its_sections(tiny, tmp_path):
    from reports import build_report

    _, store, _ = tiny
    index = build_report([store], tmp_path / "report", list_unrun=False)
    text = index.read_text()
    assert "panel failed" not in text
    for words in ("Scan of delta", "U and P against δ", "Honest tolerances over every study", "log10(seconds)"):
        assert words in text, words


# ---------------------------------------------------------------------------
# Slow: the registry at three tolerances
# ---------------------------------------------------------------------------


#: (case, rtol) where the march gives up on a case not marked stiff: UNSTABLE (sticking its
#: uniform grids cannot resolve within max_steps_per_period, ~10^6 steps a period) or
#: TOLERANCE_NOT_REACHED (harmonic_isotropic at 1e-7: more than 2^17 uniform steps)
MARCH_GIVES_UP = {(name, rtol) for name in ("harmonic_low_ratio", "harmonic_high_ratio")
                  for rtol in (1e-3, 1e-5, 1e-7)} | {("harmonic_isotropic", 1e-7)}
#: (case, rtol) whose reference neither the march at 1e-8 (TOLERANCE_NOT_REACHED on its
#: uniform grids) nor the engine's uniform 2^17-step grid (a stop inside a step) confirms to
#: 0.1 rtol
UNCONFIRMED = {("harmonic_short_period", 1e-7)}
REGISTRY_RTOLS = (1e-3, 1e-5, 1e-7)


@pytest.fixture(scope="module")
def registry_references():
    """Per agreement case: the periodic reference at rtol 1e-10 and its disagreement with an
    independent check, the explicit march at rtol 1e-8 (or, where the march fails, a uniform
    2^17-step periodic grid, which does not use the error control under test)."""
    refs = {}
    for case in AGREEMENT_CASES:
        ref = solver.solve_periodic(case.kinematics, case.physics, rtol=1e-10)
        assert ref.converged[0], case.name
        T, p = case.physics.period, case.physics.p
        V = solver.kinematic_speed(case.kinematics)
        march = solver.solve_periodic(case.kinematics, case.physics, method="march", rtol=1e-8)
        if march.converged[0]:
            U, P = march.U, march.P
        else:
            iu, ip, _ = solver.solve_fixed_grid(case.kinematics, case.physics, 2 ** 17)
            U, P = iu / T, ip * T ** -(p + 1)
        refs[case.name] = (ref, max(*solver_norm_errors(U, P, ref.U, ref.P, T, V))[0])
    return refs


@pytest.mark.slow
@pytest.mark.parametrize("method", ["periodic", "march"])
def test_registry_tolerances_are_honest(method, registry_references):
    """Every agreement case at rtol 1e-3, 1e-5, 1e-7 against its confirmed reference: >= 99 %
    within rtol, all within 10 rtol.  The march may give up (UNSTABLE, NaN) only on stiff cases
    and the listed ones, and never converges to a wrong answer; a reference that is not
    confirmed must be listed."""
    from solver.status import TOLERANCE_NOT_REACHED, UNSTABLE
    ratios, unconfirmed = [], set()
    for case in AGREEMENT_CASES:
        ref, check = registry_references[case.name]
        T, V = case.physics.period, solver.kinematic_speed(case.kinematics)
        for rtol in REGISTRY_RTOLS:
            if not check <= 0.1 * rtol:
                unconfirmed.add((case.name, rtol))
                continue
            r = solver.solve_periodic(case.kinematics, case.physics, method=method, rtol=rtol)
            if r.status[0] != 0:
                gives_up = method == "march" and r.status[0] in (
                    UNSTABLE, TOLERANCE_NOT_REACHED) and (
                    case.stiff or (case.name, rtol) in MARCH_GIVES_UP)
                assert gives_up and np.isnan(r.U[0]), (case.name, method, rtol, r.status[0])
                continue
            ratios.append((max(*solver_norm_errors(r.U, r.P, ref.U, ref.P, T, V))[0] / rtol,
                           case.name, rtol))
    assert unconfirmed == UNCONFIRMED
    ratios = sorted(ratios, reverse=True)
    # (the march gives up on 7 of the 45 (case, rtol), MARCH_GIVES_UP, and on the stiff ones)
    assert len(ratios) >= (25 if method == "march" else 35)
    assert sum(x <= 1 for x, *_ in ratios) >= 0.99 * len(ratios), ratios[:5]
    assert ratios[0][0] <= 10, ratios[:5]


def _corner_error(make_kinematics, make_physics, rtol):
    """(error, estimate) of the solve at ``rtol`` against one at 1e-8, in the solver's norm."""
    kin, phys = make_kinematics(), make_physics()
    ref = solver.solve_periodic(kin, phys, rtol=1e-8)
    assert ref.converged[0]
    r = solver.solve_periodic(kin, phys, rtol=rtol)
    assert r.converged[0]
    error = max(*solver_norm_errors(r.U, r.P, ref.U, ref.P, phys.period,
                                    solver.kinematic_speed(kin)))[0]
    return error, r.error_estimate[0]


LAYER_CORNERS = {
    # long period, delta 4e-10, a concave-down exponent 14.5 opening: at tau0 u relaxes from
    # 0.024 to -0.066 across ~1e-5, inside the step of 1e-3 after the corner; the step's own
    # integral of u held the error (12.7 rtol, estimate 0.5) until the layers were checked
    "power_law_period_113": (
        lambda: solver.PowerLaw([0.5729944571272555], [0.009698383749602814],
                                [0.4888715012712118], [5.0], [False], [14.468630943676835],
                                [False]),
        lambda: solver.Physics.from_scaled(0.16643930643694074, 112.84102281785694, p=0.0,
                                           delta=4.39375774699564e-10), 1e-3),
    # scaled period 252: the layer after tau = 0 (u from -0.96 to 0.30) ran past two graded
    # steps of 5e-6 into the third, of 9e-4 (17 rtol off with an estimate of 0.59; checking
    # only the step at the corner missed it)
    "power_law_period_252": (
        lambda: solver.PowerLaw([0.5422889370353403], [0.34140724221702023],
                                [0.6048193336661466], [1.876049754123788], [True],
                                [5.424089580451751], [True]),
        lambda: solver.Physics.from_scaled(0.27948214934672316, 251.56749633738875, p=0.0,
                                           delta=9.376140128130683e-06), 1e-3),
    # mu_n/mu_s 4096, scaled period 256, duty cycle 0.98, delta 1e-10: after tau = 0 the body
    # slides to a stop from u = 63; a stage stuck on a spurious root ended a step at 0 where
    # u is 1.8, and the next step lost the triangle of u before the stop (48 rtol at rtol
    # 1e-5, estimate 0.5): node weights, linear, put 3e-9 on that jump; the layer steps are
    # now re-solved as one stretch
    "power_law_ratio_4096": (
        lambda: solver.PowerLaw([1.7100829676153415], [1.0582892307610547], [0.98], [2.0],
                                [False], [7.104806611669263], [True]),
        lambda: solver.Physics.from_scaled(4096.0, 256.0, p=0.0, delta=1e-10), 1e-5),
    # scaled period 1.5, delta 1e-10: not a layer.  The last step of the period, 0.93 after
    # tau0, ends on a stage stuck on a spurious root at the corner tau = 1 where u is 1.7e-4;
    # searched for without a reach, it was taken for a layer step of tau0 (whose re-solve,
    # from its start, found the same root) and its turning-point defect, 2 rtol, went
    # unchecked (1.9 rtol off at rtol 1e-3, estimate 0.26)
    "power_law_stiff_step_far_from_a_corner": (
        lambda: solver.PowerLaw([0.9734623155876645], [0.7278156856060383],
                                [0.07203838584882997], [1.0337781887706494], [True],
                                [1.177254893753447], [False]),
        lambda: solver.Physics.from_scaled(2.3197710449955125, 1.5082467400265551, p=0.0,
                                           delta=1e-10), 1e-3),
}


@pytest.mark.parametrize("name", sorted(LAYER_CORNERS))
def test_layer_after_a_corner_is_counted(name):
    rtol = LAYER_CORNERS[name][2]
    error, estimate = _corner_error(*LAYER_CORNERS[name])
    assert error <= rtol, (error / rtol, estimate / rtol)


def test_small_defect_of_a_trapped_step_is_counted():
    """Scaled period 2^-6.6, mu_n/mu_s 2.28, delta 1e-8: the grids held the body near rest
    (u 9e-9) on the turning point tau = 0, where the march (1.2e-8 off the reference) passes
    at 2.3e-6.  The trapped step's defect, 3.3e-9, lay below the stage Newton's tolerance
    (1e-5 rtol V) and was dropped as its residual, though the node weight there is ~800
    (1 - M = 0.0013): U came back 4.8 rtol off with an estimate of 0.05 rtol.  The check now
    takes the Radau rule's quadrature error, which holds no residual, and drops only
    rounding.  Over 400 harmonic points at scaled periods 2^-7 .. 2^-4 the worst error went
    from 4.8 / 3.6 / 5.5 rtol to 0.7 / 0.7 / 1.3 at rtol 1e-3 / 1e-4 / 1e-5."""
    rtol = 1e-3
    error, estimate = _corner_error(
        lambda: solver.Harmonic([0.5546995905924383], [0.5041999022586156]),
        lambda: solver.Physics.from_scaled(2.2820271756188646, 0.010284882160836057, p=0.0,
                                           delta=1e-8), rtol)
    assert error <= min(estimate, rtol), (error / rtol, estimate / rtol)


def test_trapped_turning_point_at_short_period_is_seen():
    """Scaled period 2^-6, mu_n/mu_s 35.6: both grids of a 46/92-step pair held the body at
    rest on the turning point tau = 0 (u 1e-9 where the solution passes at 5.1e-5), and
    returned U = -0.00522 against -0.00197 (40 rtol) with an estimate of 0.58 rtol.  The
    turning-point check saw the step's defect (1.2e-7) but weighed it with the discrete
    node weight, 1.5, whose 1 - M = 0.68 held the trapped stage's artificial damping; with
    the step's resolved factor (``_turning._resolved_weights``) 1 - M is 0.0017 and the
    weight 587 (56 rtol against the 40 measured)."""
    rtol = 1e-3
    error, estimate = _corner_error(
        lambda: solver.Harmonic([1.4155637231239202], [1.2780034635235935]),
        lambda: solver.Physics.from_scaled(35.62197050907245, 2 ** -6, p=0.0,
                                           delta=2.710072671165811e-06), rtol)
    assert error <= min(estimate, rtol), (error / rtol, estimate / rtol)


def test_march_reports_unstable_on_burst_and_coast_at_high_anisotropy():
    """The explicit march cannot resolve this point's sticking within its budget: it must say
    so (UNSTABLE, NaN outputs), not return a number with a small estimate (before the chatter
    check it returned status 0 with an estimate far below its true error).  A march that
    learns to converge here must then be checked against a reference."""
    from solver.status import UNSTABLE
    kin = solver.PowerLaw(1.2, 0.35, 0.8, 10.0, False, 3.0, True)
    phys = solver.Physics.from_scaled(64.0, 2.0, p=0.0, delta=1e-5)
    r = solver.solve_periodic(kin, phys, method="march", rtol=1e-4)
    assert r.status[0] == UNSTABLE, solver.STATUS_REASONS[int(r.status[0])]
    assert np.isnan(r.U[0]) and np.isnan(r.P[0]) and not r.converged[0]


# Short scaled periods next to turning points of phi (found in session 4 by a sweep of
# scaled periods 2^-4 .. 2^-1, anisotropy 2^-8 .. 2^2: 82 / 86 / 94.5 % of 400 harmonic points
# within rtol at rtol 1e-3 / 1e-4 / 1e-5, worst ~1000 rtol, all with status 0).  Both grids of
# a pair held the body at rest on the turning point, so their comparison could not see it;
# ``solver._turning`` checks those steps.  Point A returned U = -0.02308 (true -0.015694) at
# rtol 1e-3, point B 3.0777e-4 (true 2.5877e-4) at rtol 1e-5 (the former order-3 engine).
# The reference is scipy's LSODA, an independent method.
TURNING_POINT_CASES = {
    "A": (solver.Harmonic(1.059879, 0.540691),
          solver.Physics.from_scaled(0.119099, 0.088041, p=0.0, delta=1e-8)),
    "B": (solver.Harmonic(1.253558, 0.846783),
          solver.Physics.from_scaled(1.625502, 0.141141, p=0.0, delta=1e-8)),
}


#: the march as a reference at short scaled periods: its uniform grids need more steps there
#: than the default budget (2^17) at rtol 1e-6
MARCH_REFERENCE_STEPS = 2 ** 20
#: the LSODA reference's own error in the solver's norm at tol 1e-10 on the turning-point
#: cases (against the engine at rtol 1e-10: 6.1e-7 and 9.1e-7), allowed on top of rtol
LSODA_REFERENCE_ERROR = 2e-6


@pytest.mark.parametrize("name", sorted(TURNING_POINT_CASES))
def test_periodic_is_honest_at_short_scaled_period_next_to_turning_points(name):
    """Against scipy's LSODA marching period by period at tol 1e-10 (``solver.tools.bench``'s
    baseline), independent of the engine; the march, which served before, cannot resolve
    the turning point's window on uniform grids (point B: TOLERANCE_NOT_REACHED at rtol 1e-5
    on 2^21 steps)."""
    from solver.tools import bench

    kin, phys = TURNING_POINT_CASES[name]
    V = solver.kinematic_speed(kin)
    U_ref, P_ref, _, _ = bench.baseline_point(bench.family_angle(kin), phys.mu_n[0],
                                              phys.mu_s[0], 0.0, phys.period[0],
                                              phys.delta_tau[0], V[0], 1e-10, 120.0)
    for rtol in (1e-3, 1e-4, 1e-5):
        r = solver.solve_periodic(kin, phys, rtol=rtol)
        error = max(*solver_norm_errors(r.U, r.P, np.array([U_ref]), np.array([P_ref]),
                                        phys.period, V))[0]
        assert r.status[0] == 0 and error <= rtol + LSODA_REFERENCE_ERROR, (
            f"rtol {rtol}: status {r.status[0]}, estimate {r.error_estimate[0]:.2g}, true {error:.2g}")


@pytest.mark.slow
def test_periodic_is_honest_on_a_sweep_of_short_scaled_periods():
    rng = np.random.default_rng(11)
    n = 120
    A0 = rng.uniform(0.3, np.pi / 2, n)
    kin = solver.Harmonic(A0, A0 * rng.uniform(0.2, 0.95, n))
    phys = solver.Physics.from_scaled(2.0 ** rng.uniform(-8, 2, n), 2.0 ** rng.uniform(-4, -1, n),
                                      p=0.0, delta=rng.choice([1e-5, 1e-8], n))
    ref = solver.solve_periodic(kin, phys, rtol=1e-9)
    assert ref.converged.all()
    V = solver.kinematic_speed(kin)
    # the reference, by the method under test, against the march on every tenth point
    some = np.arange(0, n, 10)
    march = solver.solve_periodic(kin.take(some), phys.take(some), method="march", rtol=1e-6,
                                  max_steps_per_period=MARCH_REFERENCE_STEPS)
    assert march.converged.all()
    check = np.maximum(*solver_norm_errors(march.U, march.P, ref.U[some], ref.P[some],
                                           phys.period[some], V[some]))
    assert check.max() <= 1e-5, check
    for rtol in (1e-3, 1e-5):
        r = solver.solve_periodic(kin, phys, rtol=rtol)
        assert r.converged.all()
        ratio = np.maximum(*solver_norm_errors(r.U, r.P, ref.U, ref.P, phys.period, V)) / rtol
        assert np.mean(ratio <= 1) >= 0.95 and ratio.max() <= 10, (rtol, np.sort(ratio)[-5:])


def test_status_map_has_a_colour_for_every_status_code():
    from reports._study import STATUS_COLORS
    assert len(STATUS_COLORS) == max(solver.STATUS_REASONS) + 1
    assert sorted(solver.STATUS_REASONS) == list(range(len(STATUS_COLORS)))


def test_pairs_that_disagree_beyond_the_answer_are_bisected_once():
    """mu_n/mu_s 0.0035, scaled period 0.156, exponents 12.4 and 10.3, delta 1e-10 (a
    400-point stress sweep at mu_n/mu_s 2^-12 .. 2^12): at rtol 1e-3 coarse pairs with
    spurious discrete solutions disagreed by 1e68 .. 1e242 times the answer, their steps were
    split 16-fold where marked, and the solve took 79,564 steps where rtol 1e-5 took ~1,000.
    Such pairs are now bisected once (13,284 steps measured), and the answer is honest."""
    kin = solver.PowerLaw([1.7101549133764915], [0.9994489879778728], [0.6784272143095593],
                          [12.403227782423754], [False], [10.296832823298375], [False])
    phys = solver.Physics.from_scaled(0.0035091081423200957, 0.15592301247464194, p=0.0,
                                      delta=1e-10)
    ref = solver.solve_periodic(kin, phys, rtol=1e-6)
    res = solver.solve_periodic(kin, phys, rtol=1e-3)
    assert ref.converged[0] and res.converged[0]
    assert res.n_tau[0] < 40_000, res.n_tau[0]
    error = max(*solver_norm_errors(res.U, res.P, ref.U, ref.P, phys.period,
                                    solver.kinematic_speed(kin)))[0]
    assert error <= 1e-3
