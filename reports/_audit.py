"""The reproduction audit: every quantitative claim of the paper's results, our value from the
stores and a verdict computed at build time.

The claims live in ``reports/claims.toml`` (claim in words, the paper's value, the tolerance,
and which store and reduction of :mod:`reports._claim_values` computes our value); nothing
here holds a result. Verdicts:

* **agrees** — our value is within the claim's tolerance;
* **differs** — it is not, and the reason says what the data show (an optimum on the edge of
  the scanned domain, a grid coarser than the claim's precision, failed points, or a
  difference beyond our error estimate);
* **cannot judge** — the data cannot decide the claim: the region it speaks of is not stated
  by the paper (``cannot_judge`` in ``claims.toml``), or a polished optimum it reads did not
  converge (``_polished_status`` ≠ 0); our value is still shown (issue 44, ``reports/CAUSES.md``);
* **not run** — the store the claim needs is missing, or lacks the cells it needs.

A claim may carry ``beside``: the same computation on another domain (e.g. the wider τ0 window
beside the paper's), shown in the reason without a verdict of its own.

A claim that differs may carry a *cause* (:mod:`reports._causes`, criteria in
``reports/CAUSES.md``): its kind's check, registered with the claim in ``claims.toml`` and run on
the stores here together with the kind's negative control; the row shows the cause, the check's
result and its control, ``audit.json`` its ``cause``, ``evidence`` and ``control``.  A claim whose
check does not hold, whose control fails, or that has none is ``unexplained``.

Every claim states the basis of its tolerance (``basis``: a shared rule of CAUSES.md or a
source); a claim that could not have differed for any data carries ``by_construction`` and is
counted apart from the reproductions.
"""

from __future__ import annotations

import json
import math
import tomllib
from dataclasses import dataclass
from pathlib import Path

from ._causes import CAUSES, Cause, Evidence, control_word, explain, merge_args, miss, parse_cause, tolerance_text
from ._claim_values import COMPUTE, Measurement, NotComputed
from ._labels import tex_html
from ._site import esc

__all__ = ["CLAIMS_FILE", "Claim", "AuditRow", "RegistryError", "load_claims", "evaluate_claims", "verdict", "audit_html",
           "audit_counts", "cause_counts", "audit_sentence", "audit_summary", "write_audit_json", "VERDICTS", "CAUSES"]

CLAIMS_FILE = Path(__file__).resolve().with_name("claims.toml")
VERDICTS = ("agrees", "differs", "cannot judge", "not run")
_EXPECT_KEYS = ({"value", "tolerance"}, {"value", "factor"}, {"range", "tolerance"}, {"min"}, {"max"}, {"min", "max"})


class RegistryError(ValueError):
    """claims.toml is malformed (the message names the claim)."""


@dataclass(frozen=True)
class Claim:
    """One row of the registry."""

    id: str
    figure: str
    claim: str
    paper_value: str
    expect: dict
    compute: str
    args: dict
    cause: Cause | None = None
    basis: str = ""
    by_construction: str = ""
    quote: str = ""
    cannot_judge: str = ""
    beside: tuple = ()

    @property
    def scenes(self) -> list[str]:
        """Every scene the claim reads (from ``args``, including gain's two sides)."""
        out = [self.args["scene"]] if "scene" in self.args else []
        for side in ("numerator", "denominator", "base", "partial", "full"):
            if isinstance(self.args.get(side), dict) and "scene" in self.args[side]:
                out.append(self.args[side]["scene"])
        return list(dict.fromkeys(out))

    def tolerance_text(self) -> str:
        return tolerance_text(self.expect)


@dataclass
class AuditRow:
    claim: Claim
    verdict: str
    reason: str
    measurement: Measurement | None
    cause: str | None = None          # for a claim that differs: a kind of CAUSES or "unexplained"
    evidence: Evidence | None = None  # what the cause check computed

    def to_json(self) -> dict:
        m = self.measurement
        value = None
        if m is not None:
            value = list(m.value) if isinstance(m.value, tuple) else m.value
            value = _json_number(value)
        return {"id": self.claim.id, "figure": self.claim.figure, "claim": self.claim.claim,
                "paper_value": self.claim.paper_value, "expect": self.claim.expect,
                "tolerance": self.claim.tolerance_text(), "our_value": value,
                "where": m.where if m else None, "resolution": m.resolution if m else None,
                "error_estimate": m.error if m else None, "verdict": self.verdict, "reason": self.reason,
                "scenes": self.claim.scenes, "compute": self.claim.compute, "cause": self.cause,
                "why": self.claim.cause.why if self.claim.cause and self.cause else None,
                "evidence": self.evidence.to_json() if self.evidence else None,
                "control": self.evidence.to_json()["control"] if self.evidence else None,
                "basis": self.claim.basis, "by_construction": self.claim.by_construction or None,
                "quote": self.claim.quote or None, "cannot_judge": self.claim.cannot_judge or None}


def _json_number(v):
    if isinstance(v, list):
        return [_json_number(x) for x in v]
    return None if v is None or not math.isfinite(v) else float(v)


def load_claims(path: Path | str = CLAIMS_FILE) -> list[Claim]:
    """Parse and check the registry: unique ids, a known reduction, a well-formed expectation."""
    doc = tomllib.loads(Path(path).read_text(encoding="utf-8"))
    out, seen = [], set()
    for k, c in enumerate(doc.get("claims", [])):
        cid = c.get("id", f"#{k}")
        missing = [f for f in ("id", "figure", "claim", "paper_value", "expect", "compute", "args", "basis")
                   if f not in c]
        if missing:
            raise RegistryError(f"claim {cid}: missing {', '.join(missing)}")
        if cid in seen:
            raise RegistryError(f"claim {cid}: duplicate id")
        seen.add(cid)
        if c["compute"] not in COMPUTE:
            raise RegistryError(f"claim {cid}: unknown compute {c['compute']!r} (known: {', '.join(COMPUTE)})")
        if set(c["expect"]) not in _EXPECT_KEYS:
            raise RegistryError(f"claim {cid}: expect must be one of {[sorted(s) for s in _EXPECT_KEYS]}")
        try:
            cause = parse_cause(cid, c.get("cause"), dict(c["args"]))
        except ValueError as exc:
            raise RegistryError(str(exc)) from None
        out.append(Claim(id=cid, figure=c["figure"], claim=c["claim"], paper_value=str(c["paper_value"]),
                         expect=dict(c["expect"]), compute=c["compute"], args=dict(c["args"]), cause=cause,
                         basis=str(c["basis"]), by_construction=str(c.get("by_construction", "")),
                         quote=str(c.get("quote", "")), cannot_judge=str(c.get("cannot_judge", "")),
                         beside=_parse_beside(cid, c.get("beside"))))
    return out


def _parse_beside(cid: str, doc) -> tuple:
    """``beside = { label, override }`` (or an array of such tables) of a claim: the same
    computation with ``override`` merged into its arguments, quoted beside the verdict."""
    if doc is None:
        return ()
    out = []
    for b in (doc if isinstance(doc, list) else [doc]):
        if not isinstance(b, dict) or "label" not in b or not isinstance(b.get("override"), dict):
            raise RegistryError(f"claim {cid}: beside needs label and override (a table)")
        out.append({"label": str(b["label"]), "override": dict(b["override"])})
    return tuple(out)


# ---------------------------------------------------------------------------
# Verdicts
# ---------------------------------------------------------------------------


def _num(v) -> str:
    if isinstance(v, tuple):
        return "–".join(_num(x) for x in v)
    return "n/a" if v is None or not math.isfinite(v) else f"{v:.3g}"


def _side(expect: dict, value) -> str:
    vals = list(value) if isinstance(value, tuple) else [value]
    ref = expect.get("value", expect.get("range", [expect.get("min", expect.get("max", 0))])[0])
    above = sum(v > ref for v in vals)
    return "above" if above == len(vals) else "below" if above == 0 else "across"


def verdict(claim: Claim, m: Measurement) -> tuple[str, str]:
    """(verdict, reason) of ``claim`` given our measurement ``m``, reasons drawn from the data."""
    e = claim.expect
    short = miss(e, m.value)
    notes = []
    if m.edges:
        notes.append("at the domain edge: " + "; ".join(m.edges))
    if m.failed[0] and m.failed[1]:
        notes.append(f"{m.failed[0]} of {m.failed[1]} selected cells have no valid value")
    why_not = claim.cannot_judge or m.cannot_judge
    if why_not:  # the data cannot decide it: said, with our value, and not counted as agrees or differs
        return "cannot judge", "; ".join([why_not, f"ours {_num(m.value)} ({claim.tolerance_text()} would "
                                          f"{'hold' if short == 0 else 'not hold'})"] + notes)
    if math.isnan(short):
        return "differs", "; ".join([f"no valid value ({m.where})"] + notes)
    if short == 0:
        return "agrees", "; ".join([f"ours {_num(m.value)} is within the tolerance ({claim.tolerance_text()})"] + notes)
    reasons = []
    if m.edges:
        reasons.append(f"at the domain edge ({'; '.join(m.edges)}): the optimum lies beyond the scanned range, "
                       f"and ours is {_side(e, m.value)} the paper's value")
    resolution = ""
    agreeing = [nb for nb in m.neighbours if miss(e, nb) == 0]
    if agreeing:
        resolution = (f"grid resolution coarser than the claim's precision: {m.coarse}, and the neighbouring grid "
                      f"value {_num(agreeing[0])} would agree")
    elif m.coarse and m.coarse_value >= short and m.coarse_side in ("", _side(e, m.value)):
        resolution = f"grid resolution coarser than the claim's precision: {m.coarse}" + (
            f", more than the miss {short:.2g}" if math.isfinite(m.coarse_value) else "")
    elif math.isfinite(m.error_value) and m.error_value >= short:
        resolution = (f"grid resolution coarser than the claim's precision: our error estimate ({m.error}) is "
                      f"larger than the miss {short:.2g}")
    if resolution and not m.edges:
        reasons.append(resolution)
    if m.failed[0] and m.failed[1]:
        reasons.append(f"{m.failed[0]} of {m.failed[1]} selected cells have no valid value")
    if not reasons:
        est = (f", {short / m.error_value:.3g} times our error estimate ({m.error})"
               if math.isfinite(m.error_value) and m.error_value > 0 else "")
        reasons.append(f"ours is {_side(e, m.value)} the paper's value, {short:.2g} beyond the tolerance "
                       f"({claim.tolerance_text()}){est}: a difference in the data, not in its resolution")
    return "differs", "; ".join(reasons)


def _beside_text(c: Claim, by_name) -> str:
    """The claim's computation on each ``beside`` domain, in words (no verdict of its own)."""
    out = []
    for b in c.beside:
        try:
            mb = COMPUTE[c.compute](by_name, **merge_args(c.args, b["override"]))
        except NotComputed as exc:
            out.append(f"beside, {b['label']}: not computed ({exc})")
            continue
        out.append(f"beside, {b['label']}: {_num(mb.value)} ({mb.where})")
    return "; ".join(out)


def evaluate_claims(claims, stores) -> list[AuditRow]:
    """One row per claim against ``stores`` (SceneStore objects; the first store of a scene name
    is used)."""
    by_name = {}
    for sd in stores:
        by_name.setdefault(sd.name, sd)
    rows = []
    for c in claims:
        missing = [s for s in c.scenes if s not in by_name]
        if missing:
            rows.append(AuditRow(c, "not run", f"no store of scene {', '.join(missing)} ("
                                                f"{'; '.join(f'python -m pipeline run {s}' for s in missing)})", None))
            continue
        try:
            m = COMPUTE[c.compute](by_name, **c.args)
        except NotComputed as exc:
            rows.append(AuditRow(c, "not run", str(exc), None))
            continue
        v, reason = verdict(c, m)
        if c.beside:
            reason += "; " + _beside_text(c, by_name)
        row = AuditRow(c, v, reason, m)
        if v == "differs":
            row.cause, row.evidence = explain(c.cause, by_name, c, m)
            if row.cause != "unexplained":  # the data's difference now has its computed cause
                row.reason = row.reason.replace(": a difference in the data, not in its resolution",
                                                f" (cause: {row.cause}, beside)")
        rows.append(row)
    return rows


# ---------------------------------------------------------------------------
# Output
# ---------------------------------------------------------------------------

_CLASS = {"agrees": "v-agrees", "differs": "v-differs", "cannot judge": "v-notrun", "not run": "v-notrun"}


def _verdict_items(rows) -> list[tuple[str, bool, str | None]]:
    """(verdict, by construction, cause) per claim, from AuditRow objects or audit.json's dicts:
    the one reading every count below is made from."""
    items = []
    for r in rows:
        if isinstance(r, AuditRow):
            items.append((r.verdict, bool(r.claim.by_construction), r.cause))
        else:
            items.append((r["verdict"], bool(r.get("by_construction")), r.get("cause")))
    return items


def audit_counts(rows) -> dict:
    """Every count the audit prints, from ``rows`` (AuditRow objects or audit.json's list): per
    verdict (``agrees`` includes the claims true ``by construction``), ``claims``,
    ``reproduced`` (agree, not by construction), ``explained`` and ``unexplained`` (differ with
    or without a cause that holds) and ``causes`` (differing claims per kind of CAUSES).  The
    page (:func:`audit_html`) and the command line (:func:`audit_summary`) print these, through
    the one sentence :func:`audit_sentence`."""
    items = _verdict_items(rows)
    out = {v: sum(verdict == v for verdict, _, _ in items) for v in VERDICTS}
    out["by construction"] = sum(verdict == "agrees" and built for verdict, built, _ in items)
    out["claims"] = len(items)
    out["reproduced"] = out["agrees"] - out["by construction"]
    out["causes"] = {k: sum(verdict == "differs" and cause == k for verdict, _, cause in items)
                     for k in (*CAUSES, "unexplained")}
    out["unexplained"] = out["causes"]["unexplained"]
    out["explained"] = out["differs"] - out["unexplained"]
    return out


def cause_counts(rows) -> dict:
    """Claims that differ, by cause (every kind of CAUSES, then ``unexplained``)."""
    return audit_counts(rows)["causes"]


def _sentence_parts(n: dict) -> list[tuple[str, str]]:
    """The audit's summary as (css class or "", text) pieces."""
    by_cause = ", ".join(f"{k} {n['causes'][k]}" for k in CAUSES if n["causes"][k])
    return [("", f"{n['claims']} claims of the paper's results: "),
            ("v-agrees", f"{n['reproduced']} agree"),
            ("", f" (and {n['by construction']} more true by construction, not counted as reproductions), "),
            ("v-differs", f"{n['explained']} differ with a cause whose check and control hold"),
            ("", (f" ({by_cause})" if by_cause else "") + ", "),
            ("v-unexplained", f"{n['unexplained']} differ unexplained"),
            ("", ", "),
            ("v-notrun", f"{n['cannot judge']} cannot judge"),
            ("", ", "),
            ("v-notrun", f"{n['not run']} not run")]


def audit_sentence(counts: dict, *, html: bool = False) -> str:
    """The audit's summary sentence from :func:`audit_counts`: the same words and numbers on the
    page (``html``: each verdict's count in its colour) and on the command line."""
    return "".join(f"<span class='{cls}'>{esc(text)}</span>" if html and cls else (esc(text) if html else text)
                   for cls, text in _sentence_parts(counts))


def _cause_cell(r) -> str:
    if r.verdict != "differs":
        return "—"
    ev = r.evidence
    why = f"<div class='small'>{esc(r.claim.cause.why)}</div>" if r.claim.cause else ""
    if ev is None:
        check = "<div class='small'>no cause check registered</div>"
    else:
        ctrl = ev.control
        control = ("" if ctrl is None else
                   f"<div class='small'><b>control</b> ({control_word(ctrl)}): "
                   f"{esc(ctrl.get('what', ''))}. {esc(ctrl.get('result', ''))}</div>")
        check = (f"<div class='small'><b>evidence</b> (<code>{esc(ev.check)}</code>: "
                 f"{'cannot judge' if not ev.judged else 'criterion met' if ev.holds else 'criterion not met'}): "
                 f"{esc(ev.result)}</div>{control}")
    return f"<b class='cause-{esc(r.cause)}'>{esc(r.cause)}</b>{why}{check}"


def _claim_notes(c) -> str:
    notes = f"<div class='small'>the paper: “{tex_html(c.quote)}”</div>" if c.quote else ""
    notes += f"<div class='small'>tolerance basis: {esc(c.basis)}</div>" if c.basis else ""
    if c.by_construction:
        notes += f"<div class='small'><b>true by construction</b> (not counted as a reproduction): {esc(c.by_construction)}</div>"
    return notes


def audit_html(rows, figure_anchor=lambda label: f"fig-{label}", *, reduced: str = "") -> str:
    """The audit section (front page): a summary line, every differing claim with its cause,
    evidence and control, and one table row per claim.  ``reduced``: a sentence saying the stores
    are of reduced resolution (``paper --quick``), shown first."""
    n = audit_counts(rows)
    body, differing = [], []
    for r in rows:
        c, m = r.claim, r.measurement
        ours = "—"
        if m is not None:
            ours = (f"<b>{esc(_num(m.value))}</b><div class='small'>{esc(m.where)}</div>"
                    f"<div class='small'>{esc(m.resolution)}</div>"
                    + (f"<div class='small'>error: {esc(m.error)}</div>" if m.error else ""))
        verdict_text = r.verdict + (" (by construction)" if r.verdict == "agrees" and c.by_construction else "")
        body.append(f"<tr id='claim-{esc(c.id)}'><td><a href='#{figure_anchor(c.figure)}'>{esc(c.figure)}</a>: "
                    f"{esc(c.claim)}<div class='small'><code>{esc(c.id)}</code></div>{_claim_notes(c)}</td>"
                    f"<td>{esc(c.paper_value)}<div class='small'>{esc(c.tolerance_text())}</div></td><td>{ours}</td>"
                    f"<td class='{_CLASS[r.verdict]}'>{esc(verdict_text)}</td><td>{_cause_cell(r)}</td>"
                    f"<td>{esc(r.reason)}</td></tr>")
        if r.verdict == "differs":
            differing.append(f"<li><a href='#claim-{esc(c.id)}'><code>{esc(c.id)}</code></a>: "
                             f"<b class='cause-{esc(r.cause)}'>{esc(r.cause)}</b> — ours {esc(_num(m.value) if m else 'n/a')}"
                             f", paper {esc(c.paper_value)}"
                             + (f"; evidence: {esc(r.evidence.result)}" if r.evidence else
                                f"; no cause registered; what the data say: {esc(r.reason)}")
                             + (f"; control ({control_word(r.evidence.control)}): "
                                f"{esc(r.evidence.control.get('result', ''))}"
                                if r.evidence and r.evidence.control else "") + "</li>")
    return (f"<section class='audit' id='audit'><h2>Reproduction audit</h2>"
            + (f"<p class='warn reduced'><b>Reduced resolution.</b> {esc(reduced)}</p>" if reduced else "")
            + f"<p class='audit-summary'><b>{audit_sentence(n, html=True)}</b>.</p>"
            "<p>Each claim is checked against the stores when this report is built. A cause counts only when its "
            "check meets its kind's criterion and its negative control passes (<code>reports/CAUSES.md</code>); "
            "every tolerance states its basis. The claims, their tolerances, causes and the reductions computing our "
            "values are in <code>reports/claims.toml</code>; the table is also written as <code>audit.json</code> "
            "beside this page.</p>"
            + (f"<details open><summary><b>The {len(differing)} claims that differ</b>: cause, evidence and "
               f"control</summary><ul class='small'>{''.join(differing)}</ul></details>" if differing else "")
            + "<div class='table-scroll'><table class='audit'><colgroup><col class='c-claim'><col class='c-paper'><col class='c-ours'>"
            "<col class='c-verdict'><col class='c-cause'><col class='c-reason'></colgroup>"
            "<tr><th>claim</th><th>paper</th><th>ours (from the stores)</th><th>verdict</th><th>cause</th>"
            "<th>reason</th></tr>"
            + "".join(body) + "</table></div></section>")


def audit_summary(path: Path, *, reduced: str = "") -> str:
    """The audit's summary sentence (:func:`audit_sentence`, as on the page) from an audit.json,
    then its path; ``reduced``: prefixed "reduced resolution: " when the stores were."""
    doc = json.loads(Path(path).read_text(encoding="utf-8"))
    return (("reduced resolution: " if reduced else "") + f"{audit_sentence(audit_counts(doc))} ({path})")


def write_audit_json(rows, path: Path) -> Path:
    path = Path(path)
    path.write_text(json.dumps([r.to_json() for r in rows], indent=1, ensure_ascii=False), encoding="utf-8")
    return path
