"""Study scenes (``[scene] kind = "accuracy" | "stiffness"``): parse and validate into frozen dataclasses.

A study scene is not a grid over axes but a flat list of **points** (one motion with its
physics each), solved by every method at every tolerance and compared with a fine reference:

* ``accuracy`` (work-precision): the points are the ``[[cases]]``; every method is also run on
  fixed grids (observed order) and harmonic cases also by the scipy LSODA baseline of
  ``solver.tools.bench``;
* ``stiffness``: the points are every ``[[motions]]`` entry crossed with every ``[[scans]]``
  entry (one parameter varied at a time from the ``[base]`` physics); a method that fails may
  be replaced by another method's converged answer (``fallback``, recorded per point).

The science part (everything but ``[execution]``) is normalised to JSON and hashed, as for grid
scenes; errors are :class:`~pipeline._scene.SceneError` naming the file and key.
"""

from __future__ import annotations

import math
import re
from dataclasses import dataclass, field, replace

import numpy as np

from ._scene import Execution, ParseContext, parse_shape, type_name, scene_hash

__all__ = ["STUDY_KINDS", "StudyCase", "StudyPoint", "StudyScene", "Scan", "parse_study",
           "parse_study_scene"]

STUDY_KINDS = ("accuracy", "stiffness")
FAMILIES = ("harmonic", "powerlaw", "fourier")
METHOD_NAMES = ("periodic", "march")
FALLBACKS = ("none", "periodic", "march")
CHECKS = ("march", "fixed")
#: Parameters a ``[[scans]]`` entry may vary, and the families it applies to.
SCAN_PARAMETERS = {
    "delta": FAMILIES, "scaled_period": FAMILIES, "anisotropy_ratio": FAMILIES, "p": FAMILIES,
    "exponent": ("powerlaw",), "duty_cycle": ("powerlaw",),
}
_PHYSICS_KEYS = ("anisotropy_ratio", "scaled_period", "p", "delta")
_FAMILY_KEYS = {
    "harmonic": ("A0", "A1"),
    "powerlaw": ("A0", "A1", "duty_cycle", "closing_shape", "opening_shape"),
    "fourier": ("A", "B"),
}
_POW2_RE = re.compile(r"^\s*2\s*\^\s*([-+]?\d+(?:\.\d*)?)\s*$")


@dataclass(frozen=True)
class StudyCase:
    """One motion with its physics.

    Attributes
    ----------
    name : str
    family : {"harmonic", "powerlaw", "fourier"}
    shape : tuple of (str, float or tuple)
        harmonic: A0, A1 [rad]; powerlaw: A0, A1 [rad], duty_cycle (tau0), closing_shape,
        opening_shape (signed exponents: +g concave up, -g concave down, 1 linear);
        fourier: A = (A0..AK), B = (B1..BK) [rad] (eq. Fourier).
    anisotropy_ratio, scaled_period, p, delta : float
        mu_n/mu_s, (mu_n mu_s)^(1/(4-2p)) T, force-law exponent (eq. frictionp), regularisation
        (eq. delta).
    """

    name: str
    family: str
    shape: tuple
    anisotropy_ratio: float
    scaled_period: float
    p: float = 0.0
    delta: float = 1e-5

    def value(self, key):
        return dict(self.shape)[key]

    def kinematics(self):
        """The solver's kinematic family for this motion (one point)."""
        import solver

        s = dict(self.shape)
        if self.family == "harmonic":
            return solver.Harmonic(s["A0"], s["A1"])
        if self.family == "powerlaw":
            c, o = s["closing_shape"], s["opening_shape"]
            return solver.PowerLaw(s["A0"], s["A1"], s["duty_cycle"], abs(c), c > 1, abs(o), o > 1)
        return solver.Fourier([list(s["A"])], [list(s["B"])])

    def physics(self):
        import solver

        return solver.Physics.from_scaled(self.anisotropy_ratio, self.scaled_period, p=self.p, delta=self.delta)

    def with_parameter(self, name: str, value: float) -> "StudyCase":
        """The case with one swept parameter replaced (``exponent``: both power-law exponents,
        keeping their concavity)."""
        if name in _PHYSICS_KEYS:
            return replace(self, **{name: float(value)})
        s = dict(self.shape)
        if name == "exponent":
            for k in ("closing_shape", "opening_shape"):
                s[k] = float(value) if value == 1 else math.copysign(float(value), s[k] if s[k] != 1 else -1.0)
        else:
            s[name] = float(value)
        return replace(self, shape=tuple(s.items()))

    def json(self) -> dict:
        d = {"name": self.name, "family": self.family}
        d.update({k: (list(v) if isinstance(v, tuple) else v) for k, v in self.shape})
        d.update(anisotropy_ratio=self.anisotropy_ratio, scaled_period=self.scaled_period, p=self.p,
                 delta=self.delta)
        return d


@dataclass(frozen=True)
class StudyPoint:
    """One point of a study: a case, and which scan (index into ``scans``, -1 none) put it there
    with which value of its parameter."""

    case: StudyCase
    motion: int
    scan: int = -1
    scan_value: float = math.nan


@dataclass(frozen=True)
class Scan:
    """A ``[[scans]]`` entry of a stiffness scene: one parameter varied over ``values`` (sorted)
    from the ``[base]`` physics, for every motion of a family it applies to."""

    parameter: str
    values: tuple[float, ...]


@dataclass(frozen=True)
class StudyScene:
    """A validated study scene; ``points`` is the flat list every task slices.

    ``rtols`` are in decreasing order; the reference solves every point with ``periodic`` at
    ``reference_rtol`` = ``rtol_factor`` x min(rtols) and cross-checks it with ``check``
    ("march" at ``check_rtol``, falling back to a fixed grid of ``check_steps`` steps if the
    march fails; or "fixed": the ``periodic`` solver on a uniform grid of ``check_steps``).
    """

    path: str
    name: str
    title: str
    figure: str
    kind: str
    motions: tuple[StudyCase, ...]
    scans: tuple[Scan, ...]
    points: tuple[StudyPoint, ...]
    methods: tuple[str, ...]
    rtols: tuple[float, ...]
    fixed_steps: tuple[int, ...]
    march_max_steps_per_period: int | None
    fallback: str
    rtol_factor: float
    check: str
    check_rtol: float
    check_steps: int
    baseline_tolerances: tuple[float, ...]
    baseline_cap_seconds: float
    execution: Execution
    science: dict = field(compare=False, repr=False)
    text: str = field(default="", compare=False, repr=False)
    family: str = "study"

    @property
    def hash(self) -> str:
        return scene_hash(self.science)

    @property
    def n_points(self) -> int:
        return len(self.points)

    @property
    def n_solves(self) -> int:
        """Solves of a run (without the references): the size ``paper --quick`` reduces."""
        per_point = len(self.methods) * (len(self.rtols) + len(self.fixed_steps)) + len(self.baseline_tolerances)
        return self.n_points * per_point

    @property
    def reference_rtol(self) -> float:
        return self.rtol_factor * min(self.rtols)

    @property
    def dims(self) -> tuple[str, ...]:
        return ("point",)

    @property
    def shape(self) -> tuple[int, ...]:
        return (self.n_points,)


# ---------------------------------------------------------------------------
# Parsing
# ---------------------------------------------------------------------------


def _positive(ctx: ParseContext, obj, key) -> float:
    """A positive number, also written "2^x"."""
    if isinstance(obj, str) and _POW2_RE.match(obj):
        v = 2.0 ** float(_POW2_RE.match(obj).group(1))
    else:
        v = ctx.number(obj, key)
    if not v > 0:
        raise ctx.err(key, f"must be > 0, got {v:g}")
    return v


def _physics_value(ctx: ParseContext, name: str, obj, key) -> float:
    if name in ("anisotropy_ratio", "scaled_period"):
        return _positive(ctx, obj, key)
    v = ctx.number(obj, key)
    if name == "p" and not 0 <= v < 2:
        raise ctx.err(key, f"must be in [0, 2), got {v:g}")
    if name == "delta" and not v >= 0:
        raise ctx.err(key, f"must be >= 0, got {v:g}")
    return v


def _coefficients(ctx: ParseContext, obj, key) -> tuple[float, ...]:
    if not isinstance(obj, list) or not obj:
        raise ctx.err(key, f"must be a non-empty array of numbers, got {type_name(obj)}")
    return tuple(ctx.number(v, f"{key}[{i}]", allow_pi=True) for i, v in enumerate(obj))


def _shape_entry(ctx: ParseContext, family: str, name: str, obj, key):
    if name in ("A", "B"):
        return _coefficients(ctx, obj, key)
    if name in ("closing_shape", "opening_shape"):
        return parse_shape(ctx, obj, key)
    v = ctx.number(obj, key, allow_pi=name in ("A0", "A1"))
    if name == "A1" and v < 0:
        raise ctx.err(key, f"amplitude must be >= 0, got {v:g}")
    if name == "duty_cycle" and not 0 < v < 1:
        raise ctx.err(key, f"must be in (0, 1) (tau0), got {v:g}")
    return v


def _parse_case(ctx: ParseContext, obj, key: str, base: dict) -> StudyCase:
    allowed = {"name": "", "family": "", **{k: "" for k in _PHYSICS_KEYS}}
    for keys in _FAMILY_KEYS.values():
        allowed.update({k: "" for k in keys})
    ctx.table(obj, key, allowed, required=("name", "family"))
    name = ctx.string(obj["name"], f"{key}.name")
    family = ctx.string(obj["family"], f"{key}.family", FAMILIES)
    for k in obj:
        if k in allowed and k not in ("name", "family", *_PHYSICS_KEYS, *_FAMILY_KEYS[family]):
            raise ctx.err(f"{key}.{k}", f"not a parameter of family {family!r} "
                                        f"(it takes {', '.join(_FAMILY_KEYS[family])})")
    shape = []
    for k in _FAMILY_KEYS[family]:
        if k not in obj:
            raise ctx.err(f"{key}.{k}", f"missing: family {family!r} needs {k}")
        shape.append((k, _shape_entry(ctx, family, k, obj[k], f"{key}.{k}")))
    if family == "fourier" and len(dict(shape)["B"]) != len(dict(shape)["A"]) - 1:
        raise ctx.err(f"{key}.B", "needs one coefficient fewer than A (B1..BK for A0..AK)")
    phys = {}
    for k in _PHYSICS_KEYS:
        if k in obj:
            phys[k] = _physics_value(ctx, k, obj[k], f"{key}.{k}")
        elif k in base:
            phys[k] = base[k]
        else:
            raise ctx.err(f"{key}.{k}", "missing (give it here or in [base])")
    if phys["delta"] == 0 and phys["p"] == 0:
        raise ctx.err(f"{key}.delta", "delta = 0 needs p > 0")
    return StudyCase(name, family, tuple(shape), **phys)


def _values(ctx: ParseContext, obj, key: str, kind: str) -> tuple[float, ...]:
    """A list of numbers, or ``{log10_range | log2_range | range = [a, b], step = s}`` (from a
    towards b in steps of s; a and b may be in either order)."""
    if isinstance(obj, list):
        if not obj:
            raise ctx.err(key, "empty list")
        return tuple(ctx.number(v, f"{key}[{i}]") if kind != "positive" else _positive(ctx, v, f"{key}[{i}]")
                     for i, v in enumerate(obj))
    ctx.table(obj, key, {"log10_range": "", "log2_range": "", "range": "", "step": ""}, required=("step",))
    forms = [k for k in ("log10_range", "log2_range", "range") if k in obj]
    if len(forms) != 1:
        raise ctx.err(key, "give exactly one of log10_range, log2_range, range (with step), or a list")
    form = forms[0]
    bounds = obj[form]
    if not isinstance(bounds, list) or len(bounds) != 2:
        raise ctx.err(f"{key}.{form}", f"must be [a, b], got {bounds!r}")
    a, b = (ctx.number(v, f"{key}.{form}") for v in bounds)
    step = ctx.number(obj["step"], f"{key}.step")
    if step <= 0:
        raise ctx.err(f"{key}.step", f"must be > 0, got {step:g}")
    n = int(math.floor(abs(b - a) / step + 1e-9))
    x = a + math.copysign(step, b - a if b != a else 1.0) * np.arange(n + 1)
    base = {"log10_range": 10.0, "log2_range": 2.0}.get(form)
    return tuple(float(base ** v) if base else float(v) for v in x)


def _parse_scan(ctx: ParseContext, obj, key: str) -> Scan:
    ctx.table(obj, key, {"parameter": "", "values": "", "log10_range": "", "log2_range": "", "range": "",
                         "step": ""}, required=("parameter",))
    parameter = ctx.string(obj["parameter"], f"{key}.parameter", tuple(SCAN_PARAMETERS))
    spec = obj["values"] if "values" in obj else {k: v for k, v in obj.items() if k != "parameter"}
    if "values" in obj and len(obj) > 2:
        raise ctx.err(key, "give values or a range with step, not both")
    values = _values(ctx, spec, f"{key}.values" if "values" in obj else key, "number")
    for i, v in enumerate(values):
        ok = {"delta": v >= 0, "scaled_period": v > 0, "anisotropy_ratio": v > 0, "p": 0 <= v < 2,
              "exponent": v >= 1, "duty_cycle": 0 < v < 1}[parameter]
        if not ok:
            raise ctx.err(f"{key}.values", f"value {v:g} outside the domain of {parameter}")
    return Scan(parameter, tuple(sorted(values)))


def _stiffness_points(ctx, motions, scans) -> tuple[StudyPoint, ...]:
    points = []
    for j, sw in enumerate(scans):
        applicable = [i for i, m in enumerate(motions) if m.family in SCAN_PARAMETERS[sw.parameter]]
        if not applicable:
            raise ctx.err(f"scans[{j}].parameter", f"no motion of a family {sw.parameter!r} applies to "
                                                    f"({', '.join(SCAN_PARAMETERS[sw.parameter])})")
        for i in applicable:
            for v in sw.values:
                case = motions[i].with_parameter(sw.parameter, v)
                if case.p == 0 and case.delta == 0:
                    raise ctx.err(f"scans[{j}].values", f"delta = 0 needs p > 0 (motion {motions[i].name!r})")
                points.append(StudyPoint(case, i, j, float(v)))
    return tuple(points)


_TOP = {"scene": "", "solver": "", "reference": "", "baseline": "", "base": "", "cases": "", "motions": "",
        "scans": "", "execution": ""}


def parse_study(doc: dict, text: str, file: str) -> StudyScene:
    """Validate the TOML document ``doc`` of a study scene (``[scene] kind`` accuracy or stiffness)."""
    ctx = ParseContext(file)
    if "sweeps" in doc:  # the key's name before issue 37 ("sweep" is a warm-start chain of points)
        raise ctx.err("sweeps", "renamed: write [[scans]] (a parameter scanned over values)")
    ctx.table(doc, "", _TOP, required=("scene", "solver"))
    head = ctx.table(doc["scene"], "scene", {"name": "", "title": "", "figure": "", "kind": ""},
                     required=("name", "kind"))
    kind = ctx.string(head["kind"], "scene.kind", ("grid",) + STUDY_KINDS)
    name = ctx.string(head["name"], "scene.name")
    if not re.match(r"^[A-Za-z][A-Za-z0-9_]*$", name):
        raise ctx.err("scene.name", f"must be an identifier, got {name!r}")
    title = ctx.string(head.get("title", ""), "scene.title")
    figure = ctx.string(head.get("figure", ""), "scene.figure")
    accuracy = kind == "accuracy"
    wrong = ("base", "motions", "scans") if accuracy else ("cases", "baseline")
    for k in wrong:
        if k in doc:
            raise ctx.err(k, f"not used by a {kind!r} scene")

    sol = ctx.table(doc["solver"], "solver", {"methods": "", "rtols": "", "fixed_steps": "", "fallback": "",
                                              "march_max_steps_per_period": ""}, required=("rtols",))
    methods = ctx.names(sol.get("methods", list(METHOD_NAMES)), "solver.methods", METHOD_NAMES)
    rtols = tuple(sorted(_values(ctx, sol["rtols"], "solver.rtols", "positive"), reverse=True))
    if any(not 0 < r <= 0.1 for r in rtols) or len(set(rtols)) != len(rtols):
        raise ctx.err("solver.rtols", "each rtol must be in (0, 0.1], without repeats")
    if "fixed_steps" in sol and not accuracy:
        raise ctx.err("solver.fixed_steps", "only for accuracy scenes")
    fixed = tuple(sorted({int(round(v)) for v in _values(ctx, sol.get("fixed_steps", []), "solver.fixed_steps",
                                                          "positive")})) if sol.get("fixed_steps") else ()
    if any(n < 4 for n in fixed):
        raise ctx.err("solver.fixed_steps", "grids need at least 4 steps")
    fallback = ctx.string(sol.get("fallback", "none"), "solver.fallback", FALLBACKS)
    if accuracy and fallback != "none":
        raise ctx.err("solver.fallback", "only for stiffness scenes (work-precision compares each method alone)")
    mmax = (ctx.integer(sol["march_max_steps_per_period"], "solver.march_max_steps_per_period", lo=64)
            if "march_max_steps_per_period" in sol else None)

    ref = ctx.table(doc.get("reference", {}), "reference",
                    {"rtol_factor": "", "check": "", "check_rtol": "", "check_steps": ""})
    factor = ctx.number(ref.get("rtol_factor", 1e-3), "reference.rtol_factor")
    if not 0 < factor <= 0.1:
        raise ctx.err("reference.rtol_factor", f"must be in (0, 0.1] (the reference must be finer), got {factor:g}")
    if factor * min(rtols) < 1e-13:
        raise ctx.err("reference.rtol_factor", f"reference rtol {factor * min(rtols):g} is below 1e-13")
    check = ctx.string(ref.get("check", "march" if accuracy else "fixed"), "reference.check", CHECKS)
    check_rtol = ctx.number(ref.get("check_rtol", 1e-8), "reference.check_rtol")
    if not 1e-13 <= check_rtol <= 1e-3:
        raise ctx.err("reference.check_rtol", f"must be in [1e-13, 1e-3], got {check_rtol:g}")
    check_steps = ctx.integer(ref.get("check_steps", 2 ** 16), "reference.check_steps", lo=64)

    base_doc = ctx.table(doc.get("baseline", {}), "baseline", {"tolerances": "", "cap_seconds": ""})
    btols = tuple(sorted(_values(ctx, base_doc["tolerances"], "baseline.tolerances", "positive"), reverse=True)) \
        if "tolerances" in base_doc else ()
    if any(not 1e-13 <= t <= 1e-2 for t in btols):
        raise ctx.err("baseline.tolerances", "each tolerance must be in [1e-13, 1e-2]")
    cap = ctx.number(base_doc.get("cap_seconds", 20.0), "baseline.cap_seconds")
    if not cap > 0:
        raise ctx.err("baseline.cap_seconds", f"must be > 0, got {cap:g}")

    base_tbl = ctx.table(doc.get("base", {}), "base", {k: "" for k in _PHYSICS_KEYS})
    base = {"p": 0.0, "delta": 1e-5}
    base.update({k: _physics_value(ctx, k, v, f"base.{k}") for k, v in base_tbl.items()})
    list_key = "cases" if accuracy else "motions"
    raw = doc.get(list_key)
    if not isinstance(raw, list) or not raw:
        raise ctx.err(list_key, f"a {kind!r} scene needs at least one [[{list_key}]] table")
    motions = tuple(_parse_case(ctx, c, f"{list_key}[{i}]", base) for i, c in enumerate(raw))
    names = [m.name for m in motions]
    for i, n in enumerate(names):
        if n in names[:i]:
            raise ctx.err(f"{list_key}[{i}].name", f"{n!r} is used twice")
    if accuracy:
        scans = ()
        points = tuple(StudyPoint(m, i) for i, m in enumerate(motions))
    else:
        raw_scans = doc.get("scans")
        if not isinstance(raw_scans, list) or not raw_scans:
            raise ctx.err("scans", "a stiffness scene needs at least one [[scans]] table")
        scans = tuple(_parse_scan(ctx, s, f"scans[{i}]") for i, s in enumerate(raw_scans))
        points = _stiffness_points(ctx, motions, scans)

    ex = ctx.table(doc.get("execution", {}), "execution",
                   {"points_per_task": "", "scheduler": "", "workers": "", "store": ""})
    execution = Execution(
        points_per_task=ctx.integer(ex["points_per_task"], "execution.points_per_task", lo=1)
        if "points_per_task" in ex else None,
        scheduler=ctx.string(ex.get("scheduler", "processes"), "execution.scheduler",
                             ("processes", "threads", "synchronous")),
        workers=ctx.integer(ex["workers"], "execution.workers", lo=1) if "workers" in ex else None,
        store=ctx.string(ex["store"], "execution.store") if "store" in ex else None,
    )
    science = {
        "name": name, "kind": kind, "family": "study",
        "motions": [m.json() for m in motions],
        "scans": [{"parameter": s.parameter, "values": list(s.values)} for s in scans],
        "solver": {"methods": list(methods), "rtols": list(rtols), "fixed_steps": list(fixed),
                   "fallback": fallback, "march_max_steps_per_period": mmax},
        "reference": {"rtol": factor * min(rtols), "rtol_factor": factor, "check": check,
                      "check_rtol": check_rtol, "check_steps": check_steps},
        "baseline": {"tolerances": list(btols), "cap_seconds": cap},
    }
    return StudyScene(path=file, name=name, title=title, figure=figure, kind=kind, motions=motions, scans=scans,
                      points=points, methods=methods, rtols=rtols, fixed_steps=fixed,
                      march_max_steps_per_period=mmax, fallback=fallback, rtol_factor=factor, check=check,
                      check_rtol=check_rtol, check_steps=check_steps, baseline_tolerances=btols,
                      baseline_cap_seconds=cap, execution=execution, science=science, text=text)


def parse_study_scene(doc: dict, ctx, text: str) -> StudyScene:
    """``parse_study`` with the signature of a scene kind's parser (``_kind.SceneKind.parse``)."""
    return parse_study(doc, text, ctx.file)
