"""Why a claim differs: a cause for a verdict other than "agrees", shown by a check that can fail.

The criterion of every kind, its control and the shared rules are written in
``reports/CAUSES.md`` (before the checks); this module implements exactly that. A claim of
``claims.toml`` that we do not reproduce may carry a ``[claims.cause]`` table::

    [claims.cause]
    kind = "resolution"            # one of CAUSES
    check = "converges"            # the kind's check (KIND_CHECK)
    why = "..."                    # the cause in words (what the check is to show)
    [claims.cause.args]            # the check's arguments
    ...

Each check is ``f(stores, claim, measurement, **args) -> Evidence``: whether the kind's
criterion is met (``holds``), its result in words, the numbers it compared, and its
``control`` (the kind's negative control, run on the same stores: the paper's value moved
where the cause cannot reach, a reading on a cell where the sentence is false, the
independence of a cross-check's sides). The claim's cause is ``kind`` only when the check
holds **and** its control passes; otherwise ``unexplained``, with the check's result (what was
tried). No check has a free threshold: the claim's accepted set, the stores' error estimates
and the shared rules of CAUSES.md are the only ones.
"""

from __future__ import annotations

import copy
import math
from dataclasses import dataclass, field

import numpy as np

from ._claim_values import COMPUTE, Measurement, NotComputed, is_optima, scene_store

__all__ = ["CAUSES", "CHECKS", "KIND_CHECK", "RULES", "Cause", "Evidence", "control_word", "explain", "merge_args", "miss",
           "parse_cause", "reflect", "tolerance_text"]

CAUSES = ("domain", "convention", "resolution", "cross-check", "reading", "defect")

#: the check each kind must use (CAUSES.md)
KIND_CHECK = {"resolution": "converges", "domain": "restricted", "cross-check": "cross_check",
              "reading": "reading", "convention": "recompute"}

#: the shared rules a tolerance or a reading's threshold may cite (CAUSES.md, "Shared rules")
RULES = ("printed", "figure", "most", "all", "grid", "angle", "words", "half", "much", "flat", "except", "trend",
         "limit", "judgement")


@dataclass(frozen=True)
class Cause:
    """The registered cause of a claim: its kind, the check computing it, and why."""

    kind: str
    check: str
    why: str
    args: dict = field(default_factory=dict)


@dataclass
class Evidence:
    """What a cause check computed.

    holds : the kind's criterion is met
    result : the outcome in words (printed in the audit row)
    numbers : the numbers compared, by name (written to audit.json)
    control : the kind's negative control: {"what", "passed", "result", "numbers"}; ``passed`` is
        None when the check cannot judge
    judged : False when the check's inputs cannot decide anything (the levels of a resolution
        series or the two sides of a cross-check read identical inputs, e.g. ``paper --quick``
        reducing every level to one grid): the check neither holds nor has a control that passed
        ("cannot judge", issue 44 item 5)
    """

    check: str
    holds: bool
    result: str
    numbers: dict = field(default_factory=dict)
    control: dict | None = None
    judged: bool = True

    @property
    def shown(self) -> bool:
        """The cause is shown: the criterion holds and the control passed."""
        return bool(self.holds and self.control is not None and self.control.get("passed"))

    def to_json(self) -> dict:
        ctrl = None
        if self.control is not None:
            ctrl = {k: (_plain(v) if k == "numbers" else v) for k, v in self.control.items()}
            if "numbers" in ctrl:
                ctrl["numbers"] = {k: _plain(v) for k, v in self.control["numbers"].items()}
        return {"check": self.check, "holds": self.holds, "judged": self.judged, "result": self.result,
                "numbers": {k: _plain(v) for k, v in self.numbers.items()}, "control": ctrl}


def _plain(v):
    if isinstance(v, (tuple, list)):
        return [_plain(x) for x in v]
    if isinstance(v, dict):
        return {str(k): _plain(x) for k, x in v.items()}
    if isinstance(v, (float, np.floating, int, np.integer)) and not isinstance(v, bool):
        v = float(v)
        return v if math.isfinite(v) else None
    return v


def control_word(control: dict | None) -> str:
    """How a check's control came out, in one word: "passed", "FAILED", or "cannot judge" (its
    ``passed`` is None: the check's inputs were identical, issue 44 item 5)."""
    if control is None:
        return ""
    passed = control.get("passed")
    return "cannot judge" if passed is None else ("passed" if passed else "FAILED")


def _cannot_judge(check: str, why: str, numbers: dict) -> Evidence:
    """The evidence of a check whose inputs cannot decide anything: it does not hold, and its
    control neither passed nor failed."""
    words = f"cannot judge: {why}"
    return Evidence(check, False, words, numbers, judged=False,
                    control={"what": "none: the check's inputs are identical", "passed": None, "result": words})


def _arg_scenes(a: dict) -> set:
    out = {a["scene"]} if "scene" in a else set()
    for side in ("numerator", "denominator", "base", "partial", "full"):
        if isinstance(a.get(side), dict) and "scene" in a[side]:
            out.add(a[side]["scene"])
    return out


def parse_cause(cid: str, doc, claim_args: dict | None = None) -> Cause | None:
    """The ``[claims.cause]`` table of claim ``cid`` (None when absent); ValueError names the claim.

    Refused: an unknown kind or check, a check that is not its kind's (KIND_CHECK), a reading
    without its quote, other reading, rule and control, a domain without its evidence, and a
    cross-check whose second computation reads a scene the claim's own computation reads."""
    if doc is None:
        return None
    missing = [k for k in ("kind", "check", "why") if k not in doc]
    if missing:
        raise ValueError(f"claim {cid}: cause lacks {', '.join(missing)}")
    kind, check = doc["kind"], doc["check"]
    if kind not in CAUSES:
        raise ValueError(f"claim {cid}: cause kind {kind!r} is not one of {', '.join(CAUSES)}")
    if check not in CHECKS:
        raise ValueError(f"claim {cid}: unknown cause check {check!r} (known: {', '.join(CHECKS)})")
    if KIND_CHECK.get(kind) != check:
        raise ValueError(f"claim {cid}: a {kind} cause is shown by check {KIND_CHECK.get(kind)!r}, not {check!r}")
    args = dict(doc.get("args", {}))
    need = {"reading": ("quote", "other_reading", "rule", "expect", "control"), "domain": ("evidence",),
            "resolution": ("levels",), "convention": ("evidence",)}.get(kind, ())
    lacking = [k for k in need if k not in args]
    if lacking:
        raise ValueError(f"claim {cid}: a {kind} cause needs {', '.join(lacking)}")
    if kind == "reading" and args["rule"] not in RULES:
        raise ValueError(f"claim {cid}: reading rule {args['rule']!r} is not one of {', '.join(RULES)}")
    if kind == "cross-check" and claim_args is not None:
        second = args.get("args") if args.get("args") is not None else _merge(claim_args, args.get("override", {}))
        shared = _arg_scenes(claim_args) & _arg_scenes(second)
        if shared:
            raise ValueError(f"claim {cid}: a cross-check's two sides read the same store ({', '.join(sorted(shared))})")
    return Cause(kind=kind, check=check, why=doc["why"], args=args)


def explain(cause: Cause | None, stores, claim, m: Measurement | None) -> tuple[str, Evidence | None]:
    """(cause, evidence) of a claim that does not agree: the registered kind when its check holds
    and its control passes, else ``unexplained`` (also when no cause is registered or the check
    cannot run)."""
    if cause is None:
        return "unexplained", None
    try:
        ev = CHECKS[cause.check](stores, claim, m, **cause.args)
    except (NotComputed, KeyError, IndexError, ValueError, ZeroDivisionError) as exc:
        # a store without what the check reads: no cause shown, the row says why
        return "unexplained", Evidence(cause.check, False, f"the check could not run: {type(exc).__name__}: {exc}")
    return (cause.kind if ev.shown else "unexplained"), ev


# ---------------------------------------------------------------------------
# helpers
# ---------------------------------------------------------------------------


def _num(v) -> str:
    if isinstance(v, (tuple, list)):
        return "–".join(_num(x) for x in v)
    return "n/a" if v is None or not math.isfinite(v) else f"{v:.3g}"


def _merge(base: dict, override: dict) -> dict:
    """``base`` with ``override`` merged in, nested tables recursively; a value ``"drop"``
    removes the key."""
    out = copy.deepcopy(base)
    for k, v in override.items():
        if v == "drop":
            out.pop(k, None)
        elif isinstance(v, dict) and isinstance(out.get(k), dict) and v.get("replace") is not True:
            out[k] = _merge(out[k], v)
        else:
            out[k] = {kk: vv for kk, vv in v.items() if kk != "replace"} if isinstance(v, dict) else copy.deepcopy(v)
    return out


#: the public name of :func:`_merge` (a claim's ``beside`` and causes merge their overrides alike)
merge_args = _merge


def _measure(stores, claim, compute=None, args=None, override=None) -> tuple[Measurement, dict]:
    """Our value of ``claim`` recomputed with other arguments (``args`` in full, or the claim's
    own with ``override`` merged in) and maybe another reduction."""
    a = dict(args) if args is not None else _merge(claim.args, override or {})
    for s in _arg_scenes(a):
        scene_store(stores, s)
    return COMPUTE[compute or claim.compute](stores, **a), a


def miss(expect: dict, value) -> float:
    """How far ``value`` lies outside the accepted set (0 inside; NaN for no value)."""
    vals = list(value) if isinstance(value, tuple) else [value]
    if any(v is None or not math.isfinite(v) for v in vals):
        return math.nan
    if "range" in expect:
        if len(vals) != 2:
            return math.nan
        return max(max(abs(v - p) - expect["tolerance"], 0.0) for v, p in zip(vals, expect["range"]))
    if "factor" in expect:
        p = expect["value"]
        worst = max((max(v / p, p / v) if v * p > 0 else math.inf) for v in vals)
        return max(worst - expect["factor"], 0.0)
    if "tolerance" in expect:
        return max(max(abs(v - expect["value"]) - expect["tolerance"], 0.0) for v in vals)
    lo, hi = expect.get("min", -math.inf), expect.get("max", math.inf)
    return max(max(lo - v, v - hi, 0.0) for v in vals)


def reflect(expect: dict, ours) -> dict:
    """The accepted set ``expect`` reflected through our value ``ours`` (through the midpoint of a
    range value; end by end for a ``range`` expectation; in log for a ``factor``): the paper's
    value moved to the other side of ours by the same distance, where a cause that moves our
    value toward the paper cannot reach (CAUSES.md, the controls of resolution, domain and
    convention)."""
    vals = list(ours) if isinstance(ours, tuple) else [ours]
    c = float(np.mean(vals))
    if "range" in expect:
        ends = vals if len(vals) == 2 else [c, c]
        return {"range": [2 * v - p for v, p in zip(ends, expect["range"])], "tolerance": expect["tolerance"]}
    if "factor" in expect:
        return {"value": c * c / expect["value"], "factor": expect["factor"]}
    if "tolerance" in expect:
        return {"value": 2 * c - expect["value"], "tolerance": expect["tolerance"]}
    out = {}
    if "max" in expect:
        out["min"] = 2 * c - expect["max"]
    if "min" in expect:
        out["max"] = 2 * c - expect["min"]
    return out


def tolerance_text(e: dict) -> str:
    """The accepted set of an expectation in words ("± 0.05", "in [1.1, 1.57]", ...)."""
    if "tolerance" in e and "range" in e:
        return f"each end ± {e['tolerance']:g}"
    if "tolerance" in e:
        return f"± {e['tolerance']:g}"
    if "factor" in e:
        return f"within a factor {e['factor']:g}"
    lo, hi = e.get("min"), e.get("max")
    if lo is not None and hi is not None:
        return f"in [{lo:g}, {hi:g}]"
    return f"≥ {lo:g}" if lo is not None else f"≤ {hi:g}"


def _set_text(e: dict) -> str:
    if "value" in e:
        return f"{e['value']:.3g} {tolerance_text(e)}"
    if "range" in e:
        return f"{_num(tuple(e['range']))} {tolerance_text(e)}"
    return tolerance_text({k: float(f"{v:.3g}") for k, v in e.items()})


def _reflected_control(holds_for, claim, m, what: str) -> dict:
    """The control of resolution, domain and convention: the same decision against the claim's
    accepted set reflected through our value must not hold."""
    moved = reflect(claim.expect, m.value)
    held, words = holds_for(moved)
    return {"what": what, "passed": not held, "moved_expect": moved,
            "result": f"paper's accepted set moved to {_set_text(moved)} (reflected through ours "
                      f"{_num(m.value)}): {words} — " + ("not explained, as it must be" if not held
                                                         else "explained too: the check cannot tell")}


# ---------------------------------------------------------------------------
# the domain a computation scans, the grid it samples, the store it reads
# ---------------------------------------------------------------------------


def _reductions_of(a: dict) -> list[tuple[str, str | None]]:
    """(scene, reduction or None) of every source of a computation's arguments."""
    out = []
    for src in ([a] if "scene" in a else []) + [a[s] for s in ("numerator", "denominator", "base", "partial", "full")
                                                  if isinstance(a.get(s), dict)]:
        out.append((src["scene"], src.get("reduction")))
    return out


def _over_axes(sd, reduction):
    if reduction is None:
        return [d for d in sd.ds.dims if d in sd.ds.coords]
    for red in sd.reductions:
        if red["name"] == reduction:
            return [d for d in red.get("over", []) if d in sd.ds.coords]
    return []


def _domain(stores, a: dict) -> list:
    """The ranges a computation scans: per source, the extremes of every continuous axis its
    reduction maximises over (the optimiser's ensemble for an optima store)."""
    out = []
    for scene, reduction in _reductions_of(a):
        sd = scene_store(stores, scene)
        if is_optima(sd):
            sc = sd.science
            out.append(("optima", sc.get("optimizer", {}).get("direction"), sc.get("optimizer", {}).get("objective")))
            continue
        ext = []
        for d in _over_axes(sd, reduction):
            c = np.asarray(sd.ds[d].values)
            if c.dtype.kind in "fi" and c.size > 1:
                ext.append((d, round(float(c.min()), 9), round(float(c.max()), 9)))
        out.append(tuple(ext))
    return out


def _grid(stores, a: dict) -> list:
    """The grids a computation samples: per source, the coordinates of every axis its reduction
    maximises over (the starts and seed of an optima ensemble)."""
    out = []
    for scene, reduction in _reductions_of(a):
        sd = scene_store(stores, scene)
        if is_optima(sd):
            st = sd.science.get("starts", {})
            out.append(("starts", st.get("num"), st.get("seed")))
            continue
        out.append(tuple((d, tuple(np.round(np.asarray(sd.ds[d].values, dtype=np.float64), 9)))
                         for d in _over_axes(sd, reduction)))
    return out


def _inputs(stores, a: dict) -> list:
    """What a computation reads, per source: the grid it samples (:func:`_grid`), whether it
    reads the grid optimum or the polished one, and the polish's settings (method, budget,
    tolerance: every ``polish*`` key of the reduction) — two levels of a resolution series with
    the same inputs are the same computation, whatever their labels or store files."""
    out = []
    srcs = ([a] if "scene" in a else []) + [a[s] for s in ("numerator", "denominator", "base", "partial", "full")
                                           if isinstance(a.get(s), dict)]
    for src, grid in zip(srcs, _grid(stores, a)):
        sd = scene_store(stores, src["scene"])
        red = next((r for r in sd.reductions if r.get("name") == src.get("reduction")), {})
        polish = tuple(sorted((k, str(v)) for k, v in red.items() if k.startswith("polish")))
        polished = bool(red.get("polish")) and not src.get("grid")
        out.append((grid, polished, polish if polished else ()))
    return out


def _rtol(sd) -> float:
    """The solver tolerance of a store's values (the τ-grid rtol of an optima store)."""
    if is_optima(sd):
        return float(sd.science.get("optimizer", {}).get("grid_rtol", 0.0))
    return float(getattr(sd, "rtol", 0.0) or 0.0)


def _paths(stores, a: dict) -> set:
    return {str(scene_store(stores, s).path) for s, _ in _reductions_of(a)}


# ---------------------------------------------------------------------------
# resolution: converges
# ---------------------------------------------------------------------------


def _trend(values: list[float], noise: float = 0.0) -> tuple[bool, float, str]:
    """(converging, extrapolated limit, why not) of a sequence ordered coarse -> fine; a change
    no larger than ``noise`` (the levels' own solver tolerance) is no change."""
    d = np.diff(np.asarray(values, dtype=np.float64))
    if d.size < 2 or not np.all(np.isfinite(d)):
        return False, math.nan, "fewer than three finite levels"
    d = np.where(np.abs(d) <= noise, 0.0, d)
    if np.all(d == 0):
        return True, float(values[-1]), ""
    if d[-1] == 0:  # settled within the noise at the finest levels
        return True, float(values[-1]), ""
    signs = np.sign(d[d != 0])
    if not (np.all(signs > 0) or np.all(signs < 0)):
        return False, math.nan, "the changes change sign"
    mags = np.abs(d)
    if np.any(mags[1:] > mags[:-1]) or not mags[-1] < mags[-2]:
        return False, math.nan, "the changes do not shrink (" + ", ".join(f"{x:+.3g}" for x in d) + ")"
    q = mags[-1] / mags[-2]
    return True, float(values[-1] + d[-1] * q / (1 - q)), ""


def converges(stores, claim, m, *, levels: list, paper_level: int | None = None, paper_evidence: str = "") -> Evidence:
    """``resolution`` (CAUSES.md): ``levels`` (>= 3 tables, coarse -> fine, each ``label``,
    ``resolution`` and ``override``/``args``/``compute``) of the same computation on the same
    domain; they converge, and the trend (or the level at the paper's resolution, ``paper_level``
    with ``paper_evidence``) reaches the paper's accepted set."""
    if len(levels) < 3:
        raise ValueError("a resolution cause needs three or more levels")
    vals, words, domains, rtols, inputs = [], [], [], [], []
    for lv in levels:
        m2, a = _measure(stores, claim, lv.get("compute"), lv.get("args"), lv.get("override"))
        if isinstance(m2.value, tuple):
            raise ValueError("a resolution series needs a scalar value")
        vals.append(m2.value)
        domains.append(_domain(stores, a))
        inputs.append(_inputs(stores, a))
        rtols += [_rtol(scene_store(stores, sc)) for sc, _ in _reductions_of(a)]
        words.append(f"{lv['label']} ({lv['resolution']}): {_num(m2.value)}")
    ours = m.value
    same = [(levels[i]["label"], levels[j]["label"]) for i in range(len(levels)) for j in range(i + 1, len(levels))
            if inputs[i] == inputs[j]]
    if same:  # e.g. paper --quick reducing every level to one grid: no refinement took place
        return _cannot_judge("converges", "; ".join(f"{x} and {y}" for x, y in same) + " read identical inputs (the "
                             "same grid and the same polish): no refinement took place, so no convergence can be "
                             "shown or refuted. " + "; ".join(words) + ".",
                             {"levels": vals, "ours": ours, "identical_levels": [list(p) for p in same]})
    is_level = any(math.isclose(v, ours, rel_tol=1e-12, abs_tol=1e-15) for v in vals)
    same_domain = all(dm == domains[0] for dm in domains)
    # the noise floor: each value is within its solver's rtol, a ratio within twice that
    noise = 2 * max(rtols) * max(abs(v) for v in vals) if rtols and all(map(math.isfinite, vals)) else 0.0
    ok, limit, why_not = _trend(vals, noise)
    finest = vals[-1]

    def decide(expect):
        if not (is_level and same_domain and ok):
            return False, "criterion not met"
        if paper_level is not None:
            v = vals[paper_level]
            return miss(expect, v) == 0, f"level at the paper's resolution {_num(v)}"
        lo, hi = min(finest, limit), max(finest, limit)
        grid = np.linspace(lo, hi, 201)
        reach = any(miss(expect, float(x)) == 0 for x in grid)
        return reach, f"span from the finest {_num(finest)} to the trend's limit {_num(limit)}"

    holds, how = decide(claim.expect)
    problems = ([] if is_level else ["the claim's own value is not one of the levels"]) + (
        [] if same_domain else ["the levels scan different domains (a change of domain is `domain`)"]) + (
        [] if ok else [f"no convergence: {why_not}"])
    result = ("; ".join(words) + ". " + ("; ".join(problems) + "." if problems else
              f"Converging; {how} " + ("meets" if holds else "does not meet")
              + f" the paper's {claim.paper_value} ({tolerance_text(claim.expect)})."))
    ev = Evidence("converges", holds, result, {"levels": vals, "ours": ours, "limit": limit, "noise": noise,
                                               "same_domain": same_domain, "converging": ok})
    ev.control = _reflected_control(decide, claim, m, "resolution: the paper's value moved where the refinement "
                                                       "cannot reach")
    return ev


# ---------------------------------------------------------------------------
# domain: restricted;  convention: recompute
# ---------------------------------------------------------------------------


def _same_method(claim, a: dict, compute) -> bool:
    if (compute or claim.compute) != claim.compute:
        return False
    keys = ("reduction", "role", "quantity", "absolute", "statistic")
    srcs = lambda args: [args] if "scene" in args else [args.get("numerator", {}), args.get("denominator", {})]  # noqa: E731
    return all(all(x.get(k) == y.get(k) for k in keys if k != "statistic" or "statistic" in x)
               for x, y in zip(srcs(claim.args), srcs(a)))


def restricted(stores, claim, m, *, label: str, evidence: str, compute=None, args=None, override=None) -> Evidence:
    """``domain`` (CAUSES.md): the claim's computation, same method, restricted to the range the
    paper evidently used (``evidence``), lies in the claim's own accepted set."""
    m2, a = _measure(stores, claim, compute, args, override)
    same = _same_method(claim, a, compute)
    v = m2.value

    def decide(expect):
        if not same:
            return False, "not the same method"
        return miss(expect, v) == 0, f"{_num(v)}"

    holds, _ = decide(claim.expect)
    result = (f"{label}: {_num(v)} ({m2.where}); " + ("" if same else "NOT the claim's method (reduction/role differ); ")
              + ("within" if holds else f"{miss(claim.expect, v):.2g} beyond") + f" the paper's {claim.paper_value} "
              f"({tolerance_text(claim.expect)}); as registered {_num(m.value)}. Evidence for the range: {evidence}")
    ev = Evidence("restricted", holds, result, {"ours": m.value, "restricted": v, "same_method": same})
    ev.control = _reflected_control(decide, claim, m, "domain: the paper's value moved outside what the "
                                                      "restricted range gives")
    return ev


def recompute(stores, claim, m, *, label: str, evidence: str, compute=None, args=None, override=None) -> Evidence:
    """``convention`` (CAUSES.md): our value recomputed under the paper's convention (quoted in
    ``evidence``) lies in the claim's accepted set."""
    m2, _ = _measure(stores, claim, compute, args, override)
    v = m2.value

    def decide(expect):
        return miss(expect, v) == 0, f"{_num(v)}"

    holds, _ = decide(claim.expect)
    result = (f"{label}: {_num(v)} ({m2.where}), " + ("within" if holds else f"{miss(claim.expect, v):.2g} beyond")
              + f" the paper's {claim.paper_value}; as registered {_num(m.value)}. The paper's convention: {evidence}")
    ev = Evidence("recompute", holds, result, {"ours": m.value, "recomputed": v})
    ev.control = _reflected_control(decide, claim, m, "convention: the paper's value moved to the other side of ours")
    return ev


# ---------------------------------------------------------------------------
# cross-check
# ---------------------------------------------------------------------------


def cross_check(stores, claim, m, *, label: str, compute=None, args=None, override=None) -> Evidence:
    """``cross-check`` (CAUSES.md): a second computation sharing no store and no grid with the
    claim's agrees with ours within the sum of the two error estimates and also misses the
    paper's accepted set."""
    m2, a = _measure(stores, claim, compute, args, override)
    own = claim.args
    paths_a, paths_b = _paths(stores, own), _paths(stores, a)
    grids_a, grids_b = _grid(stores, own), _grid(stores, a)
    shared_store = bool(paths_a & paths_b) or bool(_arg_scenes(own) & _arg_scenes(a))
    shared_grid = any(g in grids_b for g in grids_a)
    independent = not shared_store and not shared_grid
    if not independent:  # one store or one grid on both sides: an agreement of a computation with itself
        return _cannot_judge("cross_check", f"{label}: the two sides read "
                             + " and ".join(w for w, f in (("the same store", shared_store), ("the same grid", shared_grid))
                                            if f) + f" ({', '.join(sorted(paths_a))} | {', '.join(sorted(paths_b))}): "
                             f"their agreement ({_num(m.value)} and {_num(m2.value)}) is no second computation",
                             {"ours": m.value, "second": m2.value, "independent": False})
    va = list(m.value) if isinstance(m.value, tuple) else [m.value]
    vb = list(m2.value) if isinstance(m2.value, tuple) else [m2.value]
    ea, eb = m.error_value, m2.error_value
    tol = ea + eb if math.isfinite(ea) and math.isfinite(eb) else math.nan
    gap = max(abs(x - y) for x, y in zip(va, vb)) if len(va) == len(vb) else math.nan
    close = bool(math.isfinite(tol) and math.isfinite(gap) and gap <= tol)

    def decide(expect):
        also = miss(expect, m2.value) > 0
        return independent and close and also, ("the second also misses" if also else "the second agrees with it")

    holds, also_words = decide(claim.expect)
    result = (f"ours {_num(m.value)} ({m.error or 'no error estimate'}); {label}: {_num(m2.value)}"
              + (f" ({m2.where}; {m2.error or 'no error estimate'})" if m2.where else "")
              + f"; gap {_num(gap)} " + (f"{'within' if close else 'beyond'} the sum of the error estimates {_num(tol)}"
                                         if math.isfinite(tol) else "— a side has no error estimate, so no tolerance")
              + ("" if independent else "; the sides are NOT independent ("
                 + ", ".join(w for w, f in (("same store", shared_store), ("same grid", shared_grid)) if f) + ")")
              + f"; {also_words} the paper's {claim.paper_value}")
    ev = Evidence("cross_check", holds, result, {"ours": m.value, "second": m2.value, "gap": gap,
                                                 "tolerance": tol, "error_ours": ea, "error_second": eb,
                                                 "independent": independent})
    # the paper's value moved onto ours (within the claim's tolerance or the sides' own error
    # estimates, the larger): an agreement, which no cross-check may count as a difference
    width = max(claim.expect.get("tolerance", 0.0), tol if math.isfinite(tol) else 0.0)
    onto = ({"range": list(va), "tolerance": width} if "range" in claim.expect and len(va) == 2 else
            {"value": float(np.mean(va)), "tolerance": width + (max(va) - min(va)) / 2})
    moved_holds, _ = decide(onto)
    passed = independent and close and not moved_holds
    ev.control = {"what": "cross-check: the sides' stores and grids differ, their gap is within their error "
                          "estimates, and with the paper's value moved onto ours the check does not hold",
                  "passed": passed, "moved_expect": onto,
                  "result": (f"stores {'differ' if not shared_store else 'SHARED'} ({', '.join(sorted(paths_a))} | "
                             f"{', '.join(sorted(paths_b))}); grids {'differ' if not shared_grid else 'SHARED'}; gap "
                             f"{_num(gap)} vs tolerance {_num(tol)}; paper moved onto ours: "
                             + ("not explained, as it must be" if not moved_holds else "explained too")),
                  "numbers": {"independent": independent, "gap": gap, "tolerance": tol}}
    return ev


# ---------------------------------------------------------------------------
# reading
# ---------------------------------------------------------------------------


def reading(stores, claim, m, *, quote: str, other_reading: str, rule: str, label: str, expect: dict, control: dict,
            compute=None, args=None, override=None) -> Evidence:
    """``reading`` (CAUSES.md): the paper's sentence (``quote``) under ``other_reading``, evaluated
    by the computation (``override``/``args``/``compute``) against ``expect`` (its threshold from
    the shared rule ``rule``); the control (``control``: ``override``/``args`` of the same
    computation on a cell where the sentence is false, and ``why``) must not hold."""
    if rule not in RULES:
        raise ValueError(f"reading rule {rule!r} is not one of {', '.join(RULES)}")
    m2, a = _measure(stores, claim, compute, args, override)
    holds = miss(expect, m2.value) == 0
    c_args = control.get("args")
    c_over = control.get("override")
    if c_args is None and c_over is not None:
        c_args = _merge(a, c_over)
    mc, _ = _measure(stores, claim, compute, c_args, None)
    c_holds = miss(expect, mc.value) == 0
    result = (f"“{quote}” — read as: {other_reading}. {label}: {_num(m2.value)} ({m2.where}), "
              + ("within" if holds else f"{miss(expect, m2.value):.2g} beyond") + f" the reading's set "
              f"{_set_text(expect)} (rule “{rule}”, CAUSES.md); as registered {_num(m.value)}")
    ev = Evidence("reading", holds, result, {"ours": m.value, "reading": m2.value, "expect": expect, "rule": rule})
    ev.control = {"what": f"reading: the same reading on a control cell where the sentence is false ({control['why']})",
                  "passed": not c_holds, "numbers": {"control_value": mc.value},
                  "result": f"control: {_num(mc.value)} ({mc.where}) " + (
                      "misses the reading's set, as it must" if not c_holds else
                      "also meets the reading's set: the reading cannot tell the sentence from its negation")}
    return ev


#: The cause checks a claim may name (``[claims.cause] check = "<key>"``), one per kind.
CHECKS = {"converges": converges, "restricted": restricted, "cross_check": cross_check, "reading": reading,
          "recompute": recompute}
