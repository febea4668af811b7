"""Scene files, the part every kind shares: read a TOML scene, validate its values, hash it.

A scene is split in two parts:

* the **science** part (for a grid scene: family, axes, fixed parameters, solver settings,
  outputs, reductions) which decides every number in the store; it is normalised to plain JSON,
  hashed (sha256, with the solver's ``engine_versions``) and stored as provenance, and a store
  built from a different science part is refused;
* the **execution** part (points per task, scheduler, workers, store path) which decides only
  how the numbers are computed; it is not hashed.

This module holds what every kind's parser uses: :class:`SceneError`, :class:`ParseContext`
(typed checks of one file's values), the parameters' physical domains (:func:`parse_value`,
:func:`parse_shape`, :func:`parse_axis` and its :class:`Axis`), :class:`Execution`,
:func:`scene_hash`, :func:`read_toml` and :func:`read_scene_file`.  Each kind's schema lives
with the kind: ``_grid_scene`` (grid, the default), ``_optima``, ``_study_scene``.

Every error is a :class:`SceneError` whose message names the file, the key
and the reason, on one line.
"""

from __future__ import annotations

import hashlib
import json
import math
import re
import tomllib
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

__all__ = [
    "Axis",
    "Execution",
    "SceneError",
    "ParseContext",
    "parse_axis",
    "parse_shape",
    "parse_value",
    "parameter_units",
    "read_scene_file",
    "read_toml",
    "scene_hash",
    "engine_versions",
    "type_name",
]

class SceneError(ValueError):
    """A scene file that cannot be used; the message names file, key and reason."""

    def __init__(self, file: str, key: str, reason: str):
        self.file, self.key, self.reason = file, key, reason
        super().__init__(f"{file}: {key}: {reason}")


# ---------------------------------------------------------------------------
# Vocabulary: the parameters' physical domains.
# ---------------------------------------------------------------------------

_PI = math.pi


def _open_interval(lo, hi):
    return lambda v: lo < v < hi


#: name -> (predicate on one value, description of the domain, units)
_DOMAINS: dict[str, tuple[Any, str, str]] = {
    "anisotropy_ratio": (lambda v: 0 < v < math.inf, "must be > 0 (mu_n/mu_s)", "1"),
    "scaled_period": (lambda v: 0 < v < math.inf, "must be > 0 ((mu_n mu_s)^(1/(4-2p)) T)", "1"),
    "T2_mu_n": (lambda v: 0 < v < math.inf, "must be > 0 (T^(2-p) mu_n)", "1"),
    "T2_mu_s": (lambda v: 0 < v < math.inf, "must be > 0 (T^(2-p) mu_s)", "1"),
    "A0": (lambda v: 0 < v < _PI, "must be in (0, pi) [rad]", "rad"),
    "A1_ratio": (lambda v: 0 < v <= 1, "must be in (0, 1] (A1/A0)", "1"),
    "duty_cycle": (_open_interval(0.0, 1.0), "must be in (0, 1) (tau0)", "1"),
    "closing_shape": (lambda v: abs(v) >= 1 and math.isfinite(v),
                      "must be an exponent >= 1 with a concavity (up:g, down:g, or linear)", "1"),
    "opening_shape": (lambda v: abs(v) >= 1 and math.isfinite(v),
                      "must be an exponent >= 1 with a concavity (up:g, down:g, or linear)", "1"),
    "p": (lambda v: 0 <= v < 2, "must be in [0, 2)", "1"),
    "delta": (lambda v: 0 <= v < math.inf, "must be >= 0", "1"),
}


#: The largest wavenumber K of a grid scene's Fourier coefficients A0..AK, B1..BK (``family =
#: "fourier"``): each is a parameter, finite, any sign, in rad (eq. Fourier; phi may leave [0, pi]).
MAX_FOURIER_WAVENUMBER = 16
FOURIER_COEFFICIENT = re.compile(r"^(A|B)([1-9]\d*)$")
for _k in range(1, MAX_FOURIER_WAVENUMBER + 1):
    for _c in "AB":
        _DOMAINS[f"{_c}{_k}"] = (math.isfinite, "must be a finite number [rad] (a Fourier coefficient)", "rad")


def parameter_units(name: str) -> str:
    """Units of parameter ``name`` ("rad" for A0, "1" for the dimensionless ones and unknown names)."""
    return _DOMAINS[name][2] if name in _DOMAINS else "1"


_FOURIER_NAMES = frozenset(k for k in _DOMAINS if FOURIER_COEFFICIENT.match(k))
_PI_RE = re.compile(r"^\s*([-+]?\d*\.?\d*)\s*\*?\s*pi\s*(?:/\s*(\d+(?:\.\d*)?))?\s*$")
_SHAPE_RE = re.compile(r"^\s*(up|down)\s*:\s*(\d+(?:\.\d*)?)\s*$")


# ---------------------------------------------------------------------------
# Dataclasses
# ---------------------------------------------------------------------------


@dataclass(frozen=True)
class Axis:
    """One swept parameter.

    Attributes
    ----------
    name : str
        Parameter name (a key of the module's domain table).
    values : tuple of float
        Grid values, strictly increasing.
    spacing : str
        "linear", "log2" or "list": how the values were given (used to polish in log space).
    """

    name: str
    values: tuple[float, ...]
    spacing: str

    @property
    def size(self) -> int:
        return len(self.values)

    @property
    def continuous(self) -> bool:
        """True for axes a local optimiser may move along (not the discrete power-law shapes)."""
        return self.name not in ("closing_shape", "opening_shape") and self.size > 1

    def array(self) -> np.ndarray:
        return np.asarray(self.values, dtype=np.float64)



@dataclass(frozen=True)
class Execution:
    """How to run; not part of the scene hash."""

    points_per_task: int | None = None
    scheduler: str = "processes"
    workers: int | None = None
    store: str | None = None
    #: grid scenes: points of one block, a task's unit (the block layout; ``_grid.scene_chunks``)
    points_per_chunk: int | None = None



def engine_versions() -> dict[str, str]:
    """{method: version} of the solver's engines (``solver.ENGINES``): part of every scene's
    hash and provenance, so that results of two engine versions never share a store."""
    import solver

    return {name: engine.version for name, engine in sorted(solver.ENGINES.items())}


def scene_hash(science: dict) -> str:
    """sha256 of the scene's science part and the solver's ``engine_versions``."""
    blob = json.dumps({**science, "engines": engine_versions()}, sort_keys=True,
                      separators=(",", ":"), allow_nan=False)
    return hashlib.sha256(blob.encode()).hexdigest()


# ---------------------------------------------------------------------------
# Parsing helpers
# ---------------------------------------------------------------------------


class ParseContext:
    """Validation of one scene file's values: each check returns the value or raises a
    :class:`SceneError` naming ``file``, the key and the reason (one line)."""

    def __init__(self, file: str):
        self.file = file

    def err(self, key: str, reason: str) -> SceneError:
        return SceneError(self.file, key, reason)

    def table(self, obj, key: str, allowed: dict[str, str], required=()) -> dict:
        """Check ``obj`` is a table with only ``allowed`` keys (key -> description)."""
        if not isinstance(obj, dict):
            raise self.err(key, f"must be a table, got {type_name(obj)}")
        for k in obj:
            if k not in allowed:
                raise self.err(f"{key}.{k}" if key else k,
                               f"unknown key (allowed: {', '.join(sorted(allowed))})")
        for k in required:
            if k not in obj:
                raise self.err(f"{key}.{k}" if key else k, "missing required key")
        return obj

    def string(self, obj, key, choices=None) -> str:
        if not isinstance(obj, str):
            raise self.err(key, f"must be a string, got {type_name(obj)}")
        if choices is not None and obj not in choices:
            raise self.err(key, f"must be one of {', '.join(choices)}, got {obj!r}")
        return obj

    def boolean(self, obj, key) -> bool:
        if not isinstance(obj, bool):
            raise self.err(key, f"must be true or false, got {type_name(obj)}")
        return obj

    def integer(self, obj, key, lo=None) -> int:
        if isinstance(obj, bool) or not isinstance(obj, int):
            raise self.err(key, f"must be an integer, got {type_name(obj)}")
        if lo is not None and obj < lo:
            raise self.err(key, f"must be >= {lo}, got {obj}")
        return obj

    def number(self, obj, key, allow_pi=False) -> float:
        if isinstance(obj, bool):
            raise self.err(key, "must be a number, got a boolean")
        if isinstance(obj, (int, float)):
            v = float(obj)
        elif allow_pi and isinstance(obj, str) and _PI_RE.match(obj):
            m = _PI_RE.match(obj)
            coef = m.group(1)
            c = 1.0 if coef in ("", "+") else (-1.0 if coef == "-" else float(coef))
            v = c * math.pi / (float(m.group(2)) if m.group(2) else 1.0)
        else:
            extra = " or a multiple of pi such as \"pi/2\"" if allow_pi else ""
            raise self.err(key, f"must be a number{extra}, got {type_name(obj)} {obj!r}")
        if not math.isfinite(v):
            raise self.err(key, f"must be finite, got {v}")
        return v

    def names(self, obj, key, choices, nonempty=True) -> tuple[str, ...]:
        if not isinstance(obj, list):
            raise self.err(key, f"must be a list of names, got {type_name(obj)}")
        if nonempty and not obj:
            raise self.err(key, "must not be empty")
        out = []
        for i, v in enumerate(obj):
            if not isinstance(v, str):
                raise self.err(f"{key}[{i}]", f"must be a string, got {type_name(v)}")
            if v not in choices:
                raise self.err(f"{key}[{i}]", f"{v!r} is not one of {', '.join(choices)}")
            if v in out:
                raise self.err(f"{key}[{i}]", f"{v!r} is listed twice")
            out.append(v)
        return tuple(out)


def type_name(obj) -> str:
    return {dict: "a table", list: "an array", str: "a string", bool: "a boolean",
            int: "an integer", float: "a float"}.get(type(obj), type(obj).__name__)


def parse_shape(ctx: ParseContext, obj, key) -> float:
    """Power-law shape as a signed exponent: +g concave up, -g concave down, 1 linear."""
    if isinstance(obj, str):
        s = obj.strip().lower()
        if s == "linear":
            return 1.0
        m = _SHAPE_RE.match(s)
        if not m:
            raise ctx.err(key, f"must be \"up:g\", \"down:g\", \"linear\" or a signed exponent, got {obj!r}")
        g = float(m.group(2))
        if g < 1:
            raise ctx.err(key, f"exponent must be >= 1, got {g}")
        return 1.0 if g == 1 else (g if m.group(1) == "up" else -g)
    v = ctx.number(obj, key)
    if abs(v) < 1:
        raise ctx.err(key, f"exponent must be >= 1 in magnitude, got {v}")
    return 1.0 if abs(v) == 1 else v


def parse_value(ctx: ParseContext, name: str, obj, key) -> float:
    if name in ("closing_shape", "opening_shape"):
        v = parse_shape(ctx, obj, key)
    else:
        v = ctx.number(obj, key, allow_pi=(name == "A0" or name in _FOURIER_NAMES))
    ok, why, _ = _DOMAINS[name]
    if not ok(v):
        raise ctx.err(key, f"value {v:g} outside the physical domain: {name} {why}")
    return v


_AXIS_KEYS = {
    "values": "explicit list of values",
    "range": "[lo, hi] of a linear grid",
    "log2_range": "[lo, hi] of log2 of the values",
    "num": "number of points",
    "step": "grid step (in log2 units for log2_range)",
    "include": "which ends of the range are grid points: both, lower, upper, neither",
}
_INCLUDE = ("both", "lower", "upper", "neither")


def _grid(lo: float, hi: float, num: int | None, step: float | None, include: str) -> np.ndarray:
    if num is not None:
        if include == "both":
            return np.linspace(lo, hi, num) if num > 1 else np.array([lo])
        denom = {"lower": num, "upper": num, "neither": num + 1}[include]
        k = np.arange(num) + (0 if include == "lower" else 1)
        return lo + (hi - lo) * k / denom
    n = int(math.floor((hi - lo) / step + 1e-9))
    g = lo + step * np.arange(n + 1)
    if include in ("upper", "neither"):
        g = g[1:]
    if include in ("lower", "neither") and g.size and abs(g[-1] - hi) < 1e-9 * max(1.0, abs(hi)):
        g = g[:-1]
    return g


def parse_axis(ctx: ParseContext, name: str, spec, key: str) -> Axis:
    if name in ("closing_shape", "opening_shape") and isinstance(spec, list):
        spec = {"values": spec}
    if isinstance(spec, list):
        spec = {"values": spec}
    ctx.table(spec, key, _AXIS_KEYS)
    forms = [k for k in ("values", "range", "log2_range") if k in spec]
    if len(forms) != 1:
        raise ctx.err(key, "give exactly one of values, range, log2_range")
    form = forms[0]
    if form == "values":
        for k in ("num", "step", "include"):
            if k in spec:
                raise ctx.err(f"{key}.{k}", "only allowed with range or log2_range")
        raw = spec["values"]
        if not isinstance(raw, list):
            raise ctx.err(f"{key}.values", f"must be an array, got {type_name(raw)}")
        if not raw:
            raise ctx.err(f"{key}.values", "empty list")
        vals = [parse_value(ctx, name, v, f"{key}.values[{i}]") for i, v in enumerate(raw)]
        if any(b <= a for a, b in zip(vals, vals[1:])):
            raise ctx.err(f"{key}.values", "must be strictly increasing (no repeats)")
        return Axis(name, tuple(vals), "list")
    bounds = spec[form]
    if not isinstance(bounds, list) or len(bounds) != 2:
        raise ctx.err(f"{key}.{form}", f"must be [lo, hi], got {bounds!r}")
    angle = name == "A0" or name in _FOURIER_NAMES
    lo, hi = (ctx.number(b, f"{key}.{form}", allow_pi=(angle and form == "range")) for b in bounds)
    if hi < lo:
        raise ctx.err(f"{key}.{form}", f"reversed range [{lo:g}, {hi:g}]")
    if ("num" in spec) == ("step" in spec):
        raise ctx.err(key, f"give exactly one of num, step with {form}")
    num = ctx.integer(spec["num"], f"{key}.num", lo=1) if "num" in spec else None
    step = ctx.number(spec["step"], f"{key}.step") if "step" in spec else None
    if step is not None and step <= 0:
        raise ctx.err(f"{key}.step", f"must be > 0, got {step:g}")
    include = ctx.string(spec.get("include", "both"), f"{key}.include", _INCLUDE)
    if hi == lo and not (include == "both" and (num == 1 or step is not None)):
        raise ctx.err(f"{key}.{form}", f"empty range [{lo:g}, {hi:g}]")
    g = _grid(lo, hi, num, step, include)
    if g.size == 0:
        raise ctx.err(key, "empty range: no grid point inside")
    if form == "log2_range":
        g = np.exp2(g)
    vals = [float(v) for v in g]
    for v in vals:
        ok, why, _ = _DOMAINS[name]
        if not ok(v):
            raise ctx.err(f"{key}.{form}", f"grid value {v:g} outside the physical domain: {name} {why}")
    return Axis(name, tuple(vals), "log2" if form == "log2_range" else "linear")


def read_toml(text: str, ctx: "ParseContext") -> dict:
    """The TOML document ``text``; a syntax error is a :class:`SceneError` naming the file."""
    try:
        return tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise ctx.err("(toml)", f"not valid TOML: {exc}") from None


def read_scene_file(path: str | Path) -> str:
    """The text of the scene file ``path``; an unreadable file is a :class:`SceneError`."""
    try:
        return Path(path).read_text(encoding="utf-8")
    except OSError as exc:
        raise SceneError(str(path), "(file)", f"cannot read: {exc.strerror or exc}") from None
