"""The READMEs' numbers cannot go stale (issue 45): counts and sizes of the shipped scenes are
generated from the scene files (``python -m workflows.table --write``) and checked equal here;
times are not kept at all (the commands print them); paths are ones the commands write."""

from __future__ import annotations

import re
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parent.parent
DOCS = ("README.md", "workflows/README.md")

#: a duration written as a number: "92 s", "~8 min", "1,014 s", "about 16 min", "3 minutes"
DURATION = re.compile(r"\b\d[\d,.]*\s?(?:s|ms|min|mins|minutes?|seconds?|h|hours?)\b")


def test_generated_blocks_equal_what_the_scene_files_give():
    """Before issue 45 the README said 'twelve scenes' (14 ran) and workflows/README's table
    disagreed with the scene files."""
    from workflows.table import FILES, generated_blocks, replace_block

    for block, body in generated_blocks().items():
        text = (REPO / FILES[block]).read_text(encoding="utf-8")
        assert replace_block(text, block, body) == text, f"{FILES[block]}: run python -m workflows.table --write"


def test_the_generator_sees_a_changed_scene(tmp_path):
    """Negative control: one axis of one scene file refined changes the generated table."""
    import shutil

    from workflows import DIRECTORY
    from workflows.table import scene_table

    for f in DIRECTORY.glob("*.toml"):
        shutil.copy(f, tmp_path / f.name)
    path = tmp_path / "quick.toml"
    text = path.read_text()
    assert "num = 20" in text
    path.write_text(text.replace("num = 20", "num = 21", 1))
    assert scene_table(tmp_path) != scene_table()
    assert "3 x 3 x 21 x 20" in scene_table(tmp_path)


def test_the_counts_follow_the_papers_list():
    from pipeline.__main__ import PAPER_SCENES, QUICK_SCENES
    from workflows.table import paper_counts

    text = paper_counts()
    assert f"runs {len(PAPER_SCENES)} shipped scenes" in text and f"runs {len(QUICK_SCENES)} of them" in text
    assert "twelve" not in (REPO / "README.md").read_text()


@pytest.mark.parametrize("doc", DOCS)
def test_no_time_is_kept_by_hand(doc):
    """Times are printed by the commands that measure them (``paper`` prints each scene's and the
    total; ``pipeline estimate`` projects); before issue 45 the README gave four different
    full-paper times."""
    text = (REPO / doc).read_text(encoding="utf-8")
    assert DURATION.findall(text) == []


def test_duration_pattern_finds_what_it_should():
    """Negative control of the pattern above."""
    found = DURATION.findall("took 996 s; ~8 and ~6 min; 1,014 s; about 16 min on 2 cores; 3 minutes; rtol 1e-6; "
                             "2 cores; 25 MB; 400 cells")
    assert found == ["996 s", "6 min", "1,014 s", "16 min", "3 minutes"]


def test_readme_names_only_paths_a_clone_has_or_the_commands_write():
    """Before issue 45 it pointed to ../shared/paper/... (not in a clone) and its netCDF one-liner
    opened out/quick.zarr, which ``paper --quick`` does not write (it writes out/quick/*.zarr)."""
    from pipeline.__main__ import PAPER_SCENES, QUICK_SCENES

    text = (REPO / "README.md").read_text(encoding="utf-8")
    assert "../" not in text
    written = {f"out/{n}.zarr" for n in PAPER_SCENES} | {f"out/quick/{n}.zarr" for n in QUICK_SCENES}
    named = set(re.findall(r"out/[\w/]*?\w+\.zarr", text))
    assert named and named <= written | {"out/harmonic_grid.zarr"}, named - written
    for path in re.findall(r"`((?:solver|pipeline|reports|workflows|tests|docs)/[\w/.]+\.(?:py|md|toml|npz))`", text):
        assert (REPO / path).exists(), path


def test_readme_opens_with_the_two_commands():
    text = (REPO / "README.md").read_text(encoding="utf-8")
    sections = re.findall(r"^## (.+)$", text, re.M)
    assert sections[0] == "The two commands"
    first = text.split("## The two commands", 1)[1].split("\n## ", 1)[0]
    assert "python -m pip install -e . && python -m pipeline paper --quick" in first
    assert 'python -m pip install -e ".[test]" && python -m pytest -q' in first
