"""``python -m solver point``: JSON on success, one-line errors with exit code 2 on bad input."""
import json
import os
import subprocess
import sys

import pytest
from pathlib import Path

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
KEYS = {"U", "P", "efficiency", "scaled_speed", "scaled_power", "scaled_efficiency",
        "relative_efficiency", "converged", "status", "error_estimate", "n_tau", "iterations",
        "seconds", "compile_seconds", "kernels_compiled", "method"}


def run(*args):
    env = dict(os.environ, PYTHONPATH=ROOT)
    return subprocess.run([sys.executable, "-m", "solver", "point", *args], capture_output=True,
                          text=True, env=env, cwd=ROOT, timeout=300)


HARMONIC = ["--family", "harmonic", "--A0", "1.2", "--A1", "0.3", "--T", "1", "--mu-n", "0.0625", "--mu-s", "1"]


@pytest.mark.parametrize("args", [
    HARMONIC + ["--rtol", "1e-5"],
    HARMONIC + ["--method", "march", "--rtol", "1e-4"],
    ["--family", "powerlaw", "--A0", "1.2", "--A1", "0.35", "--tau0", "0.8", "--closing", "down:10",
     "--opening", "up:3", "--T", "1", "--mu-n", "0.0625", "--mu-s", "1", "--rtol", "1e-4"],
    ["--family", "fourier", "--A", "0.6,0.9,0,0.2", "--B", "0.15,-0.1,0.05", "--T", "1",
     "--mu-n", "0.5", "--mu-s", "1", "--p", "0.5", "--rtol", "1e-4"],
], ids=["harmonic", "march", "powerlaw", "fourier"])
def test_point_prints_one_json_object(args):
    proc = run(*args)
    assert proc.returncode == 0, proc.stderr
    lines = proc.stdout.strip().splitlines()
    assert len(lines) == 1
    out = json.loads(lines[0])
    assert KEYS <= set(out)
    assert out["converged"] is True and out["status"] == 0
    assert out["error_estimate"] <= float(args[args.index("--rtol") + 1])


def test_point_agrees_with_the_library():
    import solver
    out = json.loads(run(*HARMONIC, "--rtol", "1e-6").stdout)
    res = solver.solve_periodic(solver.Harmonic(1.2, 0.3), solver.Physics(1.0, 0.0625, 1.0), rtol=1e-6)
    assert out["U"] == pytest.approx(res.U[0], rel=1e-12)
    assert out["relative_efficiency"] == pytest.approx(res.efficiency[0] / 16.0, rel=1e-12)


@pytest.mark.parametrize("args, flag", [
    (["--mu-n", "-1"], "--mu-n"), (["--mu-s", "0"], "--mu-s"), (["--T", "0"], "--T"),
    (["--p", "2"], "--p"), (["--A1", "-0.1"], "--A1"), (["--T", "nan"], "--T"),
    (["--A0", "inf"], "--A0"), (["--delta", "0"], "--delta"), (["--rtol", "2"], "--rtol"),
])
def test_bad_input_is_one_line_naming_the_argument(args, flag):
    base = dict(zip(HARMONIC[::2], HARMONIC[1::2]))
    base.update(dict(zip(args[::2], args[1::2])))
    proc = run(*[x for kv in base.items() for x in kv])
    assert proc.returncode == 2
    assert proc.stdout == ""
    lines = proc.stderr.strip().splitlines()
    assert len(lines) == 1 and flag in lines[0] and "Traceback" not in proc.stderr


@pytest.mark.parametrize("args, flag", [
    (["--family", "powerlaw", "--A0", "1", "--A1", "0.3", "--tau0", "1.2"], "--tau0"),
    (["--family", "powerlaw", "--A0", "1", "--A1", "0.3", "--tau0", "0.5", "--closing", "down:0.5"], "--closing"),
    (["--family", "fourier", "--A", "0.6,0.9,0", "--B", "0.1"], "--B"),
])
def test_bad_kinematics_name_the_argument(args, flag):
    proc = run(*args, "--T", "1", "--mu-n", "1", "--mu-s", "1")
    assert proc.returncode == 2
    assert flag in proc.stderr and len(proc.stderr.strip().splitlines()) == 1


def test_seconds_are_the_solve_alone_and_the_compile_is_apart():
    """``seconds`` times the solve only: the kernels are compiled or loaded before it and
    reported as ``compile_seconds`` (a cold cache took 12 s inside ``seconds`` before issue 36)."""
    out = json.loads(run(*HARMONIC, "--rtol", "1e-4").stdout)
    assert isinstance(out["kernels_compiled"], int) and out["kernels_compiled"] >= 0
    assert out["compile_seconds"] > 0 and out["seconds"] > 0
    # The kernels are cached now, so a second process loads every one (compiles none).
    again = json.loads(run(*HARMONIC, "--rtol", "1e-4").stdout)
    assert again["kernels_compiled"] == 0


def test_the_timed_solve_compiles_nothing():
    """In process: after ``_timed_solve`` warmed the method's kernels, the solve it timed
    compiled no kernel (else it would have timed a second solve)."""
    import solver
    from solver.__main__ import _timed_solve, build_parser
    from solver._warmup import compiled_count

    args = build_parser().parse_args(["point", *HARMONIC, "--rtol", "1e-5", "--series"])
    kin, phys = solver.Harmonic(1.2, 0.3), solver.Physics(1.0, 0.0625, 1.0)
    res, seconds, kernels = _timed_solve(kin, phys, args)
    before = compiled_count()
    again = solver.solve_periodic(kin, phys, rtol=1e-5, return_series=True)
    assert compiled_count() == before  # the warm-up left nothing for a solve of this kind to compile
    assert res.U[0] == again.U[0] and seconds > 0 and kernels.kernel_sets in ((), ("periodic",))


@pytest.mark.parametrize("module", ["solver", "pipeline", "reports"])
def test_version_names_the_package_and_engine_versions(module):
    import importlib.metadata as md

    import solver

    env = dict(os.environ, PYTHONPATH=ROOT)
    proc = subprocess.run([sys.executable, "-m", module, "--version"], capture_output=True, text=True,
                          env=env, cwd=ROOT, timeout=300)
    assert proc.returncode == 0, proc.stderr
    lines = proc.stdout.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith(f"python -m {module} (twolink "), proc.stdout
    try:
        version = md.version("twolink")
    except md.PackageNotFoundError:
        version = "+source"
    assert version in lines[0]
    for name, engine in solver.ENGINES.items():
        assert f"{name} {engine.version}" in lines[0]


def test_version_fallback_outside_an_install(monkeypatch):
    import importlib.metadata as md

    from solver import _version

    def missing(name):
        raise md.PackageNotFoundError(name)

    monkeypatch.setattr(md, "version", missing)
    text = _version.package_version()
    assert text.endswith("+source") and text.removesuffix("+source") in (Path(ROOT) / "pyproject.toml").read_text()
