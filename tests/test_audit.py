"""The reproduction audit: the claim registry, the reductions computing our values (against
brute-force numpy on small synthetic stores), the verdicts and audit.json.

The synthetic stores here are labelled datasets built in memory with the pipeline's naming
convention (``<reduction>``, ``<reduction>_polished``, ``<reduction>_polished_<axis>``, optima
``optimum_*``), so the verdict logic is exercised end to end without running a solver.
"""

from __future__ import annotations

import json
import math
import re
import tomllib
from pathlib import Path

import numpy as np
import pytest
import xarray as xr

from reports._audit import CLAIMS_FILE, VERDICTS, Claim, evaluate_claims, load_claims, verdict, write_audit_json
from reports._claim_values import COMPUTE, Measurement, gain, monotone, stat
from reports._paper import load_figures
from reports._read import SceneStore

REPO = Path(__file__).resolve().parent.parent
WORKFLOWS = REPO / "workflows"
PAPER = REPO.parent / "shared" / "paper" / "intermittent_sliding_two_link.tex"


# ---------------------------------------------------------------------------
# The registry
# ---------------------------------------------------------------------------


def _scenes() -> dict:
    return {tomllib.loads(f.read_text())["scene"]["name"]: tomllib.loads(f.read_text())
            for f in WORKFLOWS.glob("*.toml")}


def _dims_and_roles(doc: dict):
    """(dimensions a claim may select on, {reduction: roles}, stored quantities) of a scene file."""
    head = doc["scene"]
    if head.get("kind") == "optima":
        return {"anisotropy_ratio", "max_wavenumber", "p"}, {}, set()
    dims = set(doc["axes"])
    roles, extra_dims = {}, set()
    for r in doc.get("reductions", []):
        roles[r["name"]] = {"value", "signed", *r["over"], *r.get("report", [])}
        if {"closing_shape", "opening_shape"} <= set(r["over"]):
            roles[r["name"]].add("linear_shapes")
        if "window" in r:
            extra_dims.add(f"{r['window']['axis']}_halfwidth")
        if "exponent_sets" in r:
            extra_dims.add("exponent_set")
    outputs = set(doc.get("outputs", {}).get("quantities", []))
    return dims | extra_dims, roles, outputs


def _sources(claim: Claim):
    if claim.compute == "gain":
        return [claim.args["numerator"], claim.args["denominator"]]
    return [claim.args]


def test_registry_parses_with_enough_claims_on_every_results_section():
    claims = load_claims()
    assert len(claims) >= 15
    assert len({c.id for c in claims}) == len(claims)
    labels = [f.label for f in load_figures()]
    assert all(c.figure in labels for c in claims)
    # claims on harmonic, power-law, Fourier and other-power-law figures alike
    for group in (("EtaA0A1", "UPEtaDiag1", "UPEtaDiag2", "UEtaMax"),
                  ("EtaVsMint0", "UOptt0", "EtaOptt0", "EtaVsMinGamma", "EtaOptAllParams"),
                  ("OptMotionsLowMun", "OptMotionsHighMun"), ("OptMotionsp0p5", "OptMotionsp1", "OptMotionsp1p5")):
        assert sum(c.figure in group for c in claims) >= 4, group


def test_registry_names_existing_scenes_reductions_roles_and_dimensions():
    scenes = _scenes()
    for c in load_claims():
        assert c.compute in COMPUTE, c.id
        for src in _sources(c):
            assert src["scene"] in scenes, (c.id, src["scene"])
            dims, roles, outputs = _dims_and_roles(scenes[src["scene"]])
            if "reduction" in src:
                assert src["reduction"] in roles, (c.id, src["reduction"])
                assert src.get("role", "value") in roles[src["reduction"]], (c.id, src.get("role"))
            elif "quantity" in src:
                assert src["quantity"] in outputs, (c.id, src["quantity"])
            else:
                assert src.get("role") in ("relative_efficiency", "scaled_period", "phi_max", "phi_min",
                                           "distinct"), c.id
            named = set(src.get("at", {})) | set(src.get("ranges", {})) | set(src.get("peak_over", []))
            named |= {d for cell in src.get("cells", []) + src.get("exclude", []) for d in cell}
            for key in ("location", "location_along", "along"):
                if key in src:
                    named.add(src[key])
            assert named <= dims, (c.id, named - dims)


def test_figures_follow_the_papers_label_order():
    if not PAPER.is_file():
        pytest.skip(f"paper not found at {PAPER}")
    order = re.findall(r"\\label\{fig:([^}]+)\}", PAPER.read_text(encoding="utf-8"))
    assert [f.label for f in load_figures()] == order


def test_figure_views_name_shipped_scenes_and_every_figure_scene_has_a_view():
    scenes = _scenes()
    figures = load_figures()
    viewed = {v.scene for f in figures for v in f.views}
    assert viewed <= set(scenes)
    # scenes that exist for a cause check of the audit (claims.toml) need no figure view
    checks = {s for c in load_claims() if c.cause for s in _cause_scenes(c.cause)} - viewed
    for name, doc in scenes.items():
        head = doc["scene"]
        if head.get("kind") in ("accuracy", "stiffness") or name == "quick" or name in checks:
            continue
        assert name in viewed, name


@pytest.mark.parametrize("old, new, match", [
    ('compute = "stat"', 'compute = "no_such_reduction"', "unknown compute"),
    ("expect = { value = 1.8, tolerance = 0.05 }", "expect = { value = 1.8 }", "expect"),
    ('kind = "resolution"', 'kind = "bad luck"', "cause kind"),
    ('check = "subgrid_max"', 'check = "no_such_check"', "unknown cause check"),
])
def test_malformed_registry_is_refused(tmp_path, old, new, match):
    """A registry with an unknown reduction, an incomplete expectation, an unknown cause kind
    or cause check is refused with a message naming it."""
    from reports._audit import RegistryError

    good = CLAIMS_FILE.read_text(encoding="utf-8")
    assert old in good
    bad = tmp_path / "claims.toml"
    bad.write_text(good.replace(old, new, 1))
    with pytest.raises(RegistryError, match=match):
        load_claims(bad)


# ---------------------------------------------------------------------------
# Synthetic stores
# ---------------------------------------------------------------------------


def _store(name, ds, reductions=(), kind="grid", rtol=1e-4, science=None):
    meta = {"kind": kind, "provenance": {"scene_name": name}, "layout": {"dims": list(ds.dims)},
            "state": {"chunks_complete": True, "reductions_complete": True}}
    sc = {"reductions": list(reductions), "solver": {"rtol": rtol}, **(science or {})}
    return SceneStore(path=Path(f"/nonexistent/{name}.zarr"), meta=meta, ds=ds, science=sc)


def _grid_store(value, arg_a0, arg_ratio, grid_value=None):
    """A 'harmonic_grid'-like store: reduction best_efficiency over (A0, A1_ratio), polished,
    kept over the 3 x 3 (T2_mu_n, T2_mu_s) grid."""
    t = [0.0625, 1.0, 16.0]
    coords = {"T2_mu_n": t, "T2_mu_s": t, "A0": np.linspace(0.1, 1.5, 8), "A1_ratio": np.linspace(0.1, 0.9, 9)}
    dims = ("T2_mu_n", "T2_mu_s")
    grid_value = value * 0.99 if grid_value is None else grid_value
    ds = xr.Dataset({"best_efficiency": (dims, grid_value), "best_efficiency_polished": (dims, value),
                     "best_efficiency_polished_A0": (dims, arg_a0), "best_efficiency_polished_A1_ratio": (dims, arg_ratio),
                     "best_efficiency_A0": (dims, arg_a0), "best_efficiency_A1_ratio": (dims, arg_ratio)},
                    coords=coords)
    red = {"name": "best_efficiency", "quantity": "scaled_efficiency", "statistic": "absmax",
           "over": ["A0", "A1_ratio"]}
    return _store("harmonic_grid", ds, [red])


def _claim(expect, **args):
    return Claim(id="t", figure="EtaA0A1", claim="test", paper_value="p", expect=expect, compute="stat",
                 args={"scene": "harmonic_grid", "reduction": "best_efficiency", **args})


LOWER_RIGHT = {"T2_mu_n": 0.0625, "T2_mu_s": 16.0}


def test_verdicts_agrees_differs_and_not_run_are_all_reachable():
    v = np.full((3, 3), 0.5)
    v[0, 2] = 1.8
    inside = _grid_store(v, np.full((3, 3), 1.2), np.full((3, 3), 0.5))
    rows = evaluate_claims([_claim({"value": 1.8, "tolerance": 0.05}, at=LOWER_RIGHT),
                            _claim({"value": 2.5, "tolerance": 0.05}, at=LOWER_RIGHT),
                            _claim({"value": 1.8, "tolerance": 0.05}, at={"T2_mu_n": 0.5, "T2_mu_s": 16.0})],
                           [inside])
    assert [r.verdict for r in rows] == ["agrees", "differs", "not run"]
    assert "a difference in the data" in rows[1].reason and "0.65 beyond the tolerance" in rows[1].reason
    assert "no cell at T²μn = 2^-1" in rows[2].reason
    # a claim whose store is missing altogether
    missing = evaluate_claims([_claim({"value": 1.8, "tolerance": 0.05}, at=LOWER_RIGHT)], [])
    assert missing[0].verdict == "not run" and "no store of scene harmonic_grid" in missing[0].reason


def test_a_polished_optimum_on_the_domain_edge_is_named_as_the_reason():
    v = np.full((3, 3), 0.5)
    v[0, 2] = 1.92
    ratio = np.full((3, 3), 0.5)
    ratio[0, 2] = 0.1  # A1/A0 at the lower end of its scanned range
    rows = evaluate_claims([_claim({"value": 1.8, "tolerance": 0.05}, at=LOWER_RIGHT)],
                           [_grid_store(v, np.full((3, 3), 1.2), ratio)])
    assert rows[0].verdict == "differs"
    assert rows[0].reason.startswith("at the domain edge") and "A1/A0 at the lower end" in rows[0].reason
    assert "above the paper's value" in rows[0].reason


def test_a_polish_change_larger_than_the_miss_is_named_as_resolution():
    v = np.full((3, 3), 0.5)
    v[0, 2] = 1.9
    grid = v.copy()
    grid[0, 2] = 1.6  # polishing moved the optimum by 0.3 > miss 0.05
    rows = evaluate_claims([_claim({"value": 1.8, "tolerance": 0.05}, at=LOWER_RIGHT)],
                           [_grid_store(v, np.full((3, 3), 1.2), np.full((3, 3), 0.5), grid_value=grid)])
    assert rows[0].verdict == "differs" and "grid resolution coarser than the claim's precision" in rows[0].reason


def test_no_valid_value_differs_and_says_so():
    v = np.full((3, 3), np.nan)
    rows = evaluate_claims([_claim({"value": 1.8, "tolerance": 0.05}, at=LOWER_RIGHT)],
                           [_grid_store(v, v, v)])
    assert rows[0].verdict == "differs" and "no valid value" in rows[0].reason


@pytest.mark.parametrize("expect, value, ok", [
    ({"value": 1.0, "tolerance": 0.1}, 1.09, True), ({"value": 1.0, "tolerance": 0.1}, 1.11, False),
    ({"value": 1.5, "factor": 1.42}, 2.0, True), ({"value": 1.5, "factor": 1.42}, 2.2, False),
    ({"min": 0.5}, 0.5, True), ({"min": 0.5}, 0.49, False), ({"max": 0.3}, 0.2, True),
    ({"min": 1.1, "max": 1.6}, (1.2, 1.5), True), ({"min": 1.1, "max": 1.6}, (1.0, 1.5), False),
    ({"range": [0.03, 0.09], "tolerance": 0.01}, (0.035, 0.095), True),
    ({"range": [0.03, 0.09], "tolerance": 0.01}, (0.01, 0.09), False),
])
def test_verdict_of_each_kind_of_expectation(expect, value, ok):
    c = Claim(id="t", figure="EtaA0A1", claim="c", paper_value="p", expect=expect, compute="stat", args={})
    assert verdict(c, Measurement(value=value))[0] == ("agrees" if ok else "differs")


# ---------------------------------------------------------------------------
# Reductions against brute force
# ---------------------------------------------------------------------------


@pytest.fixture
def plane():
    """A store with a reduction kept over (anisotropy_ratio, scaled_period): random values."""
    rng = np.random.default_rng(7)
    ratios, periods = 2.0 ** np.arange(-4, 5), 2.0 ** np.arange(-3, 4)
    shape = (ratios.size, periods.size)
    value = rng.uniform(0.01, 1.0, shape)
    signed = value * rng.choice([-1, 1], shape)
    a0 = rng.uniform(0.0, 1.5708, shape)
    dims = ("anisotropy_ratio", "scaled_period")
    ds = xr.Dataset({"best": (dims, value * 0.98), "best_polished": (dims, value), "best_polished_signed": (dims, signed),
                     "best_polished_A0": (dims, a0), "best_A0": (dims, a0)},
                    coords={"anisotropy_ratio": ratios, "scaled_period": periods, "A0": np.linspace(0, 1.5708, 9)})
    red = {"name": "best", "quantity": "q", "statistic": "absmax", "over": ["A0"]}
    return {"plane": _store("plane", ds, [red])}, value, signed, a0, ratios, periods


def test_stat_reductions_match_brute_force(plane):
    stores, value, signed, a0, ratios, periods = plane
    low = ratios < 1
    m = stat(stores, scene="plane", reduction="best", statistic="max", ranges={"anisotropy_ratio": [0, 0.99]})
    assert m.value == value[low].max()
    m = stat(stores, scene="plane", reduction="best", statistic="min", location="anisotropy_ratio")
    assert m.value == ratios[np.unravel_index(np.argmin(value), value.shape)[0]]
    m = stat(stores, scene="plane", reduction="best", statistic="median", at={"scaled_period": "max"})
    assert m.value == pytest.approx(np.median(value[:, -1]))
    m = stat(stores, scene="plane", reduction="best", role="A0", statistic="range")
    assert m.value == (a0.min(), a0.max())
    m = stat(stores, scene="plane", reduction="best", role="signed", statistic="fraction", test={"max": 0.0})
    assert m.value == pytest.approx(np.mean(signed <= 0))
    m = stat(stores, scene="plane", reduction="best", statistic="fraction", test={"between": [0.2, 0.6]})
    assert m.value == pytest.approx(np.mean((value >= 0.2) & (value <= 0.6)))
    # the peak over periods, then the location of the best period per ratio
    m = stat(stores, scene="plane", reduction="best", peak_over=["scaled_period"], statistic="max")
    assert m.value == value.max()
    m = stat(stores, scene="plane", reduction="best", location_along="scaled_period", statistic="fraction",
             test={"max": 0.5})
    assert m.value == pytest.approx(np.mean(periods[np.argmax(value, axis=1)] <= 0.5))
    # cells stacked, and a cell excluded (not counted as a failure)
    m = stat(stores, scene="plane", reduction="best", statistic="max",
             cells=[{"anisotropy_ratio": 1.0}, {"anisotropy_ratio": 16.0}])
    assert m.value == max(value[4].max(), value[8].max())
    m = stat(stores, scene="plane", reduction="best", statistic="median", at={"scaled_period": 1.0},
             exclude=[{"anisotropy_ratio": "min"}])
    assert m.value == pytest.approx(np.median(value[1:, 3])) and m.failed == (0, ratios.size - 1)


def test_gain_and_monotone_match_brute_force(plane):
    stores, value, _, _, ratios, periods = plane
    m = gain(stores, statistic="range", numerator={"scene": "plane", "reduction": "best", "at": {"scaled_period": 8.0}},
             denominator={"scene": "plane", "reduction": "best", "at": {"scaled_period": 0.125}})
    r = value[:, -1] / value[:, 0]
    assert m.value == (pytest.approx(r.min()), pytest.approx(r.max()))
    m = gain(stores, numerator={"scene": "plane", "reduction": "best", "at": {"anisotropy_ratio": 1.0, "scaled_period": 1.0}},
             denominator={"scene": "plane", "reduction": "best", "statistic": "max"})
    assert m.value == pytest.approx(value[4, 3] / value.max())
    m = monotone(stores, scene="plane", reduction="best", along="scaled_period")
    steps = np.diff(value, axis=1)
    assert m.value == pytest.approx(np.mean(steps >= 0))
    m = monotone(stores, scene="plane", reduction="best", along="anisotropy_ratio", direction="decreasing")
    assert m.value == pytest.approx(np.mean(np.diff(value, axis=0) <= 0))


def test_optima_roles_and_cross_store_gain():
    rng = np.random.default_rng(3)
    ratios, kmax, tau = np.array([0.0625, 1.0, 16.0]), np.array([1, 3]), np.arange(16) / 16
    stores = {}
    for name, ps in (("fourier_optima", [0.0]), ("force_laws", [0.5, 1.0])):
        shape = (ratios.size, kmax.size, len(ps), 4)
        rel = -rng.uniform(0.01, 0.6, shape)
        phi = 0.8 + 0.5 * np.sin(2 * np.pi * tau)[None, None, None, None, :] * rng.uniform(0.5, 1, shape + (1,))
        start = np.where(np.arange(4) < 2, 0, -1) * np.ones(shape, int)
        d4 = ("anisotropy_ratio", "max_wavenumber", "p", "rank")
        ds = xr.Dataset({"optimum_relative_efficiency": (d4, rel), "optimum_scaled_period": (d4, -rel * 10),
                         "optimum_phi": (d4 + ("tau",), phi), "optimum_start": (d4, start)},
                        coords={"anisotropy_ratio": ratios, "max_wavenumber": kmax, "p": ps, "tau": tau})
        stores[name] = _store(name, ds, kind="optima", science={"optimizer": {"gtol": 1e-7, "grid_rtol": 1e-4},
                                                                 "starts": {"num": 4}})
    best = np.abs(stores["fourier_optima"].ds["optimum_relative_efficiency"].values[..., 0])
    m = stat(stores, scene="fourier_optima", role="relative_efficiency", at={"p": 0.0}, statistic="max",
             ranges={"anisotropy_ratio": [0, 0.99]})
    assert m.value == best[0, :, 0].max()
    phi = stores["fourier_optima"].ds["optimum_phi"].values[..., 0, :]
    m = stat(stores, scene="fourier_optima", role="phi_max", at={"p": 0.0, "max_wavenumber": 3}, statistic="range")
    assert m.value == (phi[:, 1, 0].max(axis=-1).min(), phi[:, 1, 0].max(axis=-1).max())
    m = stat(stores, scene="fourier_optima", role="distinct", at={"p": 0.0}, statistic="max")
    assert m.value == 2
    half = np.abs(stores["force_laws"].ds["optimum_relative_efficiency"].values[:, :, 0, 0])
    m = gain(stores, statistic="fraction", test={"max": 1.0},
             numerator={"scene": "force_laws", "role": "relative_efficiency", "at": {"p": 0.5}},
             denominator={"scene": "fourier_optima", "role": "relative_efficiency", "at": {"p": 0.0}})
    assert m.value == pytest.approx(np.mean(half / best[:, :, 0] <= 1))


# ---------------------------------------------------------------------------
# audit.json
# ---------------------------------------------------------------------------


def test_audit_json_has_one_object_per_claim_with_the_schema(tmp_path):
    v = np.full((3, 3), 0.5)
    v[0, 2] = 1.8
    rows = evaluate_claims(load_claims(), [_grid_store(v, np.full((3, 3), 1.2), np.full((3, 3), 0.5))])
    doc = json.loads(write_audit_json(rows, tmp_path / "audit.json").read_text())
    assert isinstance(doc, list) and len(doc) == len(load_claims())
    for obj in doc:
        for key in ("id", "claim", "paper_value", "our_value", "verdict", "reason", "figure", "tolerance"):
            assert key in obj, key
        assert obj["verdict"] in VERDICTS and obj["reason"]
        v = obj["our_value"]
        assert v is None or isinstance(v, float) or (isinstance(v, list) and len(v) == 2)
        assert (v is None) == (obj["verdict"] == "not run")
    by_id = {o["id"]: o for o in doc}
    assert by_id["EtaA0A1.max-lower-right"]["verdict"] == "agrees"
    assert by_id["EtaA0A1.max-lower-right"]["our_value"] == 1.8
    assert by_id["UEtaMax.min-speed"]["verdict"] == "not run"
    assert math.isfinite(by_id["EtaA0A1.largest-of-nine"]["our_value"])


def test_sampling_explains_a_maximum_only_below_the_paper(plane):
    """The maximum over a sampled axis can only rise with a finer grid: a maximum below the
    paper's value may be the sampling, one above it is a difference in the data."""
    stores, value, *_ = plane
    top = float(value.max())
    for paper, expected in ((top * 1.5, "grid resolution coarser"), (top * 0.5, "a difference in the data")):
        c = Claim(id="t", figure="UEtaMax", claim="c", paper_value="p", expect={"value": paper, "tolerance": 0.01},
                  compute="stat", args={"scene": "plane", "reduction": "best", "statistic": "max"})
        row = evaluate_claims([c], list(stores.values()))[0]
        assert row.verdict == "differs" and expected in row.reason, (paper, row.reason)


def test_a_ratio_of_unpolished_grid_optima_is_named_as_resolution(plane):
    stores, value, *_ = plane
    sd = stores["plane"]
    grid_only = _store("grid_only", sd.ds.drop_vars([v for v in sd.ds.data_vars if "polished" in v]),
                       sd.reductions)
    args = {"numerator": {"scene": "grid_only", "reduction": "best", "at": {"scaled_period": 8.0}},
            "denominator": {"scene": "grid_only", "reduction": "best", "at": {"scaled_period": 0.125}},
            "statistic": "max"}
    c = Claim(id="t", figure="EtaVsMinGamma", claim="c", paper_value="p", expect={"max": 0.0}, compute="gain",
              args=args)
    row = evaluate_claims([c], [grid_only])[0]
    assert row.verdict == "differs" and "not polished, an error we cannot bound" in row.reason
    polished = evaluate_claims([Claim(**{**c.__dict__, "args": {k: ({**v, "scene": "plane"} if isinstance(v, dict) else v)
                                                               for k, v in args.items()}})], [sd])[0]
    assert "a difference in the data" in polished.reason


# ---------------------------------------------------------------------------
# Causes of the claims that differ (reports/_causes.py), each check on a small synthetic store
# ---------------------------------------------------------------------------


def _cause_scenes(cause) -> set:
    """Every scene a cause check reads (its ``scene``, ``args.scene`` and gain sides)."""
    out = set()
    for table in (cause.args, cause.args.get("args") or {}, cause.args.get("override") or {}):
        if "scene" in table:
            out.add(table["scene"])
        for side in ("numerator", "denominator"):
            if isinstance(table.get(side), dict) and "scene" in table[side]:
                out.add(table[side]["scene"])
    return out


def test_registered_causes_name_known_kinds_checks_and_shipped_scenes():
    from reports._causes import CAUSES, CHECKS

    scenes = _scenes()
    causes = [c for c in load_claims() if c.cause is not None]
    assert len(causes) >= 15
    for c in causes:
        assert c.cause.kind in CAUSES and c.cause.check in CHECKS and c.cause.why, c.id
        assert _cause_scenes(c.cause) <= set(scenes), (c.id, _cause_scenes(c.cause) - set(scenes))



def _cause(kind, check, **args):
    from reports._causes import Cause

    return Cause(kind=kind, check=check, why="because", args=args)


def _with_cause(claim, cause):
    return Claim(**{**claim.__dict__, "cause": cause})


def test_recompute_holds_on_the_papers_range_and_not_elsewhere(plane):
    """domain/reading/convention: the claim's reduction on another selection, judged again."""
    stores, value, *_ = plane
    halves = {(0.0, 0.5): value[:4].max(), (2.0, 16.0): value[5:].max()}
    paper_range = min(halves, key=halves.get)  # the half without the global maximum
    other = max(halves, key=halves.get)
    low = halves[paper_range]
    c = Claim(id="t", figure="EtaOptt0", claim="c", paper_value="p", expect={"value": low, "tolerance": 1e-9},
              compute="stat", args={"scene": "plane", "reduction": "best", "statistic": "max"})
    on_range = _cause("domain", "recompute", label="on the paper's range",
                      override={"ranges": {"anisotropy_ratio": list(paper_range)}})
    row = evaluate_claims([_with_cause(c, on_range)], list(stores.values()))[0]
    assert row.verdict == "differs" and row.cause == "domain" and row.evidence.holds
    assert row.evidence.numbers["recomputed"] == low and "on the paper's range" in row.evidence.result
    wrong = _cause("domain", "recompute", label="elsewhere", override={"ranges": {"anisotropy_ratio": list(other)}})
    row = evaluate_claims([_with_cause(c, wrong)], list(stores.values()))[0]
    assert row.cause == "unexplained" and not row.evidence.holds and "still" in row.evidence.result
    # a reading with its own expectation
    reading = _cause("reading", "recompute", label="the median", override={"statistic": "median"},
                     expect={"value": float(np.median(value)), "tolerance": 1e-9})
    assert evaluate_claims([_with_cause(c, reading)], list(stores.values()))[0].cause == "reading"


def test_cross_check_holds_when_two_computations_agree_and_both_miss(plane):
    stores, value, *_ = plane
    sd = stores["plane"]
    twin = _store("twin", sd.ds * 1.01, sd.reductions)  # a second computation, 1 % apart
    both = {**stores, "twin": twin}
    c = Claim(id="t", figure="EtaOptt0", claim="c", paper_value="p", expect={"value": 5.0, "tolerance": 0.1},
              compute="stat", args={"scene": "plane", "reduction": "best", "statistic": "max"})
    check = _cause("cross-check", "cross_check", label="twin", override={"scene": "twin"}, rtol=0.02)
    row = evaluate_claims([_with_cause(c, check)], list(both.values()))[0]
    assert row.cause == "cross-check" and row.evidence.numbers["relative_gap"] == pytest.approx(0.01 / 1.01)
    tight = _cause("cross-check", "cross_check", label="twin", override={"scene": "twin"}, rtol=0.001)
    assert evaluate_claims([_with_cause(c, tight)], list(both.values()))[0].cause == "unexplained"
    # a second computation that agrees with the paper is no cross-check of a difference
    agreeing = Claim(**{**c.__dict__, "expect": {"value": float(value.max() * 1.01), "tolerance": 1e-6}})
    row = evaluate_claims([_with_cause(agreeing, check)], list(both.values()))[0]
    assert row.verdict == "differs" and row.cause == "unexplained" and "agrees with" in row.evidence.result
    # the second store missing: the check cannot run, the claim stays unexplained
    row = evaluate_claims([_with_cause(c, check)], [sd])[0]
    assert row.cause == "unexplained" and "could not run" in row.evidence.result


def test_toward_holds_when_the_finer_computation_removes_most_of_the_miss(plane):
    """resolution: the grid optimum against the polished one (``grid = true``)."""
    stores, value, *_ = plane
    paper = float(value.max())  # the polished maximum; the grid one is 2 % lower
    c = Claim(id="t", figure="EtaOptt0", claim="c", paper_value="p", expect={"value": paper, "tolerance": 1e-3},
              compute="stat", args={"scene": "plane", "reduction": "best", "statistic": "max", "grid": True})
    finer = _cause("resolution", "toward", label="polished", override={"grid": False})
    row = evaluate_claims([_with_cause(c, finer)], list(stores.values()))[0]
    assert row.measurement.value == pytest.approx(0.98 * paper)
    assert row.cause == "resolution" and row.evidence.numbers["miss_finer"] == 0
    coarser = _cause("resolution", "toward", label="coarser", override={"ranges": {"anisotropy_ratio": [0, 0.3]}})
    assert evaluate_claims([_with_cause(c, coarser)], list(stores.values()))[0].cause == "unexplained"


def _ridge_store():
    """A field with a narrow ridge at small A1/A0: its maximum 2.4 at the second sample."""
    a0, r = np.linspace(0.1, 1.5, 24), np.linspace(0.01, 0.99, 48)
    field = 2.4 * np.exp(-((r - r[1]) / 0.04) ** 2)[None, :] * np.exp(-((a0 - a0[-2]) / 0.5) ** 2)[:, None]
    ds = xr.Dataset({"scaled_efficiency": (("A0", "A1_ratio"), field)}, coords={"A0": a0, "A1_ratio": r})
    return _store("ridge", ds), field


def test_subgrid_max_shows_a_coarser_grid_gives_the_papers_value():
    sd, field = _ridge_store()
    for paper, holds in ((1.8, True), (3.0, False)):
        c = Claim(id="t", figure="EtaA0A1", claim="c", paper_value="p", expect={"value": paper, "tolerance": 0.05},
                  compute="stat", args={})
        from reports._causes import subgrid_max

        ev = subgrid_max({"ridge": sd}, c, Measurement(value=2.4), scene="ridge", quantity="scaled_efficiency",
                         at={}, dims=["A0", "A1_ratio"], strides=[1, 2, 4, 8])
        assert ev.holds is holds
        lows = [v[0] for v in ev.numbers["subgrid_maxima"].values()]
        assert lows[0] == pytest.approx(field.max()) and lows == sorted(lows, reverse=True)


def test_region_near_optimal_measures_the_top_contour_over_the_papers_place():
    sd, field = _ridge_store()
    from reports._causes import region_near_optimal

    c = Claim(id="t", figure="UPEtaDiag1", claim="c", paper_value="p", expect={"min": 1.0}, compute="stat", args={})
    a0 = sd.ds["A0"].values
    near = region_near_optimal({"ridge": sd}, c, None, scene="ridge", quantity="scaled_efficiency", cells=[{}],
                               region={"A0": [a0[-6], a0[-1]]}, share=0.95)
    far = region_near_optimal({"ridge": sd}, c, None, scene="ridge", quantity="scaled_efficiency", cells=[{}],
                              region={"A0": [a0[0], a0[3]]}, share=0.95)
    assert near.holds and near.numbers["ratios"][0] == pytest.approx(1.0)
    expected = field[:4].max() / field.max()
    assert not far.holds and far.numbers["ratios"][0] == pytest.approx(expected)


def test_nested_shortfall_bounds_the_grid_error_of_a_containing_family(plane):
    stores, value, *_ = plane
    sd = stores["plane"]
    ds = sd.ds.copy()
    wide = value * np.linspace(0.7, 1.3, value.shape[1])[None, :]  # the containing family, one cell 30 % low
    ds["best_polished"] = (("anisotropy_ratio", "scaled_period"), wide)
    both = {"plane": sd, "wide": _store("wide", ds, sd.reductions)}
    args = {"statistic": "median", "numerator": {"scene": "wide", "reduction": "best"},
            "denominator": {"scene": "plane", "reduction": "best"}}
    for paper, holds in ((1.1, True), (2.0, False)):
        c = Claim(id="t", figure="EtaOptAllParams", claim="c", paper_value="p", expect={"value": paper, "tolerance": 0.01},
                  compute="gain", args=args, cause=_cause("resolution", "nested_shortfall", label="wide"))
        row = evaluate_claims([c], list(both.values()))[0]
        assert row.evidence.numbers["smallest_gain"] == pytest.approx(0.7)
        assert (row.cause == "resolution") is holds, row.evidence.result


def test_audit_json_and_front_page_carry_causes_and_their_counts(plane, tmp_path):
    from reports._audit import audit_html, audit_summary, cause_counts

    stores, value, *_ = plane
    base = dict(id="t", figure="EtaOptt0", claim="c", paper_value="p", compute="stat",
                args={"scene": "plane", "reduction": "best", "statistic": "max"})
    at = {"scaled_period": 1.0}
    claims = [Claim(**{**base, "id": "agree", "expect": {"value": float(value.max()), "tolerance": 1e-9}}),
              Claim(**{**base, "id": "domain", "expect": {"value": float(value[:, 3].max()), "tolerance": 1e-9},
                       "cause": _cause("domain", "recompute", label="range", override={"at": at})}),
              Claim(**{**base, "id": "open", "expect": {"value": 9.0, "tolerance": 1e-9}})]
    rows = evaluate_claims(claims, list(stores.values()))
    assert cause_counts(rows)["domain"] == 1 and cause_counts(rows)["unexplained"] == 1
    doc = json.loads(write_audit_json(rows, tmp_path / "audit.json").read_text())
    by = {o["id"]: o for o in doc}
    assert by["agree"]["cause"] is None and by["agree"]["evidence"] is None
    assert by["domain"]["cause"] == "domain" and by["domain"]["why"] == "because"
    assert by["domain"]["evidence"]["check"] == "recompute" and by["domain"]["evidence"]["holds"] is True
    assert by["domain"]["evidence"]["numbers"]["recomputed"] == pytest.approx(value[:, 3].max())
    assert by["open"]["cause"] == "unexplained" and by["open"]["evidence"] is None
    html = audit_html(rows)
    assert "1 differ with a computed cause</span> (domain 1)" in html and "1 unexplained</span>" in html
    assert "check <code>recompute</code>: holds" in html
    assert "1 agree, 2 differ (domain 1; 1 unexplained), 0 not run" in audit_summary(tmp_path / "audit.json")


def test_distinct_in_best_ten_counts_the_optima_the_papers_figures_draw():
    """The paper draws "the ten most efficient local optima (with repetition)": the distinct
    optima among the ten best starts, walking the kept optima in rank order."""
    d4 = ("anisotropy_ratio", "max_wavenumber", "p", "rank")
    mult = np.array([[[[5, 1, 0]]], [[[12, 3, 0]]], [[[9, 1, 2]]], [[[0, 0, 0]]]])  # 4 ratios, 3 ranks
    start = np.where(mult > 0, 0, -1)
    ds = xr.Dataset({"optimum_multiplicity": (d4, mult), "optimum_start": (d4, start),
                     "optimum_relative_efficiency": (d4, -np.ones(mult.shape))},
                    coords={"anisotropy_ratio": [0.25, 0.5, 1.0, 2.0], "max_wavenumber": [1], "p": [0.0]})
    from reports._claim_values import optima_role_array

    sd = _store("force_laws", ds, kind="optima")
    shown = optima_role_array(sd, "distinct_in_best_ten").values.ravel()
    # 6 starts: both drawn; 15: the best alone covers ten; 12: 9 + 1 = ten, the third not drawn
    assert shown[:3].tolist() == [2.0, 1.0, 2.0] and np.isnan(shown[3])
    assert optima_role_array(sd, "distinct").values.ravel()[:3].tolist() == [2.0, 2.0, 3.0]
