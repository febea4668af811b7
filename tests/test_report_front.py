"""The report's front page and its command line (issue 45): a reduced run says so, the command
line and the page print the same counts, the paper's LaTeX is rendered, stores are found under
``out/`` at any depth, and a report of a user's own stores leads with them and has no empty
section.

Stores here are the pipeline's own skeletons with synthetic values (``report_helpers``), or one
tiny real scene: seconds, no solver runs of a paper scene.
"""

from __future__ import annotations

import html as _html
import json
import os
import re
import subprocess
import sys
from pathlib import Path

import pytest

import report_helpers as rh

REPO = Path(__file__).resolve().parent.parent
WORKFLOWS = REPO / "workflows"


def _cli(*args, cwd) -> subprocess.CompletedProcess:
    env = dict(os.environ, PYTHONPATH=str(REPO) + os.pathsep + os.environ.get("PYTHONPATH", ""))
    return subprocess.run([sys.executable, "-m", "reports", *map(str, args)], cwd=cwd, env=env,
                          capture_output=True, text=True, timeout=600)


def _text(fragment: str) -> str:
    """Visible text of an HTML fragment (tags dropped, entities decoded, spaces collapsed)."""
    return re.sub(r"\s+", " ", _html.unescape(re.sub(r"<[^>]+>", "", fragment))).strip()


def _sections(page: str) -> list[tuple[str, str]]:
    return re.findall(r"<section class='(\w+)' id='([^']*)'>", page)


@pytest.fixture(scope="module")
def quick_run(tmp_path_factory):
    """``out/quick/`` as ``paper --quick`` leaves it (two scenes' quick variants, synthetic
    values), the report built by ``reports build`` with no arguments."""
    root = tmp_path_factory.mktemp("quick_run")
    quick = root / "out" / "quick"
    quick.mkdir(parents=True)
    for name in ("quick", "harmonic_optimum"):
        rh.synthetic_store(quick / f"{name}.zarr", WORKFLOWS / f"{name}.toml", quick=True)
    proc = _cli("build", cwd=root)
    assert proc.returncode == 0, proc.stderr
    index = root / "out" / "report" / "index.html"
    return {"root": root, "proc": proc, "page": index.read_text(encoding="utf-8"), "index": index}


# -- finding the stores ---------------------------------------------------------------------------


def test_build_without_arguments_finds_the_quick_stores_and_names_them(quick_run):
    """Before issue 45 it looked at out/*.zarr only: after ``paper --quick`` (stores in
    out/quick/) it read 0 stores."""
    out = quick_run["proc"].stdout
    assert "(2 store(s) read" in out
    assert "out/quick/harmonic_optimum.zarr" in out and "out/quick/quick.zarr" in out


def test_default_stores_are_found_at_any_depth_but_not_inside_a_store(tmp_path):
    from reports._build import default_stores

    for p in ("a.zarr/inner.zarr", "quick/b.zarr", "deep/er/c.zarr", "report/x"):
        (tmp_path / p).mkdir(parents=True)
    found = [p.relative_to(tmp_path).as_posix() for p in default_stores(tmp_path)]
    assert found == ["a.zarr", "deep/er/c.zarr", "quick/b.zarr"]
    assert default_stores(tmp_path / "missing") == []


def test_two_stores_of_one_scene_read_the_one_nearer_out_and_name_the_other(tmp_path):
    (tmp_path / "out" / "quick").mkdir(parents=True)
    rh.synthetic_store(tmp_path / "out" / "quick.zarr", WORKFLOWS / "quick.toml")
    rh.synthetic_store(tmp_path / "out" / "quick" / "quick.zarr", WORKFLOWS / "quick.toml", quick=True)
    proc = _cli("build", "--no-unrun", cwd=tmp_path)
    assert proc.returncode == 0, proc.stderr
    assert "(1 store(s) read" in proc.stdout and "out/quick.zarr" in proc.stdout
    assert re.search(r"left out out/quick/quick\.zarr: scene quick is read from out/quick\.zarr", proc.stderr)
    # the one read is the full-resolution store: the page does not call itself reduced
    assert "reduced resolution" not in (tmp_path / "out" / "report" / "index.html").read_text().lower()


def test_build_with_no_store_anywhere_is_one_line_and_exit_2(tmp_path):
    proc = _cli("build", cwd=tmp_path)
    assert proc.returncode == 2 and proc.stdout == ""
    assert proc.stderr.count("\n") == 1 and "no pipeline store under out/" in proc.stderr
    assert not (tmp_path / "out").exists()


# -- a reduced run says so ----------------------------------------------------------------------


def test_a_reduced_run_says_so_in_its_title_first_line_and_audit(quick_run):
    page = quick_run["page"]
    title = re.search(r"<title>(.*?)</title>", page).group(1)
    assert "reduced resolution" in title
    header = page[page.index("<header>"):page.index("</header>")]
    first = re.findall(r"<(?:p|div)[^>]*>(.*?)</(?:p|div)>", header, re.S)[0]
    assert "Reduced resolution" in first and "2 of 2 stores" in first and "paper --quick" in _text(first)
    audit = page[page.index("<section class='audit'"):]
    assert "Reduced resolution" in audit[:audit.index("<table")]
    assert "audit: reduced resolution: " in quick_run["proc"].stdout


def test_a_full_resolution_store_is_not_called_reduced(tmp_path):
    """Negative control: the same scene at the resolution of its file."""
    (tmp_path / "out").mkdir()
    rh.synthetic_store(tmp_path / "out" / "quick.zarr", WORKFLOWS / "quick.toml")
    proc = _cli("build", cwd=tmp_path)
    assert proc.returncode == 0, proc.stderr
    page = (tmp_path / "out" / "report" / "index.html").read_text()
    body = page[page.index("<body>"):]
    assert "reduced resolution" not in body.lower() and "reduced" not in proc.stdout


# -- one source for every count -----------------------------------------------------------------


def test_command_line_and_page_print_the_same_audit_sentence(quick_run):
    """Before issue 45 the command line said 'N agree (3 by construction)' where the page said
    'N - 3 agree (and 3 more ...)'."""
    from reports._audit import audit_counts, audit_sentence

    line = next(x for x in quick_run["proc"].stdout.splitlines() if x.startswith("audit: "))
    sentence = re.sub(r"^audit: (reduced resolution: )?", "", line).rsplit(" (", 1)[0]
    page = quick_run["page"]
    summary = _text(re.search(r"<p class='audit-summary'>(.*?)</p>", page, re.S).group(1))
    assert summary == sentence + "."
    doc = json.loads((quick_run["index"].parent / "audit.json").read_text())
    n = audit_counts(doc)
    assert sentence == audit_sentence(n)
    numbers = [int(x) for x in re.findall(r"\b(\d+) (?:claims|agree|more|differ|cannot judge|not run)", sentence)]
    assert numbers[:3] == [n["claims"], n["reproduced"], n["by construction"]]
    assert (n["reproduced"] + n["by construction"] + n["differs"] + n["cannot judge"] + n["not run"] == n["claims"]
            == len(doc))
    assert n["explained"] + n["unexplained"] == n["differs"]


def test_audit_counts_from_rows_and_from_audit_json_agree():
    """audit_counts reads AuditRow objects and audit.json's dicts alike (the CLI reads the JSON,
    the page the rows)."""
    from reports._audit import AuditRow, Claim, audit_counts

    def claim(cid, built=""):
        return Claim(id=cid, figure="F", claim="c", paper_value="1", expect={"min": 0}, compute="stat", args={},
                     by_construction=built)

    rows = [AuditRow(claim("a"), "agrees", "", None), AuditRow(claim("b", "nested"), "agrees", "", None),
            AuditRow(claim("c"), "differs", "", None, cause="unexplained"),
            AuditRow(claim("d"), "differs", "", None, cause="domain"), AuditRow(claim("e"), "not run", "", None),
            AuditRow(claim("f"), "cannot judge", "", None)]
    doc = [{"verdict": r.verdict, "by_construction": r.claim.by_construction or None, "cause": r.cause} for r in rows]
    n = audit_counts(rows)
    assert n == audit_counts(doc)
    assert (n["claims"], n["agrees"], n["reproduced"], n["by construction"], n["explained"], n["unexplained"],
            n["not run"], n["cannot judge"]) == (6, 2, 1, 1, 1, 1, 1, 1)


# -- the paper's LaTeX --------------------------------------------------------------------------


@pytest.mark.parametrize("tex, rendered", [
    (r"as $(\mu_n \mu_s)^{1/4}T \to 0$ and $\infty$.", "as (μ<sub>n</sub> μ<sub>s</sub>)<sup>1/4</sup>T → 0 and ∞."),
    (r"for $2^{-3} \leq \mu_n/\mu_s \leq 2^3$", "for 2<sup>-3</sup> ≤ μ<sub>n</sub>/μ<sub>s</sub> ≤ 2<sup>3</sup>"),
    (r"each $K_{\mbox{max}}$", "each K<sub>max</sub>"),
    (r"(i.e.~small, $\phi = \pi/2$)", "(i.e.\u00a0small, φ = π/2)"),
    ("scene best_efficiency {x} <b> 1 < 2", "scene best_efficiency {x} &lt;b&gt; 1 &lt; 2"),  # no math: as written
])
def test_tex_is_rendered_as_unicode_html(tex, rendered):
    from reports._labels import tex_html

    assert tex_html(tex) == rendered


def test_every_quoted_sentence_of_the_registry_renders_without_tex():
    from reports._audit import load_claims
    from reports._labels import tex_html

    quotes = [c.quote for c in load_claims() if c.quote]
    assert sum("$" in q for q in quotes) >= 10  # the registry quotes LaTeX (else this tests nothing)
    for q in quotes:
        text = tex_html(q)
        assert "$" not in text and "\\" not in text and "^" not in text and "_{" not in text, (q, text)


def test_quoted_sentences_on_the_page_carry_no_raw_latex(quick_run):
    page = quick_run["page"]
    quotes = re.findall(r"the paper: “(.*?)”</div>", page, re.S)
    assert len(quotes) >= 10
    assert not [q for q in quotes if "$" in q or "\\" in q], "raw LaTeX on the page"
    assert any("μ<sub>n</sub>/μ<sub>s</sub>" in q for q in quotes)


# -- contents first -----------------------------------------------------------------------------


def test_contents_come_before_the_audit_table(quick_run):
    page = quick_run["page"]
    assert page.index("<nav id='toc'>") < page.index("<section class='audit'") < page.index("<table class='audit'>")
    assert "<li><a href='#audit'>Reproduction audit</a></li>" in page


# -- a user's own stores ------------------------------------------------------------------------


@pytest.fixture(scope="module")
def own_run(tmp_path_factory):
    """One real tiny store of a user's own scene under out/, the report built with no arguments."""
    root = tmp_path_factory.mktemp("own_run")
    out = root / "out"
    out.mkdir()
    rh.build_store(out, "tiny_plane")
    proc = _cli("build", cwd=root)
    assert proc.returncode == 0, proc.stderr
    return {"root": root, "proc": proc, "page": (out / "report" / "index.html").read_text(encoding="utf-8")}


def test_a_report_of_own_stores_leads_with_them_and_has_no_empty_section(own_run):
    """Before issue 45: titled 'reproduction report', 101 'not run' claims and 20 empty figure
    sections first, the user's scene last."""
    page = own_run["page"]
    title = re.search(r"<title>(.*?)</title>", page).group(1)
    assert "reproduction" not in title.lower() and "tiny_plane" in title
    assert _sections(page) == [("scene", "own-tiny_plane")]
    assert "id='audit'" not in page and "not run" not in page and "not yet run" not in page
    assert "<h3 id='scene-tiny_plane'>" in page
    assert not (own_run["root"] / "out" / "report" / "audit.json").exists()
    assert "audit: none" in own_run["proc"].stdout


def test_no_audit_puts_own_scenes_first_and_drops_empty_figures(tmp_path):
    """With a shipped scene among the stores the audit is on unless --no-audit; with it the
    user's scene leads and only figures with a store have a section."""
    out = tmp_path / "out"
    out.mkdir()
    rh.build_store(out, "tiny_plane")
    rh.synthetic_store(out / "harmonic_grid.zarr", WORKFLOWS / "harmonic_grid.toml")
    with_audit = _cli("build", "--out", tmp_path / "a", cwd=tmp_path)
    assert with_audit.returncode == 0, with_audit.stderr
    page = (tmp_path / "a" / "index.html").read_text()
    assert "id='audit'" in page and (tmp_path / "a" / "audit.json").is_file()  # control: the paper's report
    proc = _cli("build", "--no-audit", "--out", tmp_path / "b", cwd=tmp_path)
    assert proc.returncode == 0, proc.stderr
    page = (tmp_path / "b" / "index.html").read_text()
    sections = _sections(page)
    assert sections[0] == ("scene", "own-tiny_plane")
    assert [s for s in sections if s[0] == "figure"] == [("figure", "fig-EtaA0A1")]
    assert "id='audit'" not in page and "not yet run" not in page


def test_no_unrun_drops_the_figures_no_store_draws(quick_run, tmp_path):
    proc = _cli("build", "--no-unrun", "--out", tmp_path / "r", cwd=quick_run["root"])
    assert proc.returncode == 0, proc.stderr
    page = (tmp_path / "r" / "index.html").read_text()
    figures = [a for c, a in _sections(page) if c == "figure"]
    assert figures and "No store of a scene reproducing this figure" not in page
    assert "not yet run" not in page
    every = [a for c, a in _sections(quick_run["page"]) if c == "figure"]
    assert len(every) > len(figures)  # control: without the flag the empty figures are there
