"""Why a claim differs: a computed cause for every verdict other than "agrees".

A claim of ``claims.toml`` that we do not reproduce carries a ``[claims.cause]`` table::

    [claims.cause]
    kind = "resolution"            # one of CAUSES
    check = "subgrid_max"          # a check of CHECKS, run on the stores at build time
    why = "..."                    # the cause in words (what the check is to show)
    [claims.cause.args]            # the check's arguments
    ...

The check is a computation on the stores (restrict to the paper's range and recompute, recompute
under the paper's reading or convention, compare two of our computations, subsample a grid);
it returns :class:`Evidence`: whether it *holds* (shows the cause), its result in words and the
numbers it compared.  The row's cause is ``kind`` when the check holds, else ``unexplained``
(with the check's result, so the reader sees what was tried).  Causes:

* ``domain`` — our optimum lies outside the range the paper evidently scanned, or the paper's
  value is what our data give on the range it used;
* ``convention`` — a different objective, normalisation or sign convention;
* ``resolution`` — a finer (or coarser, the paper's) grid or more starts moves our value;
* ``cross-check`` — two of our independent computations agree with each other, not the paper;
* ``reading`` — the paper's sentence admits another reading, and ours agrees under it;
* ``defect`` — our value was wrong (fixed; then the claim agrees or has another cause).

Every check is ``f(stores, claim, measurement, **args) -> Evidence`` in :data:`CHECKS`.
"""

from __future__ import annotations

import copy
import math
from dataclasses import dataclass, field

import numpy as np

from ._claim_values import COMPUTE, Measurement, NotComputed, scene_store, select

__all__ = ["CAUSES", "CHECKS", "Cause", "Evidence", "explain", "miss", "parse_cause", "tolerance_text"]

CAUSES = ("domain", "convention", "resolution", "cross-check", "reading", "defect")


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

    holds : the check shows the cause
    result : the outcome in words (printed in the audit row)
    numbers : the numbers compared, by name (written to audit.json)
    """

    check: str
    holds: bool
    result: str
    numbers: dict = field(default_factory=dict)

    def to_json(self) -> dict:
        return {"check": self.check, "holds": self.holds, "result": self.result,
                "numbers": {k: _plain(v) for k, v in self.numbers.items()}}


def _plain(v):
    if isinstance(v, (tuple, list)):
        return [_plain(x) for x in v]
    if isinstance(v, dict):
        return {str(k): _plain(x) for k, x in v.items()}
    if isinstance(v, (float, np.floating, int, np.integer)) and not isinstance(v, bool):
        v = float(v)
        return v if math.isfinite(v) else None
    return v


def parse_cause(cid: str, doc) -> Cause | None:
    """The ``[claims.cause]`` table of claim ``cid`` (None when absent); ValueError names the claim."""
    if doc is None:
        return None
    missing = [k for k in ("kind", "check", "why") if k not in doc]
    if missing:
        raise ValueError(f"claim {cid}: cause lacks {', '.join(missing)}")
    if doc["kind"] not in CAUSES:
        raise ValueError(f"claim {cid}: cause kind {doc['kind']!r} is not one of {', '.join(CAUSES)}")
    if doc["check"] not in CHECKS:
        raise ValueError(f"claim {cid}: unknown cause check {doc['check']!r} (known: {', '.join(CHECKS)})")
    return Cause(kind=doc["kind"], check=doc["check"], why=doc["why"], args=dict(doc.get("args", {})))


def explain(cause: Cause | None, stores, claim, m: Measurement | None) -> tuple[str, Evidence | None]:
    """(cause, evidence) of a claim that does not agree: the registered kind when its check holds,
    else ``unexplained`` (also when no cause is registered or the check cannot run)."""
    if cause is None:
        return "unexplained", None
    try:
        ev = CHECKS[cause.check](stores, claim, m, **cause.args)
    except (NotComputed, KeyError, IndexError, ValueError, ZeroDivisionError) as exc:
        # a store without what the check reads: no cause shown, the row says why
        return "unexplained", Evidence(cause.check, False, f"the check could not run: {type(exc).__name__}: {exc}")
    return (cause.kind if ev.holds else "unexplained"), ev


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


def _measure(stores, claim, compute=None, args=None, override=None) -> tuple[Measurement, dict]:
    """Our value of ``claim`` recomputed with other arguments (``args`` in full, or the claim's
    own with ``override`` merged in) and maybe another reduction."""
    a = dict(args) if args is not None else _merge(claim.args, override or {})
    scenes = [a["scene"]] if "scene" in a else []
    scenes += [a[s]["scene"] for s in ("numerator", "denominator") if isinstance(a.get(s), dict) and "scene" in a[s]]
    for s in scenes:
        scene_store(stores, s)
    return COMPUTE[compute or claim.compute](stores, **a), a


def _miss(claim, value, expect=None) -> float:
    return miss(expect or claim.expect, value)


def _expect_text(expect: dict) -> str:
    return tolerance_text(expect)


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


# ---------------------------------------------------------------------------
# the checks
# ---------------------------------------------------------------------------


def recompute(stores, claim, m, *, label: str, compute=None, args=None, override=None, expect=None) -> Evidence:
    """Our value under the paper's range, reading or convention (``label`` says which): the
    claim's reduction with ``override`` merged into its arguments (or ``args`` in full),
    judged against the claim's expectation (or ``expect``, the reading's). Holds when it agrees."""
    m2, _ = _measure(stores, claim, compute, args, override)
    e = expect or claim.expect
    miss = _miss(claim, m2.value, e)
    holds = miss == 0
    ours = m.value if m is not None else math.nan
    whose = "the reading's" if expect else f"the paper's {claim.paper_value}"
    result = (f"{label}: {_num(m2.value)} ({m2.where}), "
              + (f"within {whose} ({_expect_text(e)})" if holds else f"still {miss:.2g} beyond {whose} ({_expect_text(e)})")
              + f"; as registered {_num(ours)}")
    return Evidence("recompute", holds, result, {"ours": ours, "recomputed": m2.value, "paper": e,
                                                 "miss_recomputed": miss})


def cross_check(stores, claim, m, *, label: str, compute=None, args=None, override=None, rtol: float,
                atol: float = 0.0) -> Evidence:
    """A second, independent computation of the claim's value (another scene, the grid against
    the optimiser, ...) named ``label``: holds when the two agree within ``rtol`` (relative) or
    ``atol`` (absolute, for shares) and the second also misses the paper's value."""
    m2, _ = _measure(stores, claim, compute, args, override)
    a, b = m.value, m2.value
    va = list(a) if isinstance(a, tuple) else [a]
    vb = list(b) if isinstance(b, tuple) else [b]
    gaps = [0.0 if x == y else abs(x - y) / max(abs(x), abs(y)) for x, y in zip(va, vb)]
    gap = max(gaps) if gaps and all(math.isfinite(g) for g in gaps) else math.nan
    also_misses = _miss(claim, b) > 0
    close = bool(math.isfinite(gap) and (gap <= rtol or max(abs(x - y) for x, y in zip(va, vb)) <= atol))
    holds = close and also_misses
    result = (f"ours {_num(a)}; {label}: {_num(b)}" + (f" ({m2.where})" if m2.where else "") + f"; they differ by {100 * gap:.2g} % "
              f"({'within' if close else 'beyond'} {100 * rtol:g} %" + (f" or {atol:g}" if atol else "") + "), and the second "
              + ("also misses" if also_misses else "agrees with") + f" the paper's {claim.paper_value}")
    return Evidence("cross_check", holds, result, {"ours": a, "second": b, "relative_gap": gap, "rtol": rtol,
                                                   "atol": atol})


def toward(stores, claim, m, *, label: str, compute=None, args=None, override=None, share: float = 0.5) -> Evidence:
    """A finer computation (``label``: more samples, a polished optimum) moves our value toward the
    paper's: holds when it removes at least ``share`` of the miss."""
    m2, _ = _measure(stores, claim, compute, args, override)
    miss0, miss1 = _miss(claim, m.value), _miss(claim, m2.value)
    holds = bool(math.isfinite(miss0) and math.isfinite(miss1) and miss0 > 0 and miss1 <= (1 - share) * miss0)
    result = (f"ours {_num(m.value)} ({miss0:.2g} beyond {claim.tolerance_text()}); {label}: {_num(m2.value)} "
              f"({m2.where}), " + ("within the tolerance" if miss1 == 0 else f"{miss1:.2g} beyond it")
              + f": the finer computation removes {100 * (1 - miss1 / miss0) if miss0 else 0:.0f} % of the miss")
    return Evidence("toward", holds, result, {"ours": m.value, "finer": m2.value, "miss_ours": miss0,
                                              "miss_finer": miss1})


def _converged_magnitude(stores, scene: str, quantity: str):
    """(the scene's store, |``quantity``| where the solve converged) or NotComputed."""
    sd = scene_store(stores, scene)
    if quantity not in sd.ds:
        raise NotComputed(f"store {scene} has no quantity {quantity!r}")
    da = abs(sd.ds[quantity])
    if "status" in sd.ds:
        da = da.where(sd.ds["status"] == 0)
    return sd, da


def subgrid_max(stores, claim, m, *, scene: str, quantity: str, at: dict, dims: list, strides: list,
                tolerance: float | None = None) -> Evidence:
    """The maximum of |``quantity``| over sub-grids of the stored field (every ``s``-th sample along
    each of ``dims``, at every offset): what a coarser grid gives, from its worst-aligned to its
    best-aligned placement. Holds when the paper's value lies in that span for a grid coarser than
    ours (± ``tolerance``, default the claim's) and the worst-aligned maxima rise toward ours as the
    grid is refined (the maximum is not yet converged in the sampling)."""
    sd, da = _converged_magnitude(stores, scene, quantity)
    da, _ = select(da, at=at)
    paper = claim.expect["value"]
    tol = claim.expect.get("tolerance", 0.0) if tolerance is None else tolerance
    table, bracket = {}, []
    for s in strides:
        maxima = []
        for offsets in np.ndindex(*([s] * len(dims))):
            sub = da.isel({d: slice(o, None, s) for d, o in zip(dims, offsets)})
            maxima.append(float(sub.max(skipna=True)))
        n = " × ".join(str(-(-da.sizes[d] // s)) for d in dims)
        table[n] = (min(maxima), max(maxima))
        if s > 1 and min(maxima) - tol <= paper <= max(maxima) + tol:
            bracket.append(n)
    lows = [lo for lo, _ in table.values()]  # strides ascending: finest first
    rising = all(fine >= coarse - 1e-12 for fine, coarse in zip(lows, lows[1:]))
    holds = bool(bracket) and rising
    text = "; ".join(f"{n}: {_num(lo)}–{_num(hi)}" for n, (lo, hi) in table.items())
    result = (f"maxima of the stored {sd.ds.sizes[dims[0]]} × {sd.ds.sizes[dims[1]]} field on sub-grids, worst- to "
              f"best-aligned ({text}); "
              f"polished {_num(m.value)}: " + (f"the paper's {paper:g} is the maximum of a {bracket[0]} grid"
                                               if bracket else f"no coarser grid gives {paper:g}")
              + ("" if rising else "; the worst-aligned maxima do not rise with the sampling"))
    return Evidence("subgrid_max", holds, result, {"paper": paper, "ours": m.value,
                                                   "subgrid_maxima": {k: list(v) for k, v in table.items()}})


def region_near_optimal(stores, claim, m, *, scene: str, quantity: str, cells: list, region: dict,
                        share: float) -> Evidence:
    """The paper's reading of where a maximum lies, read off a contour plot: in each of ``cells``
    the maximum of |``quantity``| over ``region`` (the paper's place, ranges per axis) against the
    maximum over the whole panel. Holds when every ratio is at least ``share`` (the top contour
    covers the paper's place)."""
    _, da = _converged_magnitude(stores, scene, quantity)
    ratios, words = [], []
    for c in cells:
        panel, _ = select(da, at=c)
        part, _ = select(panel, ranges=region)
        r = float(part.max(skipna=True)) / float(panel.max(skipna=True))
        ratios.append(r)
        words.append(", ".join(f"{k} = {v:g}" for k, v in c.items()) + f": {r:.3f}")
    holds = min(ratios) >= share
    where = ", ".join(f"{k} in [{lo:.3g}, {hi:.3g}]" for k, (lo, hi) in region.items())
    result = (f"best |{quantity}| with {where} over the panel's maximum: " + "; ".join(words)
              + f" ({'all' if holds else 'not all'} ≥ {share:g})")
    return Evidence("region_near_optimal", holds, result, {"ratios": ratios, "share": share})


def nested_shortfall(stores, claim, m, *, label: str) -> Evidence:
    """For a gain of a family over a family it contains (power laws over linear strokes), the
    gain cannot be below 1 except by the numerator's grid error: the smallest gain over the
    claim's cells bounds that error from below (``label`` names the numerator's grid). Holds
    when that demonstrated error (relative) is at least the claim's miss (relative)."""
    m2, _ = _measure(stores, claim, None, None, {"statistic": "min"})
    lo = m2.value
    value = m.value if not isinstance(m.value, tuple) else m.value[0]
    miss = _miss(claim, m.value)
    shortfall = 1.0 - lo if math.isfinite(lo) else math.nan
    rel_miss = miss / abs(value) if value else math.inf
    holds = bool(math.isfinite(shortfall) and shortfall > 0 and shortfall >= rel_miss)
    result = (f"the smallest gain over the same cells is {lo:.3g} ({m2.where}): {label} misses an optimum it "
              f"contains by {100 * shortfall:.2g} %, " + ("more" if holds else "less")
              + f" than the claim's miss ({miss:.2g} on {_num(m.value)}, {100 * rel_miss:.2g} %)")
    return Evidence("nested_shortfall", holds, result, {"ours": m.value, "smallest_gain": lo,
                                                        "demonstrated_error": shortfall, "relative_miss": rel_miss})


#: The cause checks a claim may name (``[claims.cause] check = "<key>"``).
CHECKS = {"recompute": recompute, "cross_check": cross_check, "toward": toward, "subgrid_max": subgrid_max,
          "region_near_optimal": region_near_optimal, "nested_shortfall": nested_shortfall}
