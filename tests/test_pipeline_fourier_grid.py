"""Fourier motions as a grid scene's family (issue 45): ``family = "fourier"`` with the
coefficients A0, A1.., B1.. as axes or fixed values (Kmax: the largest wavenumber given; a
coefficient not given is 0), stored and reported like any grid scene."""

from __future__ import annotations

import numpy as np
import pytest

import pipeline
import solver
from pipeline._scene import SceneError

#: 2 ratios x 3 A1 x 3 B1 = 18 points, A0 and A2 fixed (Kmax = 2), a reduction over (A1, B1)
FOURIER = """
[scene]
name = "tiny_fourier"
title = "Fourier motions over (A1, B1)"
family = "fourier"

[axes]
anisotropy_ratio = { values = [0.25, 4.0] }
A1 = { range = [0.2, 0.6], num = 3 }
B1 = { values = [-0.3, 0.0, 0.3] }

[fixed]
scaled_period = 1.0
A0 = "pi/3"
A2 = 0.1

[solver]
rtol = 1e-5

[outputs]
quantities = ["scaled_speed", "scaled_efficiency"]
diagnostics = ["error_estimate"]

[[reductions]]
name = "best_efficiency"
quantity = "scaled_efficiency"
statistic = "absmax"
over = ["A1", "B1"]

[series]
n_tau = 16
points = [{ anisotropy_ratio = 4.0, A1 = 0.4, B1 = 0.3 }]

[execution]
points_per_chunk = 9
points_per_task = 9
"""


def _scene(tmp_path, text=FOURIER):
    path = tmp_path / "fourier.toml"
    path.write_text(text)
    return pipeline.load_scene(path)


def test_fourier_scene_parses_with_kmax_from_its_coefficients(tmp_path):
    scene = _scene(tmp_path)
    assert scene.family == "fourier" and scene.dims == ("anisotropy_ratio", "A1", "B1")
    assert scene.max_wavenumber == 2 and scene.n_points == 18
    assert dict(scene.fixed)["A0"] == pytest.approx(np.pi / 3)
    # a coefficient's value is part of the scene's hash
    other = _scene(tmp_path, FOURIER.replace("A2 = 0.1", "A2 = 0.2"))
    assert other.hash != scene.hash


@pytest.mark.parametrize("edit, key, words", [
    (("A2 = 0.1", "B0 = 0.1"), "fixed.B0", "no sine coefficient of wavenumber 0"),
    (("A2 = 0.1", "A17 = 0.1"), "fixed.A17", "above the largest, 16"),
    (("A2 = 0.1", "A1_ratio = 0.5"), "fixed.A1_ratio", "unknown key for family 'fourier'"),
    (('A0 = "pi/3"\n', ""), "axes.A0", "needs A0"),
    (("A2 = 0.1", 'A2 = "x"'), "fixed.A2", "must be a number"),
    (("B1 = { values = [-0.3, 0.0, 0.3] }", "B1 = { values = [0.3, 0.0] }"), "axes.B1.values", "strictly increasing"),
    (('family = "fourier"', 'family = "fourrier"'), "scene.family", "harmonic, powerlaw, fourier"),
])
def test_a_bad_fourier_scene_names_the_key(tmp_path, edit, key, words):
    with pytest.raises(SceneError) as err:
        _scene(tmp_path, FOURIER.replace(*edit))
    message = str(err.value)
    assert f": {key}: " in message and words in message and "\n" not in message


def test_before_issue_45_family_fourier_was_refused_and_now_is_not(tmp_path):
    """The negative control of the parser: the families it knows."""
    from pipeline._grid_scene import FAMILY_PARAMETERS

    assert set(FAMILY_PARAMETERS) == {"harmonic", "powerlaw", "fourier"}
    with pytest.raises(SceneError, match="family"):
        _scene(tmp_path, FOURIER.replace('family = "fourier"', 'family = "harmonic"'))  # A1, B1: not harmonic's


@pytest.fixture(scope="module")
def store(tmp_path_factory):
    tmp = tmp_path_factory.mktemp("fourier")
    scene = _scene(tmp)
    path = tmp / "tiny_fourier.zarr"
    pipeline.run_scene(scene, path, scheduler="synchronous", progress=False)
    return scene, path


def test_the_store_holds_the_solvers_values_at_every_point(store):
    import xarray as xr

    scene, path = store
    ds = xr.open_zarr(path)
    assert tuple(ds["scaled_efficiency"].dims) == scene.dims
    ratio, a1, b1 = np.meshgrid(*(ds[d].values for d in scene.dims), indexing="ij")
    n = ratio.size
    kin = solver.Fourier(np.column_stack([np.full(n, np.pi / 3), a1.ravel(), np.full(n, 0.1)]),
                         np.column_stack([b1.ravel(), np.zeros(n)]))
    phys = solver.Physics.from_scaled(anisotropy_ratio=ratio.ravel(), scaled_period=1.0, p=0.0, delta=1e-5)
    res = solver.solve_periodic(kin, phys, rtol=1e-5)
    assert np.all(res.status == 0) and np.all(ds["status"].values == 0)
    np.testing.assert_allclose(ds["scaled_efficiency"].values.ravel(), res.scaled_efficiency, rtol=1e-12)
    # the reduction's arg-max parameters are grid values of the coefficient axes
    best = ds["best_efficiency_A1"].values
    assert np.all(np.isin(best, ds["A1"].values))
    assert ds["A1"].attrs["units"] == "rad" and "Fourier cosine coefficient A1" in ds["A1"].attrs["long_name"]
    assert np.isfinite(ds["series_u"].values).all()


def test_the_report_draws_a_fourier_store(store, tmp_path):
    import reports

    _, path = store
    index = reports.build_report([path], tmp_path / "report")
    page = index.read_text()
    assert "panel failed" not in page
    assert "id='own-tiny_fourier'" in page and "A<sub>1</sub>" in page
