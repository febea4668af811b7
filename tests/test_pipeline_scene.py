"""Scene parsing and validation: errors name file, key and reason; exit code 2; nothing written."""

from __future__ import annotations

import math

import numpy as np
import pytest

from pipeline import SceneError, load_scene, parse_scene
from pipeline.__main__ import main
from pipeline._grid import DEFAULT_POINTS_PER_CHUNK, chunk_grid, chunk_region, chunk_shape, iter_chunks, scene_chunks
from pipeline_cases import REPO, cli, small_scene_text, write_scene

SHIPPED = sorted((REPO / "workflows").glob("*.toml"))


def _edit(old: str, new: str) -> str:
    text = small_scene_text()
    assert old in text, old
    return text.replace(old, new, 1)


# (edit of the small scene, key named in the error, words of the reason)
BAD = [
    pytest.param(("[solver]", "[solver]\nspeed = 3"), "solver.speed", "unknown key", id="unknown-key"),
    pytest.param(("[scene]", "[scene]\ncolour = 'red'"), "scene.colour", "unknown key", id="unknown-key-2"),
    pytest.param(('A0 = { range = [0.4, 1.5], num = 4 }', 'A0 = { range = [0.4, 1.5], num = "four" }'),
                 "axes.A0.num", "must be an integer", id="wrong-type"),
    pytest.param(("rtol = 0.001", 'rtol = "small"'), "solver.rtol", "must be a number", id="wrong-type-2"),
    pytest.param(('A0 = { range = [0.4, 1.5], num = 4 }', 'A0 = { range = [1.5, 0.4], num = 4 }'),
                 "axes.A0.range", "reversed range", id="reversed-range"),
    pytest.param(('A0 = { range = [0.4, 1.5], num = 4 }', 'A0 = { range = [0.4, 0.4], num = 3 }'),
                 "axes.A0.range", "empty range", id="empty-range"),
    pytest.param(('A0 = { range = [0.4, 1.5], num = 4 }', 'A0 = { range = [0.4, 1.5], num = 0 }'),
                 "axes.A0.num", "must be >= 1", id="empty-range-num"),
    pytest.param(("anisotropy_ratio = { values = [0.0625, 16.0] }", "anisotropy_ratio = { values = [] }"),
                 "axes.anisotropy_ratio.values", "empty list", id="empty-values"),
    pytest.param(("anisotropy_ratio = { values = [0.0625, 16.0] }", "anisotropy_ratio = { values = [-1.0, 16.0] }"),
                 "axes.anisotropy_ratio.values[0]", "outside the physical domain", id="negative-ratio"),
    pytest.param(("p = 0.0", "p = 2.5"), "fixed.p", "outside the physical domain", id="p-domain"),
    pytest.param(('A1_ratio = { range = [0.2, 0.8], num = 4 }', 'A1_ratio = { range = [0.2, 1.8], num = 4 }'),
                 "axes.A1_ratio.range", "outside the physical domain", id="ratio-domain"),
    pytest.param(("rtol = 0.001", "rtol = 0.0"), "solver.rtol", "must be in (0, 0.1]", id="rtol-domain"),
    pytest.param(('method = "periodic"', 'method = "euler"'), "solver.method", "must be one of", id="method"),
    pytest.param(('method = "periodic"', 'method = "march"'), "solver.sweeps", "need method 'periodic'",
                 id="sweeps-march"),
    pytest.param(("sweeps = true", 'sweeps = "yes"'), "solver.sweeps", "must be true or false", id="sweeps-type"),
    pytest.param(('over = ["A0", "A1_ratio"]', 'over = ["A0", "A2"]'), "reductions[0].over[1]",
                 "is not one of", id="reduction-axis"),
    pytest.param(('quantity = "scaled_speed"', 'quantity = "U"'), "reductions[1].quantity",
                 "not among the scene's outputs", id="reduction-quantity"),
    pytest.param(("delta = 1e-5", "delta = 0.0"), "fixed.delta", "delta = 0 needs p > 0", id="delta-zero"),
    pytest.param(("A1_ratio = 0.2 }", "A1_ratio = 0.2, p = 1.0 }"), "series.points[1].p", "unknown key",
                 id="series-key"),
    pytest.param(("A0 = 1.5, A1_ratio = 0.2 }", "A0 = 1.5 }"), "series.points[1].A1_ratio", "missing",
                 id="series-missing"),
]


@pytest.mark.parametrize("edit, key, reason", BAD)
def test_bad_scene_error_names_file_key_reason(tmp_path, edit, key, reason):
    path = write_scene(tmp_path, _edit(*edit), "bad.toml")
    with pytest.raises(SceneError) as info:
        load_scene(path)
    msg = str(info.value)
    assert "\n" not in msg
    assert msg.startswith(f"{path}: {key}: "), msg
    assert reason in msg, msg


def test_missing_family_parameter(tmp_path):
    path = write_scene(tmp_path, _edit("A1_ratio = { range = [0.2, 0.8], num = 4 }\n", ""), "bad.toml")
    with pytest.raises(SceneError, match=r"axes\.A1_ratio: missing"):
        load_scene(path)


def test_cli_bad_scene_exit_2_nothing_written(tmp_path, capsys):
    path = write_scene(tmp_path, _edit("[solver]", "[solver]\nspeed = 3"), "bad.toml")
    store = tmp_path / "out" / "bad.zarr"
    assert main(["run", str(path), "--store", str(store)]) == 2
    err = capsys.readouterr().err.strip()
    assert err == f"error: {path}: solver.speed: unknown key (allowed: method, rtol, sweeps)"
    assert not (tmp_path / "out").exists()


def test_cli_subprocess_bad_scene_no_traceback(tmp_path):
    path = write_scene(tmp_path, _edit("p = 0.0", "p = -1"), "bad.toml")
    proc = cli("run", path, "--store", tmp_path / "x.zarr")
    assert proc.returncode == 2
    assert "Traceback" not in proc.stderr
    assert f"{path}: fixed.p: " in proc.stderr and "outside the physical domain" in proc.stderr
    assert not (tmp_path / "x.zarr").exists()


def test_missing_file(tmp_path):
    assert main(["run", str(tmp_path / "nope.toml")]) == 2


def test_hash_covers_science_not_execution():
    a = parse_scene(small_scene_text(), "a.toml")
    b = parse_scene(small_scene_text().replace("points_per_task = 8", "points_per_task = 4\nworkers = 1"), "b.toml")
    c = parse_scene(small_scene_text(rtol=1e-4), "a.toml")
    assert a.hash == b.hash
    assert a.hash != c.hash


def test_sweeps_and_their_chunk_layout_are_hashed():
    """With sweeps a value depends on its chunk's points: the sweeps and the layout enter
    the hash; without, the layout does not (a store of another layout is refused anyway)."""
    swept = parse_scene(small_scene_text(), "a.toml")
    cold = parse_scene(small_scene_text().replace("sweeps = true", "sweeps = false"), "a.toml")
    other_layout = parse_scene(small_scene_text().replace("points_per_chunk = 8", "points_per_chunk = 16"), "a.toml")
    cold_layout = parse_scene(small_scene_text().replace("sweeps = true", "sweeps = false")
                              .replace("points_per_chunk = 8", "points_per_chunk = 16"), "a.toml")
    assert swept.sweeps and not cold.sweeps
    assert swept.hash != cold.hash
    assert swept.hash != other_layout.hash
    assert cold.hash == cold_layout.hash


def test_a_swept_chunk_is_its_snake_ordered_sweeps(tmp_path):
    """``solve_chunk`` with sweeps, written by the driver's ``ChunkWriter``, stores what ``solve_periodic`` gives the chunk's points in
    snake order as sweeps of ``solver.SWEEP_POINTS``, put back in grid order (computed here directly)."""
    import solver
    from pipeline._grid import chunk_region, region_parameters, scene_chunks
    from pipeline._store import ChunkWriter, create_skeleton, store_meta
    from pipeline._grid_kind import solve_chunk
    from pipeline_cases import read_store

    scene = parse_scene(small_scene_text().replace("points_per_chunk = 8", "points_per_chunk = 16"), "a.toml")
    chunks = scene_chunks(scene)
    store = tmp_path / "s.zarr"
    create_skeleton(store, scene, chunks)
    index = (1, 0, 0, 0)
    ChunkWriter(store, store_meta(store)["layout"], [index]).add(index, solve_chunk(scene, chunks, index))
    region = chunk_region(index, scene.shape, chunks)
    rshape = tuple(r.stop - r.start for r in region)
    params = region_parameters(scene, region)
    order = solver.snake_order(rshape)
    kin = solver.Harmonic(A0=params["A0"][order], A1=(params["A1_ratio"] * params["A0"])[order])
    phys = solver.Physics.from_scaled(anisotropy_ratio=params["anisotropy_ratio"][order],
                                      scaled_period=params["scaled_period"][order], p=params["p"][order],
                                      delta=params["delta"][order])
    runs = np.r_[np.arange(0, order.size, solver.SWEEP_POINTS), order.size]
    res = solver.solve_periodic(kin, phys, rtol=scene.rtol, sweeps=runs)
    want = np.empty(order.size)
    want[order] = res.scaled_efficiency
    got = read_store(store)["scaled_efficiency"][region].ravel()
    np.testing.assert_array_equal(got, want)
    assert np.count_nonzero(res.start == 1) == order.size - 1  # one sweep: all but the first warm


def test_axis_forms():
    s = parse_scene(small_scene_text(), "a.toml")
    np.testing.assert_allclose(s.axis("scaled_period").values, [1.0, 2.0])
    np.testing.assert_allclose(s.axis("A0").values, np.linspace(0.4, 1.5, 4))
    text = small_scene_text().replace('A0 = { range = [0.4, 1.5], num = 4 }',
                                      'A0 = { range = [0, "pi/2"], num = 4, include = "upper" }')
    s = parse_scene(text, "a.toml")
    np.testing.assert_allclose(s.axis("A0").values, math.pi / 8 * np.arange(1, 5))
    text = small_scene_text().replace('A1_ratio = { range = [0.2, 0.8], num = 4 }',
                                      'A1_ratio = { range = [0, 1], step = 0.25, include = "neither" }')
    np.testing.assert_allclose(parse_scene(text, "a.toml").axis("A1_ratio").values, [0.25, 0.5, 0.75])


@pytest.mark.parametrize("path", SHIPPED, ids=[p.stem for p in SHIPPED])
def test_shipped_scenes_are_valid(path):
    scene = load_scene(path)
    assert scene.name == path.stem
    assert scene.n_points > 0


def test_shipped_scene_set():
    names = {p.stem for p in SHIPPED}
    assert {"harmonic_grid", "harmonic_diagonals", "harmonic_optimum", "duty_cycle", "linear_two_phase",
            "exponent_sets", "power_law", "quick"} <= names


@pytest.mark.parametrize("shape, target", [((3, 3, 24, 24), 576), ((29, 29, 32, 32), 4096), ((7, 5, 3), 10),
                                           ((5,), 2), ((2, 3), 1000)])
def test_chunks_tile_the_grid(shape, target):
    chunks = chunk_shape(shape, target)
    assert np.prod(chunks) <= max(target, 1) or chunks == tuple([1] * (len(shape) - 1) + [1])
    seen = np.zeros(shape, dtype=int)
    for idx in iter_chunks(shape, chunks):
        seen[chunk_region(idx, shape, chunks)] += 1
    assert (seen == 1).all()
    assert len(list(iter_chunks(shape, chunks))) == np.prod(chunk_grid(shape, chunks))


def test_chunk_shape_is_a_function_of_the_scene_only(tmp_path, monkeypatch):
    """Issue 29: where chunks begin follows from the grid's shape and [execution]
    points_per_chunk, never from a timing, the scheduler, the workers or points_per_task."""
    import pipeline._grid as grid
    from pipeline._kind import RunContext
    from pipeline._registry import kind_of
    from pipeline._schedule import Scheduler
    from pipeline._store import store_meta

    assert chunk_shape((3, 3, 20, 20), 256) == (1, 1, 10, 20)
    assert chunk_shape((2, 3, 64, 64), 256) == (1, 1, 4, 64)
    assert chunk_shape((7, 4, 5, 5, 5, 5, 5), 256) == (1, 1, 1, 2, 5, 5, 5)
    quick = load_scene(REPO / "workflows" / "quick.toml")
    assert scene_chunks(quick) == chunk_shape(quick.shape, DEFAULT_POINTS_PER_CHUNK) == (1, 1, 10, 20)
    assert chunk_grid(quick.shape, scene_chunks(quick)) == (3, 3, 2, 1)
    base = small_scene_text().replace("points_per_chunk = 8\npoints_per_task = 8\n", "")
    runs = ["", "points_per_task = 3\n", "points_per_task = 5000\nworkers = 1\n", "scheduler = 'threads'\nworkers = 2\n"]
    scenes = [parse_scene(base.replace("[execution]\n", "[execution]\n" + extra), "a.toml") for extra in runs]
    assert {scene_chunks(s) for s in scenes} == {chunk_shape((2, 2, 4, 4), DEFAULT_POINTS_PER_CHUNK)} == {(2, 2, 4, 4)}  # 64 points: one chunk
    chunked = parse_scene(base.replace("[execution]\n", "[execution]\npoints_per_chunk = 8\n"), "a.toml")
    # (the small scene solves its chunks as sweeps, whose values depend on the layout: hashed)
    assert scene_chunks(chunked) == (1, 1, 2, 4) and chunked.hash != scenes[0].hash
    default = parse_scene(base.replace("[execution]\n", "[execution]\npoints_per_chunk = 256\n"), "a.toml")
    assert default.hash == scenes[0].hash

    # The skeleton never asks the probe: its layout is the scene's under any load.
    def no_probe(*args, **kwargs):
        raise AssertionError("the chunk layout must not depend on a timing probe")

    monkeypatch.setattr(grid, "calibrate_points_per_task", no_probe)
    for i, scene in enumerate([scenes[0], chunked]):
        store = tmp_path / f"s{i}.zarr"
        with Scheduler("synchronous", None) as sched:
            kind_of(scene).create_skeleton(RunContext(scene, store, sched, 1, True, print))
        layout = store_meta(store)["layout"]
        assert tuple(layout["blocks"]) == scene_chunks(scene)
        # (a chunk per block: the tests' TWOLINK_PIPELINE_CHUNK_BYTES, tests/conftest.py)
        assert tuple(layout["chunk_grid"]) == chunk_grid(scene.shape, scene_chunks(scene))


def test_T2_axes_map_to_the_physical_friction():
    """T^2 mu_n = a, T^2 mu_s = b (figure EtaA0A1) is mu_n = a, mu_s = b at T = 1."""
    import solver

    from pipeline._grid import solve_points

    a, b = np.array([16.0, 0.0625]), np.array([1.0, 16.0])
    A0, A1r = np.array([1.2, 0.5]), np.array([0.25, 0.6])
    params = {"T2_mu_n": a, "T2_mu_s": b, "A0": A0, "A1_ratio": A1r, "p": np.zeros(2), "delta": np.full(2, 1e-5)}
    got = solve_points("harmonic", params, ("scaled_efficiency", "relative_efficiency"), method="periodic", rtol=1e-6)
    ref = solver.solve_periodic(solver.Harmonic(A0=A0, A1=A1r * A0),
                                solver.Physics(period=np.ones(2), mu_n=a, mu_s=b, p=np.zeros(2), delta=np.full(2, 1e-5)),
                                rtol=1e-6)
    np.testing.assert_allclose(got["scaled_efficiency"], ref.scaled_efficiency, rtol=1e-4)
    np.testing.assert_allclose(got["relative_efficiency"], ref.relative_efficiency, rtol=1e-4)


def test_empty_subset_is_an_error(tmp_path):
    text = (REPO / "workflows" / "duty_cycle.toml").read_text().replace(
        "halfwidths = [0.0, 0.05,", "halfwidths = [0.0, 0.01, 0.05,")
    text = text.replace("duty_cycle = { range = [0.05, 0.95], step = 0.025 }",
                        "duty_cycle = { range = [0.05, 0.95], step = 0.1 }")
    path = write_scene(tmp_path, text, "d.toml")
    with pytest.raises(SceneError, match=r"reductions\[0\]\.window\.halfwidths\[0\]: window 0.5 \+- 0 holds no"):
        load_scene(path)


def test_reduction_array_name_clash(tmp_path):
    text = small_scene_text().replace('name = "fastest"', 'name = "best_efficiency_A0"')
    with pytest.raises(SceneError, match=r"reductions\[1\]\.name: array 'best_efficiency_A0' .* clashes"):
        parse_scene(text, "c.toml")


def test_quick_variants_are_smaller_versions_of_every_shipped_scene():
    from pathlib import Path

    from pipeline.__main__ import PAPER_SCENES, WORKFLOWS, quick_variant
    from pipeline import load_scene

    for name in PAPER_SCENES:
        full = load_scene(WORKFLOWS / f"{name}.toml")
        quick = quick_variant(Path(WORKFLOWS / f"{name}.toml"))
        assert quick.dims == full.dims
        # study scenes (issue 6) keep their cases and solve each fewer times
        assert getattr(quick, "n_solves", quick.n_points) < getattr(full, "n_solves", full.n_points)
        assert quick.hash != full.hash  # its stores can never be mistaken for the full ones
