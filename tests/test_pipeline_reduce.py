"""Reductions against a brute-force numpy reference (loops over cells) on small grids."""

from __future__ import annotations

import itertools

import numpy as np
import pytest

from pipeline import parse_scene
from pipeline._reduce import grid_reduction

SCENE = """
[scene]
name = "red"
family = "powerlaw"
[axes]
anisotropy_ratio = {{ values = [0.25, 4.0] }}
closing_shape = ["down:3", "linear", "up:3", "up:10"]
duty_cycle = {{ range = [0.1, 0.9], step = 0.2 }}
A0 = {{ range = [0.2, 1.4], num = 3 }}
A1_ratio = {{ values = [0.3, 0.6] }}
[fixed]
opening_shape = "linear"
scaled_period = 1.0
[solver]
rtol = 1e-3
[outputs]
quantities = ["scaled_efficiency", "relative_efficiency"]
[[reductions]]
name = "best"
quantity = "scaled_efficiency"
statistic = "{statistic}"
over = {over}
report = ["relative_efficiency"]
{extra}
"""

WINDOW = '[reductions.window]\naxis = "duty_cycle"\ncenter = 0.5\nhalfwidths = [0.0, 0.2, 0.4]'
SETS = '[reductions.exponent_sets]\naxes = ["closing_shape"]\nsets = [[1], [1, 3], [1, 3, 10]]'


def _scene(statistic, over, extra=""):
    return parse_scene(SCENE.format(statistic=statistic, over=str(list(over)).replace("'", '"'), extra=extra),
                       "red.toml")


def _data(scene, seed):
    rng = np.random.default_rng(seed)
    q = rng.normal(size=scene.shape)
    q[rng.random(scene.shape) < 0.15] = np.nan  # failed points are NaN and never win
    rel = q / 3.0 + rng.normal(size=scene.shape) * 1e-3
    return {"scaled_efficiency": q, "relative_efficiency": rel}


def _brute(scene, r, data, subset_mask=None):
    """Loop over kept cells; inside a cell loop over every point of the reduced axes."""
    dims = scene.dims
    kept = [d for d in dims if d not in r.over]
    sign = {"max": 1.0, "min": -1.0}
    out = {}
    for kidx in itertools.product(*(range(scene.axis(d).size) for d in kept)):
        best, best_key = -np.inf, None
        for oidx in itertools.product(*(range(scene.axis(d).size) for d in r.over)):
            full = dict(zip(kept, kidx)) | dict(zip(r.over, oidx))
            if subset_mask is not None and not subset_mask(full):
                continue
            q = data[r.quantity][tuple(full[d] for d in dims)]
            if np.isnan(q):
                continue
            o = abs(q) if r.statistic == "absmax" else sign[r.statistic] * q
            if o > best:
                best, best_key = o, full
        out[kidx] = (best_key, best)
    return out


@pytest.mark.parametrize("statistic", ["max", "min", "absmax"])
@pytest.mark.parametrize("over", [("A0", "A1_ratio"), ("duty_cycle", "A0", "A1_ratio"),
                                  ("anisotropy_ratio", "closing_shape", "duty_cycle", "A0", "A1_ratio")])
def test_grid_reduction_matches_brute_force(statistic, over):
    scene = _scene(statistic, over)
    r = scene.reductions[0]
    data = _data(scene, 1)
    arrays, _ = grid_reduction(scene, r, data)
    kept = [d for d in scene.dims if d not in r.over]
    for kidx, (key, best) in _brute(scene, r, data).items():
        q = data[r.quantity][tuple(key[d] for d in scene.dims)]
        expect = abs(q) if statistic == "absmax" else q
        assert arrays["best"][kidx] == expect
        if statistic == "absmax":
            assert arrays["best_signed"][kidx] == q
        for d in r.over:
            assert arrays[f"best_{d}"][kidx] == scene.axis(d).values[key[d]]
        assert arrays["best_relative_efficiency"][kidx] == data["relative_efficiency"][tuple(key[d] for d in scene.dims)]
    assert arrays["best"].shape == tuple(scene.axis(d).size for d in kept)


def test_window_subsets_match_brute_force():
    scene = _scene("absmax", ("duty_cycle", "A0", "A1_ratio"), WINDOW)
    r = scene.reductions[0]
    data = _data(scene, 2)
    arrays, _ = grid_reduction(scene, r, data)
    tau = scene.axis("duty_cycle").array()
    for k, h in enumerate((0.0, 0.2, 0.4)):
        ref = _brute(scene, r, data, lambda full: abs(tau[full["duty_cycle"]] - 0.5) <= h + 1e-12)
        for kidx, (key, best) in ref.items():
            assert arrays["best"][kidx + (k,)] == best
            assert arrays["best_duty_cycle"][kidx + (k,)] == tau[key["duty_cycle"]]
    # Nested windows: the maximum never decreases as the window widens.
    assert (np.diff(arrays["best"], axis=-1) >= 0).all()


def test_exponent_sets_match_brute_force():
    scene = _scene("absmax", ("closing_shape", "duty_cycle", "A0", "A1_ratio"), SETS)
    r = scene.reductions[0]
    data = _data(scene, 3)
    arrays, _ = grid_reduction(scene, r, data)
    shapes = np.abs(scene.axis("closing_shape").array())
    for k, allowed in enumerate(([1], [1, 3], [1, 3, 10])):
        ref = _brute(scene, r, data, lambda full: shapes[full["closing_shape"]] in allowed)
        for kidx, (key, best) in ref.items():
            assert arrays["best"][kidx + (k,)] == best
            assert abs(arrays["best_closing_shape"][kidx + (k,)]) in allowed


def test_all_failed_cell_is_nan():
    scene = _scene("max", ("A0", "A1_ratio"))
    r = scene.reductions[0]
    data = _data(scene, 4)
    data["scaled_efficiency"][0, 1, 2] = np.nan
    arrays, flat = grid_reduction(scene, r, data)
    assert np.isnan(arrays["best"][0, 1, 2]) and np.isnan(arrays["best_A0"][0, 1, 2])
    assert flat[0, 1, 2] == -1
