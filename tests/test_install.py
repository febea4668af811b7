"""A regular (not editable) install carries every file the packages read (issue 36): the
shipped scenes are package data of ``workflows`` and are found through it, not through the
checkout's layout."""

from __future__ import annotations

import shutil
import subprocess
import sys
import zipfile
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parent.parent


def test_shipped_scenes_are_found_through_the_package():
    import workflows

    from pipeline.__main__ import PAPER_SCENES, WORKFLOWS
    from reports._read import shipped_scenes

    assert WORKFLOWS == workflows.DIRECTORY == (REPO / "workflows").resolve()
    assert all(workflows.scene_file(name).is_file() for name in PAPER_SCENES)
    assert {e["name"] for e in shipped_scenes()} >= set(PAPER_SCENES)


@pytest.mark.slow
def test_wheel_carries_the_scenes_and_package_data(tmp_path):
    """``pip wheel .`` (what ``pip install .`` installs) holds every shipped scene file and
    README, the reports' registries and the solver tools' references."""
    src = tmp_path / "src"  # built from a copy: setuptools writes build/ and *.egg-info beside the sources
    src.mkdir()
    for name in ("pyproject.toml", "README.md", "solver", "pipeline", "reports", "workflows"):
        if (REPO / name).is_dir():
            shutil.copytree(REPO / name, src / name, ignore=shutil.ignore_patterns("__pycache__"))
        else:
            shutil.copy2(REPO / name, src / name)
    proc = subprocess.run([sys.executable, "-m", "pip", "wheel", "--no-deps", "-q", "-w", str(tmp_path), str(src)],
                          capture_output=True, text=True, timeout=600)
    if proc.returncode != 0 and "setuptools" in proc.stderr and "Could not" in proc.stderr:
        pytest.skip(f"cannot build a wheel here (no build backend): {proc.stderr.strip().splitlines()[-1]}")
    assert proc.returncode == 0, proc.stderr
    (wheel,) = tmp_path.glob("twolink-*.whl")
    names = set(zipfile.ZipFile(wheel).namelist())
    want = {f"workflows/{p.name}" for p in (REPO / "workflows").glob("*.toml")}
    want |= {"workflows/README.md", "workflows/__init__.py", "reports/claims.toml", "reports/figures.toml"}
    want |= {f"solver/tools/{p.name}" for p in (REPO / "solver" / "tools").glob("*.npz")}
    assert len(want) > 15 and want <= names, sorted(want - names)


def test_paper_reads_the_scenes_of_workflows_dir(tmp_path, capsys):
    """``paper --workflows DIR`` reads DIR/<name>.toml: an empty folder is one line naming the
    first missing file (exit 2, nothing run or written); a missing folder is named too."""
    from pipeline.__main__ import EXIT_BAD_SCENE, QUICK_SCENES, main

    empty = tmp_path / "scenes"
    empty.mkdir()
    out = tmp_path / "out"
    assert main(["paper", "--quick", "--workflows", str(empty), "--out", str(out)]) == EXIT_BAD_SCENE
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and str(empty / f"{QUICK_SCENES[0]}.toml") in err[0], err
    assert main(["paper", "--workflows", str(tmp_path / "nope"), "--out", str(out)]) == EXIT_BAD_SCENE
    err = capsys.readouterr().err.strip().splitlines()
    assert err == [f"error: --workflows: no such folder: {tmp_path / 'nope'}"]
    assert not out.exists()
