"""The command lines of ``python -m solver`` and ``python -m reports`` (issue 45): every option
has ``--help`` text stating its default, and every user mistake gives one line on stderr naming
the argument, the documented exit code (2) and writes nothing.  ``python -m pipeline``'s options
are checked for help text here too; its mistakes are ``tests/test_pipeline_mistakes.py``'s.

The mistakes are the list in ``/work/notes/mistakes.md`` (reportdocs' part), run in process
through each command's ``main`` (the same code path as ``python -m``; one subprocess per command
checks the real entry point).
"""

from __future__ import annotations

import argparse
import os
import subprocess
import sys
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parent.parent


def _parsers():
    from pipeline.__main__ import _parser as pipeline_parser
    from reports.__main__ import _parser as reports_parser
    from solver.__main__ import build_parser as solver_parser

    return {"solver": solver_parser(), "reports": reports_parser(), "pipeline": pipeline_parser()}


def _options(parser, prefix=""):
    """(command, action) of every option and positional of ``parser`` and its sub-commands."""
    for action in parser._actions:
        if isinstance(action, argparse._SubParsersAction):
            for name, sub in action.choices.items():
                yield from _options(sub, f"{prefix} {name}".strip())
        elif not isinstance(action, argparse._HelpAction) and action.dest != "version":
            yield prefix, action


@pytest.mark.parametrize("module", ["solver", "reports", "pipeline"])
def test_every_option_has_help_and_states_its_default(module):
    """Before issue 45 ``solver point --help`` had no text for 13 of its 17 options and stated no
    default (``--closing``, ``--p``, ``--rtol``, ...)."""
    missing = []
    for command, action in _options(_parsers()[module]):
        name = f"{command} {'/'.join(action.option_strings) or action.dest}"
        if not (action.help or "").strip():
            missing.append(f"{name}: no help")
            continue
        has_default = action.default not in (None, False, [], argparse.SUPPRESS) and action.option_strings
        if has_default and "default" not in action.help:
            missing.append(f"{name}: default {action.default!r} not stated")
    assert missing == []


# -- mistakes ------------------------------------------------------------------------------------

HARMONIC = ["--family", "harmonic", "--A0", "1.2", "--A1", "0.3", "--T", "1", "--mu-n", "0.0625", "--mu-s", "1"]
POWERLAW = ["--family", "powerlaw", "--A0", "1.2", "--A1", "0.3", "--tau0", "0.5", "--T", "1", "--mu-n", "1",
            "--mu-s", "1"]

#: (id, argv of ``python -m solver``, words the one line must hold); every one exit 2
SOLVER_MISTAKES = [
    ("no-command", [], "command"),
    ("unknown-command", ["pont"], "pont"),
    ("unknown-option", ["point", *HARMONIC, "--mu_n", "1"], "--mu_n"),
    ("no-family", ["point", "--T", "1", "--mu-n", "1", "--mu-s", "1"], "--family"),
    ("bad-family", ["point", "--family", "sine", "--T", "1", "--mu-n", "1", "--mu-s", "1"], "--family"),
    ("closing-without-colon", ["point", *POWERLAW, "--closing", "down10"], "--closing: expected 'down:G'"),
    ("closing-below-one", ["point", *POWERLAW, "--opening", "up:0.5"], "--opening: expected"),
    ("period-not-a-number", ["point", *HARMONIC[:-6], "--T", "one", "--mu-n", "1", "--mu-s", "1"], "--T: expected a number"),
    ("period-zero", ["point", *HARMONIC[:-6], "--T", "0", "--mu-n", "1", "--mu-s", "1"], "--T"),
    ("friction-negative", ["point", *HARMONIC[:-2], "--mu-s", "-1"], "--mu-s"),
    ("amplitude-missing", ["point", "--family", "harmonic", "--A0", "1", "--T", "1", "--mu-n", "1", "--mu-s", "1"],
     "--A1: required for --family harmonic"),
    ("duty-cycle-outside", ["point", *POWERLAW[:6], "--tau0", "1.5", *POWERLAW[8:]], "--tau0"),
    ("fourier-not-numbers", ["point", "--family", "fourier", "--A", "0.5,x", "--T", "1", "--mu-n", "1", "--mu-s", "1"],
     "--A: expected comma-separated numbers"),
    ("fourier-sine-count", ["point", "--family", "fourier", "--A", "0.5,0.2", "--B", "0.1,0.2", "--T", "1",
                            "--mu-n", "1", "--mu-s", "1"], "--B"),
    ("bad-method", ["point", *HARMONIC, "--method", "rk4"], "--method"),
    ("rtol-outside", ["point", *HARMONIC, "--rtol", "2"], "--rtol"),
    ("p-outside", ["point", *HARMONIC, "--p", "2.5"], "--p"),
]


def _one_line(err: str) -> str:
    lines = err.strip().splitlines()
    assert len(lines) == 1, err
    assert "Traceback" not in err and lines[0].startswith("error: ")
    return lines[0]


@pytest.mark.parametrize("argv, words", [(a, w) for _, a, w in SOLVER_MISTAKES],
                         ids=[i for i, _, _ in SOLVER_MISTAKES])
def test_solver_mistake_is_one_line_naming_the_argument_and_exit_2(argv, words, capsys):
    from solver.__main__ import main

    assert main(argv) == 2
    out, err = capsys.readouterr()
    assert out == ""
    line = _one_line(err)
    assert words in line
    assert line.count("--") <= 2 + words.count("--") or "choose from" in line  # the argument named once


@pytest.fixture
def stores(tmp_path):
    """A folder with a regular file, a folder of other files and a Zarr store written by xarray."""
    import numpy as np
    import xarray as xr

    (tmp_path / "notes.txt").write_text("not a store\n")
    (tmp_path / "folder").mkdir()
    (tmp_path / "folder" / "a.txt").write_text("x")
    xr.Dataset({"v": ("x", np.arange(3.0))}).to_zarr(tmp_path / "plain.zarr")
    return tmp_path


#: (id, argv of ``python -m reports`` run in the ``stores`` folder, words the line must hold,
#: what must not exist afterwards); every one exit 2
REPORT_MISTAKES = [
    ("no-command", [], "command", None),
    ("unknown-command", ["biuld"], "biuld", None),
    ("unknown-option", ["build", "--outt", "r"], "--outt", "r"),
    ("store-missing", ["build", "nothere.zarr", "--out", "r"], "nothere.zarr", "r"),
    ("store-is-a-file", ["build", "notes.txt", "--out", "r"], "notes.txt", "r"),
    ("store-is-a-folder-of-files", ["build", "folder", "--out", "r"], "folder", "r"),
    ("store-not-written-by-the-pipeline", ["build", "plain.zarr", "--out", "r"], "plain.zarr", "r"),
    ("no-store-under-out", ["build"], "no pipeline store under out/", "out"),
    ("out-is-a-file", ["build", "plain.zarr", "--out", "notes.txt"], "notes.txt", None),
    ("out-cannot-be-created", ["build", "--out", "/proc/twolink/report"], "--out", None),
]


@pytest.mark.parametrize("argv, words, absent", [(a, w, x) for _, a, w, x in REPORT_MISTAKES],
                         ids=[i for i, *_ in REPORT_MISTAKES])
def test_report_mistake_is_one_line_naming_the_argument_and_exit_2(argv, words, absent, stores, monkeypatch,
                                                                   capsys):
    from reports.__main__ import main

    monkeypatch.chdir(stores)
    if argv[-2:] == ["--out", "/proc/twolink/report"]:
        import report_helpers as rh

        rh.synthetic_store(stores / "out" / "quick.zarr", REPO / "workflows" / "quick.toml")
    assert main(argv) == 2
    out, err = capsys.readouterr()
    assert out == ""
    assert words in _one_line(err)
    if absent:
        assert not (stores / absent).exists()
    assert (stores / "notes.txt").read_text() == "not a store\n"


@pytest.mark.parametrize("module, argv, words", [
    ("solver", ["point", "--family", "powerlaw", "--closing", "down10", "--T", "1", "--mu-n", "1", "--mu-s", "1"],
     "--closing: expected"),
    ("reports", ["build", "nothere.zarr"], "nothere.zarr"),
])
def test_the_real_entry_point_prints_one_line_and_exits_2(module, argv, words, tmp_path):
    env = dict(os.environ, PYTHONPATH=str(REPO) + os.pathsep + os.environ.get("PYTHONPATH", ""))
    proc = subprocess.run([sys.executable, "-m", module, *argv], cwd=tmp_path, env=env, capture_output=True,
                          text=True, timeout=300)
    assert proc.returncode == 2 and proc.stdout == ""
    assert words in _one_line(proc.stderr)
