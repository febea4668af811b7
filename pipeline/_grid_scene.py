"""Grid scenes (``[scene] kind = "grid"``, the default): their schema, parsed and validated into
frozen dataclasses.

A grid scene sweeps a family's parameters over the axes of a grid (:class:`Scene`), stores the
solver's quantities and diagnostics at every point, u(tau) at a few points (:class:`Series`) and
reductions of the stored grid (:class:`Reduction`, optionally over :class:`Subsets`).  What every
kind shares (errors, value checks, axes, hashing) is ``_scene``; the chunk layout and the solves
are ``_grid``, the chunk task and steps ``_grid_kind``, the reductions ``_reduce``.

Every error is a :class:`~pipeline._scene.SceneError` whose message names the file, the key and
the reason, on one line.
"""

from __future__ import annotations

import math
import re
from dataclasses import dataclass, field

import numpy as np

from ._scene import (FOURIER_COEFFICIENT, MAX_FOURIER_WAVENUMBER, Axis, Execution, ParseContext, parameter_units,
                     parse_axis, parse_value, scene_hash)

__all__ = [
    "DEFAULT_POINTS_PER_CHUNK",
    "DIAGNOSTICS",
    "FAMILY_PARAMETERS",
    "QUANTITIES",
    "Reduction",
    "Scene",
    "Series",
    "Subsets",
    "axis_attrs",
    "parse_grid_scene",
]


# ---------------------------------------------------------------------------
# Vocabulary: parameters of each family, their long names, and outputs.
# ---------------------------------------------------------------------------

#: Parameters every family takes. ``anisotropy_ratio`` = mu_n/mu_s and
#: ``scaled_period`` = (mu_n mu_s)^(1/(4-2p)) T may be replaced by the pair
#: ``T2_mu_n`` = T^(2-p) mu_n and ``T2_mu_s`` = T^(2-p) mu_s (figure EtaA0A1).
_PHYSICS = ("p", "delta")
_FRICTION_SCALED = ("anisotropy_ratio", "scaled_period")
_FRICTION_PRODUCTS = ("T2_mu_n", "T2_mu_s")

FAMILY_PARAMETERS: dict[str, tuple[str, ...]] = {
    "harmonic": ("A0", "A1_ratio"),
    "powerlaw": ("A0", "A1_ratio", "duty_cycle", "closing_shape", "opening_shape"),
    # phi = A0 + sum_k A_k cos(2 pi k tau) + B_k sin(2 pi k tau) (eq. Fourier): A0 is needed, the
    # others are optional (0 where not given), and the largest k given is the motion's Kmax
    "fourier": ("A0",),
}
#: Optional parameters of a family: any of them as an axis or in [fixed].
FAMILY_OPTIONAL: dict[str, tuple[str, ...]] = {
    "fourier": tuple(f"{c}{k}" for k in range(1, MAX_FOURIER_WAVENUMBER + 1) for c in "AB"),
}


def fourier_wavenumber(names) -> int:
    """Kmax of a Fourier grid scene: the largest k of the coefficients A_k, B_k among ``names``
    (0 when only A0 is given)."""
    return max((int(m.group(2)) for n in names if (m := FOURIER_COEFFICIENT.match(n))), default=0)

#: Defaults for parameters a scene may leave out (paper: delta = 1e-5, p = 0).
_DEFAULTS = {"p": 0.0, "delta": 1e-5}

_LONG_NAMES = {
    "anisotropy_ratio": "friction anisotropy ratio mu_n/mu_s",
    "scaled_period": "scaled period (mu_n mu_s)^(1/(4-2p)) T",
    "T2_mu_n": "T^(2-p) mu_n",
    "T2_mu_s": "T^(2-p) mu_s",
    "A0": "mean half-opening angle A0",
    "A1_ratio": "normalised amplitude A1/A0",
    "duty_cycle": "duration of the closing phase tau0 (duty cycle)",
    "closing_shape": "closing power law: +g concave up (eq. rapidbegc), -g concave down (eq. rapidendc), 1 linear",
    "opening_shape": "opening power law: +g concave up (eq. rapidendo), -g concave down (eq. rapidbego), 1 linear",
    "p": "exponent p of the resistive force law (eq. frictionp)",
    "delta": "velocity regularisation delta (eq. delta)",
    **{f"{c}{k}": f"Fourier {'cosine' if c == 'A' else 'sine'} coefficient {c}{k} of phi (eq. Fourier) [rad]"
       for k in range(1, MAX_FOURIER_WAVENUMBER + 1) for c in "AB"},
}

#: Quantities a scene can store: solver outputs plus derived ones.
QUANTITIES: dict[str, str] = {
    "U": "time-averaged speed U (eq. U), at mu_n mu_s = 1",
    "P": "time-averaged power P (eq. power), at mu_n mu_s = 1",
    "efficiency": "efficiency lambda = U/P (eq. lambda), at mu_n mu_s = 1; signed like U",
    "scaled_speed": "scaled speed (mu_n mu_s)^(-1/(4-2p)) U",
    "scaled_power": "scaled power",
    "scaled_efficiency": "scaled efficiency sqrt(mu_n mu_s) lambda; signed like U",
    "relative_efficiency": "relative efficiency lambda/lambda_ub (eq. relefficiency); signed like U",
    "efficiency_upper_bound": "lambda_ub = 1/min(mu_n, mu_s), at mu_n mu_s = 1",
    "displacement_per_period": "T U: distance travelled per period [body lengths]",
}
#: Per-point diagnostics a scene can store.
DIAGNOSTICS: dict[str, str] = {
    "error_estimate": "solver error estimate",
    "iterations": "solver iterations",
    "n_tau": "final tau-grid size",
}
_STATISTICS = ("max", "min", "absmax")
#: a polish's relative value tolerance in ``paper --quick`` (a smoke run, not a result)
QUICK_POLISH_TOLERANCE = 1e-2
_POLISH_METHODS = ("L-BFGS-B", "Powell", "Nelder-Mead", "compass")  # pipeline.polish.METHODS
_SCHEDULERS = ("processes", "threads", "synchronous")

_NAME_RE = re.compile(r"^[A-Za-z][A-Za-z0-9_]*$")


# ---------------------------------------------------------------------------
# Dataclasses
# ---------------------------------------------------------------------------


@dataclass(frozen=True)
class Subsets:
    """Nested subsets of one or two axes over which a reduction is repeated.

    kind "window": values v of ``axes[0]`` with |v - center| <= halfwidth, one subset per halfwidth
    (figure EtaVsMint0). kind "exponent_sets": shapes whose exponent |g| is in the set, for every
    axis in ``axes`` (figure EtaVsMinGamma).
    """

    kind: str
    axes: tuple[str, ...]
    dim: str
    labels: tuple[float, ...]
    center: float = 0.5
    sets: tuple[tuple[float, ...], ...] = ()

    def masks(self, scene: "Scene") -> list[dict[str, np.ndarray]]:
        """For each subset, a boolean mask per axis in ``axes`` (shape (axis size,))."""
        out = []
        for k, label in enumerate(self.labels):
            masks = {}
            for name in self.axes:
                v = scene.axis(name).array()
                if self.kind == "window":
                    masks[name] = np.abs(v - self.center) <= label + 1e-12
                else:
                    masks[name] = np.isin(np.abs(v), np.asarray(self.sets[k]))
            out.append(masks)
        return out


@dataclass(frozen=True)
class Reduction:
    """A statistic of one stored quantity over some axes, with its arg-max parameters.

    The result keeps the other axes (plus ``subsets.dim`` when given). With ``polish`` every
    cell is polished from its best ``polish_starts`` distinct grid basins by a bounded local
    method over the continuous axes in ``over`` (``pipeline.polish``): "L-BFGS-B" (default,
    chosen by measurement, docs/validation.md), "Powell", "Nelder-Mead" or "compass", each start until
    the value changes by less than ``polish_tolerance`` (relative) or ``polish_max_evaluations``
    solver calls (then the cell's status says "cap reached", never converged), at solver rtol
    ``polish_rtol`` (default the grid's).
    """

    name: str
    quantity: str
    statistic: str
    over: tuple[str, ...]
    report: tuple[str, ...] = ()
    polish: bool = False
    polish_method: str = "L-BFGS-B"
    polish_rtol: float | None = None
    polish_max_evaluations: int = 600
    subsets: Subsets | None = None
    polish_tolerance: float = 1e-4
    polish_starts: int = 3


@dataclass(frozen=True)
class Series:
    """u(tau) stored at a few points, resampled to ``n_tau`` uniform nodes tau_k = k/n_tau.

    ``points`` holds, per point, a value for every axis of the scene (fixed parameters as in
    ``[fixed]``).
    """

    n_tau: int
    points: tuple[tuple[tuple[str, float], ...], ...]


#: Points of one block (a task's unit) of a grid store unless the scene says ``[execution]
#: points_per_chunk``.  A constant, never a timing: where blocks begin decides which grid
#: neighbours a block's sweep may start from, so it must follow from the scene alone
#: (``_grid.scene_chunks``); the store's chunks are whole blocks (``_store.storage_chunks``).
DEFAULT_POINTS_PER_CHUNK = 256


@dataclass(frozen=True)
class Scene:
    """A validated grid scene. ``science`` is the normalised JSON-able dict that is hashed."""

    path: str
    name: str
    title: str
    figure: str
    family: str
    axes: tuple[Axis, ...]
    fixed: tuple[tuple[str, float], ...]
    method: str
    rtol: float
    quantities: tuple[str, ...]
    diagnostics: tuple[str, ...]
    reductions: tuple[Reduction, ...]
    series: "Series | None"
    execution: Execution
    science: dict = field(compare=False, repr=False)
    text: str = field(default="", compare=False, repr=False)
    kind: str = "grid"
    #: ``[solver] sweeps``: each chunk solved as sweeps in snake order (``_grid.chunk_sweeps``)
    sweeps: bool = False

    # -- convenience -------------------------------------------------------
    @property
    def dims(self) -> tuple[str, ...]:
        return tuple(a.name for a in self.axes)

    @property
    def shape(self) -> tuple[int, ...]:
        return tuple(a.size for a in self.axes)

    @property
    def n_points(self) -> int:
        return int(np.prod(self.shape, dtype=np.int64))

    @property
    def outputs(self) -> tuple[str, ...]:
        return self.quantities + self.diagnostics

    def axis(self, name: str) -> Axis:
        for a in self.axes:
            if a.name == name:
                return a
        raise KeyError(name)

    @property
    def hash(self) -> str:
        return scene_hash(self.science)

    def fixed_dict(self) -> dict[str, float]:
        return dict(self.fixed)

    def quick_variant(self) -> "Scene":
        """The scene for ``pipeline paper --quick``: every polish to ``QUICK_POLISH_TOLERANCE``
        (relative) and a quarter of its cap (the axes are reduced by ``__main__.quick_variant``)."""
        from dataclasses import replace

        reds = tuple(replace(r, polish_tolerance=max(r.polish_tolerance, QUICK_POLISH_TOLERANCE),
                             polish_max_evaluations=max(1, r.polish_max_evaluations // 4)) if r.polish else r
                     for r in self.reductions)
        return replace(self, reductions=reds, science={**self.science, "reductions": [_reduction_json(r) for r in reds]})

    @property
    def max_wavenumber(self) -> int | None:
        """Kmax of a Fourier scene (the largest k of its coefficients A_k, B_k), else None."""
        if self.family != "fourier":
            return None
        return fourier_wavenumber(list(self.dims) + [k for k, _ in self.fixed])


# ---------------------------------------------------------------------------
# Parsing
# ---------------------------------------------------------------------------


_REDUCTION_KEYS = {
    "name": "name of the result arrays",
    "quantity": "stored quantity to reduce",
    "statistic": "max, min or absmax",
    "over": "axes reduced",
    "report": "other quantities reported at the arg-max",
    "polish": "refine the grid optimum with a local optimiser",
    "polish_method": "L-BFGS-B (default), Powell, Nelder-Mead or compass",
    "polish_rtol": "solver rtol while polishing",
    "polish_max_evaluations": "cap on solver calls per start (reached: status 1, not converged)",
    "polish_tolerance": "relative value tolerance at which a start has converged (default 1e-4)",
    "polish_starts": "distinct grid basins polished per cell (default 3)",
    "window": "nested windows of one axis",
    "exponent_sets": "nested sets of power-law exponents",
}


def _parse_reduction(ctx: ParseContext, obj, key: str, dims, stored) -> Reduction:
    ctx.table(obj, key, _REDUCTION_KEYS, required=("name", "quantity", "over"))
    name = ctx.string(obj["name"], f"{key}.name")
    if not _NAME_RE.match(name):
        raise ctx.err(f"{key}.name", f"must be an identifier, got {name!r}")
    quantity = ctx.string(obj["quantity"], f"{key}.quantity")
    if quantity not in stored:
        raise ctx.err(f"{key}.quantity", f"{quantity!r} is not among the scene's outputs ({', '.join(stored)})")
    statistic = ctx.string(obj.get("statistic", "max"), f"{key}.statistic", _STATISTICS)
    over = ctx.names(obj["over"], f"{key}.over", dims)
    report = ctx.names(obj.get("report", []), f"{key}.report", stored, nonempty=False)
    polish = ctx.boolean(obj.get("polish", False), f"{key}.polish")
    method = ctx.string(obj.get("polish_method", "L-BFGS-B"), f"{key}.polish_method", _POLISH_METHODS)
    prtol = None
    if "polish_rtol" in obj:
        prtol = ctx.number(obj["polish_rtol"], f"{key}.polish_rtol")
        if not 0 < prtol <= 0.1:
            raise ctx.err(f"{key}.polish_rtol", f"must be in (0, 0.1], got {prtol:g}")
    pmax = ctx.integer(obj.get("polish_max_evaluations", 600), f"{key}.polish_max_evaluations", lo=1)
    ptol = ctx.number(obj.get("polish_tolerance", 1e-4), f"{key}.polish_tolerance")
    if not 0 < ptol < 1:
        raise ctx.err(f"{key}.polish_tolerance", f"must be in (0, 1), got {ptol:g}")
    pstarts = ctx.integer(obj.get("polish_starts", 3), f"{key}.polish_starts", lo=1)
    subsets = None
    if "window" in obj and "exponent_sets" in obj:
        raise ctx.err(key, "give at most one of window, exponent_sets")
    if "window" in obj:
        wkey = f"{key}.window"
        w = ctx.table(obj["window"], wkey, {"axis": "axis windowed", "center": "window centre",
                                            "halfwidths": "list of half-widths"},
                      required=("axis", "halfwidths"))
        axis = ctx.string(w["axis"], f"{wkey}.axis", over)
        center = ctx.number(w.get("center", 0.5), f"{wkey}.center")
        hw = w["halfwidths"]
        if not isinstance(hw, list) or not hw:
            raise ctx.err(f"{wkey}.halfwidths", "must be a non-empty array of numbers")
        hws = [ctx.number(v, f"{wkey}.halfwidths[{i}]") for i, v in enumerate(hw)]
        if any(v < 0 for v in hws):
            raise ctx.err(f"{wkey}.halfwidths", "half-widths must be >= 0")
        if any(b <= a for a, b in zip(hws, hws[1:])):
            raise ctx.err(f"{wkey}.halfwidths", "must be strictly increasing")
        subsets = Subsets("window", (axis,), f"{axis}_halfwidth", tuple(hws), center=center)
    if "exponent_sets" in obj:
        ekey = f"{key}.exponent_sets"
        e = ctx.table(obj["exponent_sets"], ekey, {"axes": "shape axes", "sets": "list of exponent sets"},
                      required=("axes", "sets"))
        axes = ctx.names(e["axes"], f"{ekey}.axes", [d for d in over if d.endswith("_shape")])
        sets = e["sets"]
        if not isinstance(sets, list) or not sets:
            raise ctx.err(f"{ekey}.sets", "must be a non-empty array of arrays of exponents")
        parsed = []
        for i, s in enumerate(sets):
            if not isinstance(s, list) or not s:
                raise ctx.err(f"{ekey}.sets[{i}]", "must be a non-empty array of exponents")
            vals = tuple(sorted(ctx.number(v, f"{ekey}.sets[{i}]") for v in s))
            if any(v < 1 for v in vals):
                raise ctx.err(f"{ekey}.sets[{i}]", "exponents must be >= 1")
            parsed.append(vals)
        subsets = Subsets("exponent_sets", axes, "exponent_set", tuple(float(i) for i in range(len(parsed))),
                          sets=tuple(parsed))
    return Reduction(name, quantity, statistic, over, report, polish, method, prtol, pmax, subsets, ptol, pstarts)


_TOP_KEYS = {
    "scene": "kind (grid, default), name, title, figure, family",
    "axes": "swept parameters",
    "fixed": "parameters held fixed",
    "solver": "method, rtol and sweeps",
    "outputs": "stored quantities and diagnostics",
    "reductions": "maxima over axes",
    "series": "u(tau) at a few points",
    "execution": "points_per_chunk, points_per_task, scheduler, workers, store (not hashed)",
}


def _check_fourier_keys(ctx: ParseContext, table, section: str, allowed) -> None:
    """A key of ``[axes]`` or ``[fixed]`` a Fourier grid scene does not take: one line saying
    which coefficients exist (the generic message would list all 32 of them)."""
    if not isinstance(table, dict):
        return
    for k in table:
        if k in allowed:
            continue
        if k == "B0":
            why = "there is no sine coefficient of wavenumber 0 (B1, B2, ...; A0 is the mean angle)"
        elif (m := re.match(r"^[AB](\d+)$", k)) and int(m.group(1)) > MAX_FOURIER_WAVENUMBER:
            why = f"wavenumber {int(m.group(1))} is above the largest, {MAX_FOURIER_WAVENUMBER}"
        else:
            why = (f"unknown key for family 'fourier' (allowed: A0, A1..A{MAX_FOURIER_WAVENUMBER}, "
                   f"B1..B{MAX_FOURIER_WAVENUMBER} [rad], anisotropy_ratio and scaled_period or T2_mu_n and "
                   "T2_mu_s, p, delta)")
        raise ctx.err(f"{section}.{k}", why)


def parse_grid_scene(doc: dict, ctx: "ParseContext", text: str) -> Scene:
    """Validate the parsed TOML ``doc`` of a grid scene (``[scene] kind = "grid"``, the
    default); ``text`` is kept as provenance.  Errors are :class:`SceneError` naming the key."""
    ctx.table(doc, "", _TOP_KEYS, required=("scene", "axes", "solver", "outputs"))

    head = ctx.table(doc["scene"], "scene", {"kind": "", "name": "", "title": "", "figure": "",
                                             "family": ""}, required=("name", "family"))
    name = ctx.string(head["name"], "scene.name")
    if not _NAME_RE.match(name):
        raise ctx.err("scene.name", f"must be an identifier, got {name!r}")
    title = ctx.string(head.get("title", ""), "scene.title")
    figure = ctx.string(head.get("figure", ""), "scene.figure")
    family = ctx.string(head["family"], "scene.family", tuple(FAMILY_PARAMETERS))

    known = (FAMILY_PARAMETERS[family] + FAMILY_OPTIONAL.get(family, ()) + _FRICTION_SCALED + _FRICTION_PRODUCTS
             + _PHYSICS)
    allowed = {k: _LONG_NAMES[k] for k in known}
    if family == "fourier":
        for section in ("axes", "fixed"):
            _check_fourier_keys(ctx, doc.get(section, {}), section, allowed)
    axes_doc = ctx.table(doc["axes"], "axes", allowed)
    if not axes_doc:
        raise ctx.err("axes", "at least one axis is needed")
    fixed_doc = ctx.table(doc.get("fixed", {}), "fixed", allowed)
    axes = tuple(parse_axis(ctx, k, v, f"axes.{k}") for k, v in axes_doc.items())
    fixed: dict[str, float] = {}
    for k, v in fixed_doc.items():
        if k in axes_doc:
            raise ctx.err(f"fixed.{k}", "is also an axis")
        fixed[k] = parse_value(ctx, k, v, f"fixed.{k}")
    given = set(axes_doc) | set(fixed)
    for k, v in _DEFAULTS.items():
        if k not in given:
            fixed[k] = v
            given.add(k)
    for k in FAMILY_PARAMETERS[family]:
        if k not in given:
            raise ctx.err(f"axes.{k}", f"missing: family {family!r} needs {k} as an axis or in [fixed]")
    scaled = [k for k in _FRICTION_SCALED if k in given]
    products = [k for k in _FRICTION_PRODUCTS if k in given]
    if not ((len(scaled) == 2 and not products) or (len(products) == 2 and not scaled)):
        raise ctx.err("axes", "give friction as anisotropy_ratio and scaled_period, or as T2_mu_n and T2_mu_s "
                              f"(axes or fixed); got {', '.join(scaled + products) or 'none'}")

    def extreme(k, f):
        return f(axes[[a.name for a in axes].index(k)].values) if k in axes_doc else fixed[k]

    # Cross-parameter domains: phi stays in [0, pi] (Fourier motions may leave it: the paper's
    # clapping convention); delta = 0 needs p > 0.
    if family != "fourier" and extreme("A0", max) * (1 + extreme("A1_ratio", max)) > math.pi + 1e-12:
        raise ctx.err("axes.A1_ratio", "A0 (1 + A1/A0) exceeds pi: the angle phi would leave [0, pi]")
    if extreme("delta", min) == 0 and extreme("p", min) == 0:
        raise ctx.err("fixed.delta" if "delta" in fixed else "axes.delta", "delta = 0 needs p > 0")

    sol = ctx.table(doc["solver"], "solver", {"method": "periodic or march", "rtol": "relative tolerance",
                                              "sweeps": "true: warm starts along each chunk"},
                    required=("rtol",))
    method = ctx.string(sol.get("method", "periodic"), "solver.method", ("periodic", "march"))
    sweeps = ctx.boolean(sol["sweeps"], "solver.sweeps") if "sweeps" in sol else False
    if sweeps and method != "periodic":
        raise ctx.err("solver.sweeps", f"warm starts need method 'periodic', not {method!r}")
    rtol = ctx.number(sol["rtol"], "solver.rtol")
    if not 0 < rtol <= 0.1:
        raise ctx.err("solver.rtol", f"must be in (0, 0.1], got {rtol:g}")

    out = ctx.table(doc["outputs"], "outputs", {"quantities": "", "diagnostics": ""}, required=("quantities",))
    quantities = ctx.names(out["quantities"], "outputs.quantities", tuple(QUANTITIES))
    diagnostics = ctx.names(out.get("diagnostics", []), "outputs.diagnostics", tuple(DIAGNOSTICS), nonempty=False)
    stored = quantities + diagnostics

    red_doc = doc.get("reductions", [])
    if not isinstance(red_doc, list):
        raise ctx.err("reductions", "must be an array of tables ([[reductions]])")
    dims = tuple(a.name for a in axes)
    reductions = tuple(_parse_reduction(ctx, r, f"reductions[{i}]", dims, stored) for i, r in enumerate(red_doc))
    seen = set(stored) | set(dims) | {"status"}
    for i, r in enumerate(reductions):
        for array in _reduction_array_names(r):
            if array in seen:
                raise ctx.err(f"reductions[{i}].name", f"array {array!r} of {r.name!r} clashes with another array")
            seen.add(array)
    subset_dims: dict[str, tuple] = {}
    for i, r in enumerate(reductions):
        if r.subsets is None:
            continue
        dim, labels = r.subsets.dim, (r.subsets.labels, r.subsets.sets, r.subsets.center)
        if dim in seen or subset_dims.get(dim, labels) != labels:
            raise ctx.err(f"reductions[{i}]", f"subset dimension {dim!r} clashes with another array or "
                                              "with different subsets of another reduction")
        subset_dims[dim] = labels
        # Every subset must hold at least one grid point, or its results would be silently NaN.
        if r.subsets is not None:
            sub = r.subsets
            for ax in sub.axes:
                v = np.asarray(axes[dims.index(ax)].values)
                for k, label in enumerate(sub.labels):
                    if sub.kind == "window":
                        empty = not np.any(np.abs(v - sub.center) <= label + 1e-12)
                        what = f"window {sub.center:g} +- {label:g} holds no {ax} grid value"
                        key = f"reductions[{i}].window.halfwidths[{k}]"
                    else:
                        empty = not np.any(np.isin(np.abs(v), np.asarray(sub.sets[k])))
                        what = f"exponent set {list(sub.sets[k])} matches no {ax} grid value"
                        key = f"reductions[{i}].exponent_sets.sets[{k}]"
                    if empty:
                        raise ctx.err(key, what)

    series = _parse_series(ctx, doc["series"], dims, fixed) if "series" in doc else None

    ex = ctx.table(doc.get("execution", {}), "execution",
                   {"points_per_chunk": "", "points_per_task": "", "scheduler": "", "workers": "", "store": ""})
    execution = Execution(
        points_per_task=ctx.integer(ex["points_per_task"], "execution.points_per_task", lo=1)
        if "points_per_task" in ex else None,
        points_per_chunk=ctx.integer(ex["points_per_chunk"], "execution.points_per_chunk", lo=1)
        if "points_per_chunk" in ex else None,
        scheduler=ctx.string(ex.get("scheduler", "processes"), "execution.scheduler", _SCHEDULERS),
        workers=ctx.integer(ex["workers"], "execution.workers", lo=1) if "workers" in ex else None,
        store=ctx.string(ex["store"], "execution.store") if "store" in ex else None,
    )

    science = {
        "name": name,
        "family": family,
        "axes": [{"name": a.name, "values": list(a.values), "spacing": a.spacing} for a in axes],
        "fixed": dict(sorted(fixed.items())),
        # (with sweeps a point's value depends on its chunk's points: the layout is hashed)
        "solver": {"method": method, "rtol": rtol, **({"sweeps": True, "points_per_chunk": _chunk_points(execution)}
                                                      if sweeps else {})},
        "outputs": {"quantities": list(quantities), "diagnostics": list(diagnostics)},
        "reductions": [_reduction_json(r) for r in reductions],
        **({"series": {"n_tau": series.n_tau, "points": [dict(p) for p in series.points]}} if series else {}),
    }
    return Scene(path=ctx.file, name=name, title=title, figure=figure, family=family, axes=axes,
                 fixed=tuple(sorted(fixed.items())), method=method, rtol=rtol, sweeps=sweeps, quantities=quantities,
                 diagnostics=diagnostics, reductions=reductions, series=series, execution=execution, science=science, text=text)


def _chunk_points(execution: Execution) -> int:
    """``[execution] points_per_chunk`` or its default, DEFAULT_POINTS_PER_CHUNK."""
    return execution.points_per_chunk or DEFAULT_POINTS_PER_CHUNK


_MAX_SERIES_POINTS = 64


def _parse_series(ctx: ParseContext, obj, dims, fixed) -> Series:
    ctx.table(obj, "series", {"points": "tables giving every axis value", "n_tau": "uniform nodes per period"},
              required=("points",))
    n_tau = ctx.integer(obj.get("n_tau", 256), "series.n_tau", lo=4)
    pts = obj["points"]
    if not isinstance(pts, list) or not pts:
        raise ctx.err("series.points", "must be a non-empty array of tables")
    if len(pts) > _MAX_SERIES_POINTS:
        raise ctx.err("series.points", f"at most {_MAX_SERIES_POINTS} points (series are for a few points)")
    out = []
    for i, p in enumerate(pts):
        key = f"series.points[{i}]"
        ctx.table(p, key, {d: "" for d in dims}, required=dims)
        vals = {d: parse_value(ctx, d, p[d], f"{key}.{d}") for d in dims}
        a0 = vals.get("A0", fixed.get("A0"))
        a1r = vals.get("A1_ratio", fixed.get("A1_ratio"))
        if a0 is not None and a1r is not None and a0 * (1 + a1r) > math.pi + 1e-12:
            raise ctx.err(f"{key}.A1_ratio", "A0 (1 + A1/A0) exceeds pi: the angle phi would leave [0, pi]")
        out.append(tuple(vals.items()))
    return Series(n_tau, tuple(out))


def _reduction_array_names(r: Reduction) -> list[str]:
    """Names of the arrays a reduction writes (see pipeline._store.reduction_arrays)."""
    names = []
    for base in [r.name] + ([f"{r.name}_polished"] if r.polish else []):
        names.append(base)
        if r.statistic == "absmax":
            names.append(f"{base}_signed")
        names += [f"{base}_{a}" for a in r.over]
        names += [f"{base}_{q}" for q in r.report if q != r.quantity]
        if base != r.name:
            names += [f"{base}_status", f"{base}_evaluations", f"{base}_uncertainty"]
            names += [f"{base}_{a}_edge" for a in r.over]
    return names


def _reduction_json(r: Reduction) -> dict:
    d = {"name": r.name, "quantity": r.quantity, "statistic": r.statistic, "over": list(r.over),
         "report": list(r.report), "polish": r.polish}
    if r.polish:
        d.update(polish_method=r.polish_method, polish_rtol=r.polish_rtol,
                 polish_max_evaluations=r.polish_max_evaluations, polish_tolerance=r.polish_tolerance,
                 polish_starts=r.polish_starts)
    if r.subsets is not None:
        s = r.subsets
        d["subsets"] = {"kind": s.kind, "axes": list(s.axes), "labels": list(s.labels), "center": s.center,
                        "sets": [list(x) for x in s.sets]}
    return d


def axis_attrs(name: str) -> dict:
    """Attributes for a coordinate array: long name and units."""
    return {"long_name": _LONG_NAMES.get(name, name), "units": parameter_units(name)}
