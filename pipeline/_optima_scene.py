"""Optima scenes (``[scene] kind = "optima"``): their schema, parsed and validated into frozen
dataclasses.

An optima scene names the cells (anisotropy ratio mu_n/mu_s, Kmax, p), the random starts of
every cell, the optimiser's settings and what the reduction keeps (``[keep]``).  The
optimisations, the store and the distinct-optima reduction are ``_optima``; what every kind
shares (errors, value checks, axes, hashing) is ``_scene``.
"""

from __future__ import annotations

import math
import tomllib
from dataclasses import dataclass, field

import numpy as np

from ._scene import Execution, ParseContext, parse_axis, parse_value, scene_hash

__all__ = ["DIMS", "KIND", "Keep", "OptimaScene", "Optimizer", "STOP_CODES", "parse_optima_scene"]

KIND = "optima"
#: version of the optima kind's array layout and of what its per-start values mean (checked
#: by readers beside FORMAT_VERSION, and part of the scene's hash: a store of another version
#: is never resumed).  2: U, P, efficiency, objective are the engine's at the final motion
#: (``solver.OptimizeResult.engine_*``), the fixed grid's in grid_efficiency, with grid_error.
#: 3: every optimum certified (issue 47: searched again on finer steps where its grid_error
#: exceeds ``optimizer.certify_tolerance``; only certified starts kept), with the per-start
#: certified, at_rest, cpu_seconds, solves, coarse_iterations, certify_rounds
KIND_VERSION = 3
DIMS = ("anisotropy_ratio", "max_wavenumber", "p", "start")
#: optimiser stop reasons as the int8 ``status`` of a start; -1 not computed
STOP_CODES = {"gradient_tolerance": 0, "max_iterations": 1, "line_search_failed": 2,
              "ill_conditioned": 3, "solve_failed": 4, "no_progress": 5, "error": 6}
_OBJECTIVES = ("efficiency", "speed", "speed_at_power")

_TOP_KEYS = {
    "scene": "kind, name, title, figure, family",
    "axes": "anisotropy_ratio, max_wavenumber, p",
    "fixed": "delta",
    "starts": "num, seed, scaled_period",
    "optimizer": "objective, power, gtol, max_iterations, grid_rtol, grid_rounds, certify_tolerance, "
                 "certify_rounds, fidelity, fidelity_gtol",
    "keep": "best, n_tau, phi_tolerance, period_tolerance, accept",
    "quick": "overrides for `pipeline paper --quick`: max_wavenumber, p, starts, max_iterations",
    "execution": "starts_per_task, scheduler, workers, store (not hashed)",
}


# ---------------------------------------------------------------------------------------------
# the scene


@dataclass(frozen=True)
class Optimizer:
    """Settings of ``solver.optimize_motion`` for every start."""

    objective: str = "efficiency"
    direction: int = 0  # 0: keep the start's sign; -1: minimise (the paper's U < 0)
    power: float | None = None
    gtol: float = 1e-7
    max_iterations: int = 300
    grid_rtol: float = 1e-4
    grid_rounds: int = 3
    certify_tolerance: float = 1e-4
    certify_rounds: int = 2
    fidelity: float = 1.0
    fidelity_gtol: float = 1e-2


@dataclass(frozen=True)
class Keep:
    """The reduction: ``best`` distinct optima per cell, compared on ``n_tau`` samples."""

    best: int = 10
    n_tau: int = 128
    phi_tolerance: float = 0.02
    period_tolerance: float = 0.01
    accept: tuple[str, ...] = ("gradient_tolerance",)
    accept_gradient_norm: float = 0.0


@dataclass(frozen=True)
class OptimaScene:
    """A validated optima scene; ``science`` is hashed, ``execution`` is not."""

    path: str
    name: str
    title: str
    figure: str
    family: str
    anisotropy_ratios: tuple[float, ...]
    max_wavenumbers: tuple[int, ...]
    exponents: tuple[float, ...]
    delta: float
    n_starts: int
    seed: int
    start_scaled_period: float
    optimizer: Optimizer
    keep: Keep
    starts_per_task: int
    execution: Execution
    quick: dict = field(compare=False, repr=False, default_factory=dict)
    science: dict = field(compare=False, repr=False, default_factory=dict)
    text: str = field(default="", compare=False, repr=False)
    kind: str = KIND

    @property
    def hash(self) -> str:
        return scene_hash(self.science)

    @property
    def dims(self) -> tuple[str, ...]:
        return DIMS

    @property
    def shape(self) -> tuple[int, ...]:
        return (len(self.anisotropy_ratios), len(self.max_wavenumbers), len(self.exponents),
                self.n_starts)

    @property
    def n_points(self) -> int:
        """Optimisations in the scene (one per start and cell)."""
        return int(np.prod(self.shape))

    @property
    def n_coefficients(self) -> int:
        return 2 * max(self.max_wavenumbers) + 1

    def start_values(self) -> np.ndarray:
        """(A_0, A_1) of every start, shape (n_starts, 2): uniform on (0, 1), seeded."""
        return np.random.default_rng(self.seed).uniform(0.0, 1.0, size=(self.n_starts, 2))

    def quick_variant(self) -> "OptimaScene":
        """The scene with its ``[quick]`` overrides (``pipeline paper --quick``)."""
        if not self.quick:
            return self
        doc = tomllib.loads(self.text)
        q = doc.pop("quick")
        for key in ("max_wavenumber", "p"):
            if key in q:
                doc["axes"][key] = q[key]
        if "starts" in q:
            doc["starts"]["num"] = q["starts"]
        if "max_iterations" in q:
            doc.setdefault("optimizer", {})["max_iterations"] = q["max_iterations"]
        return _build(ParseContext(f"{self.path} (quick)"), doc, self.text)


_STARTS_KEYS = {"num": "random starts per cell", "seed": "seed of the starts' generator",
                "scaled_period": "starting scaled period"}
_OPTIMIZER_KEYS = {"objective": "efficiency, speed or speed_at_power",
                   "direction": "start (keep the start's sign; default) or negative (minimise, as the paper)",
                   "power": "target mean power of speed_at_power (mu_n mu_s = 1)",
                   "gtol": "gradient-norm tolerance", "max_iterations": "steps per grid round",
                   "grid_rtol": "rtol of the adaptive tau grid", "grid_rounds": "grid re-adaptations",
                   "certify_tolerance": "largest grid_error of a certified optimum",
                   "certify_rounds": "searches on steps 10x, 100x finer where it is exceeded",
                   "fidelity": "coarse stage: grid_rtol x this far from an optimum (1: none)",
                   "fidelity_gtol": "gradient norm that ends the coarse stage"}
_KEEP_KEYS = {"best": "distinct optima kept per cell", "n_tau": "phi samples per period",
              "phi_tolerance": "max |dphi| [rad] of equal optima",
              "period_tolerance": "relative scaled-period difference of equal optima",
              "accept": "stop reasons of the starts eligible",
              "accept_gradient_norm": "also eligible: any stop reason with a final gradient norm below this"}
_EXECUTION_KEYS = {"starts_per_task": "", "scheduler": "", "workers": "", "store": ""}


def parse_optima_scene(doc: dict, ctx: ParseContext, text: str) -> OptimaScene:
    """Validate a parsed TOML ``doc`` of kind "optima" (errors name the key, one line)."""
    return _build(ctx, doc, text)


def _positive(ctx, obj, key, upper=math.inf) -> float:
    v = ctx.number(obj, key)
    if not 0 < v <= upper:
        raise ctx.err(key, f"must be in (0, {upper:g}], got {v:g}")
    return v


def _wavenumbers(ctx, obj, key) -> tuple[int, ...]:
    if not isinstance(obj, list) or not obj:
        raise ctx.err(key, "must be a non-empty array of integers >= 1")
    vals = tuple(ctx.integer(v, f"{key}[{i}]", lo=1) for i, v in enumerate(obj))
    if any(b <= a for a, b in zip(vals, vals[1:])):
        raise ctx.err(key, "must be strictly increasing")
    if vals[-1] > 64:
        raise ctx.err(key, f"Kmax {vals[-1]} is beyond 64 (2 Kmax + 2 parameters per optimisation)")
    return vals


def _build(ctx: ParseContext, doc: dict, text: str) -> OptimaScene:
    ctx.table(doc, "", _TOP_KEYS, required=("scene", "axes", "starts"))
    head = ctx.table(doc["scene"], "scene", {"kind": "", "name": "", "title": "", "figure": "",
                                             "family": ""}, required=("name",))
    name = ctx.string(head["name"], "scene.name")
    if not name.isidentifier():
        raise ctx.err("scene.name", f"must be an identifier, got {name!r}")
    family = ctx.string(head.get("family", "fourier"), "scene.family", ("fourier",))
    axes = ctx.table(doc["axes"], "axes", {"anisotropy_ratio": "", "max_wavenumber": "", "p": ""},
                     required=("anisotropy_ratio", "max_wavenumber"))
    ratios = parse_axis(ctx, "anisotropy_ratio", axes["anisotropy_ratio"], "axes.anisotropy_ratio")
    kmax = _wavenumbers(ctx, axes["max_wavenumber"], "axes.max_wavenumber")
    exponents = (parse_axis(ctx, "p", axes["p"], "axes.p").values if "p" in axes else (0.0,))
    fixed = ctx.table(doc.get("fixed", {}), "fixed", {"delta": ""})
    delta = parse_value(ctx, "delta", fixed.get("delta", 1e-5), "fixed.delta")
    if delta == 0 and min(exponents) == 0:
        raise ctx.err("fixed.delta", "delta = 0 needs p > 0")

    starts = ctx.table(doc["starts"], "starts", _STARTS_KEYS, required=("num",))
    n_starts = ctx.integer(starts["num"], "starts.num", lo=1)
    seed = ctx.integer(starts.get("seed", 0), "starts.seed", lo=0)
    start_period = _positive(ctx, starts.get("scaled_period", 2.0), "starts.scaled_period")

    opt = ctx.table(doc.get("optimizer", {}), "optimizer", _OPTIMIZER_KEYS)
    objective = ctx.string(opt.get("objective", "efficiency"), "optimizer.objective", _OBJECTIVES)
    power = None
    if objective == "speed_at_power":
        if "power" not in opt:
            raise ctx.err("optimizer.power", "missing: speed_at_power needs the target power")
        power = _positive(ctx, opt["power"], "optimizer.power")
    elif "power" in opt:
        raise ctx.err("optimizer.power", "only allowed with objective = \"speed_at_power\"")
    direction = ctx.string(opt.get("direction", "start"), "optimizer.direction",
                           ("negative", "start"))
    optimizer = Optimizer(
        objective=objective, direction=-1 if direction == "negative" else 0, power=power,
        gtol=_positive(ctx, opt.get("gtol", 1e-7), "optimizer.gtol", 1.0),
        max_iterations=ctx.integer(opt.get("max_iterations", 300), "optimizer.max_iterations", lo=1),
        grid_rtol=_positive(ctx, opt.get("grid_rtol", 1e-4), "optimizer.grid_rtol", 0.1),
        grid_rounds=ctx.integer(opt.get("grid_rounds", 3), "optimizer.grid_rounds", lo=1),
        certify_tolerance=_positive(ctx, opt.get("certify_tolerance", 1e-4),
                                    "optimizer.certify_tolerance", 1.0),
        certify_rounds=ctx.integer(opt.get("certify_rounds", 2), "optimizer.certify_rounds", lo=0),
        fidelity=ctx.number(opt.get("fidelity", 1.0), "optimizer.fidelity"),
        fidelity_gtol=_positive(ctx, opt.get("fidelity_gtol", 1e-2), "optimizer.fidelity_gtol", 1.0))
    if not 1.0 <= optimizer.fidelity <= 1e4:
        raise ctx.err("optimizer.fidelity", f"must be in [1, 1e4], got {optimizer.fidelity:g}")

    kp = ctx.table(doc.get("keep", {}), "keep", _KEEP_KEYS)
    accept = ctx.names(kp.get("accept", ["gradient_tolerance"]), "keep.accept",
                       tuple(k for k in STOP_CODES if k != "error"))
    keep = Keep(best=ctx.integer(kp.get("best", 10), "keep.best", lo=1),
                n_tau=ctx.integer(kp.get("n_tau", 128), "keep.n_tau", lo=8),
                phi_tolerance=_positive(ctx, kp.get("phi_tolerance", 0.02), "keep.phi_tolerance"),
                period_tolerance=_positive(ctx, kp.get("period_tolerance", 0.01),
                                           "keep.period_tolerance"),
                accept=accept,
                accept_gradient_norm=ctx.number(kp.get("accept_gradient_norm", 0.0),
                                                "keep.accept_gradient_norm"))
    if not 0 <= keep.accept_gradient_norm < 1:
        raise ctx.err("keep.accept_gradient_norm", f"must be in [0, 1), got {keep.accept_gradient_norm:g}")

    quick = ctx.table(doc.get("quick", {}), "quick", {"max_wavenumber": "", "p": "", "starts": "",
                                                      "max_iterations": ""})
    if "max_wavenumber" in quick:
        _wavenumbers(ctx, quick["max_wavenumber"], "quick.max_wavenumber")
    if "p" in quick:
        parse_axis(ctx, "p", quick["p"], "quick.p")
    if "starts" in quick:
        ctx.integer(quick["starts"], "quick.starts", lo=1)
    if "max_iterations" in quick:
        ctx.integer(quick["max_iterations"], "quick.max_iterations", lo=1)

    ex = ctx.table(doc.get("execution", {}), "execution", _EXECUTION_KEYS)
    per_task = ctx.integer(ex.get("starts_per_task", 4), "execution.starts_per_task", lo=1)
    execution = Execution(
        points_per_task=per_task,
        scheduler=ctx.string(ex.get("scheduler", "processes"), "execution.scheduler",
                             ("processes", "threads", "synchronous")),
        workers=ctx.integer(ex["workers"], "execution.workers", lo=1) if "workers" in ex else None,
        store=ctx.string(ex["store"], "execution.store") if "store" in ex else None)

    science = {
        "kind": KIND, "kind_version": KIND_VERSION, "name": name, "family": family,
        "axes": {"anisotropy_ratio": list(ratios.values), "max_wavenumber": list(kmax),
                 "p": list(exponents)},
        "fixed": {"delta": delta},
        "starts": {"num": n_starts, "seed": seed, "scaled_period": start_period},
        "optimizer": {"objective": objective, "direction": direction, "power": power, "gtol": optimizer.gtol,
                      "max_iterations": optimizer.max_iterations,
                      "grid_rtol": optimizer.grid_rtol, "grid_rounds": optimizer.grid_rounds,
                      "certify_tolerance": optimizer.certify_tolerance,
                      "certify_rounds": optimizer.certify_rounds, "fidelity": optimizer.fidelity,
                      "fidelity_gtol": optimizer.fidelity_gtol},
        "keep": {"best": keep.best, "n_tau": keep.n_tau, "phi_tolerance": keep.phi_tolerance,
                 "period_tolerance": keep.period_tolerance, "accept": list(accept),
                 "accept_gradient_norm": keep.accept_gradient_norm},
        # chunking over starts decides the store layout, so it is part of the hash
        "starts_per_task": per_task,
    }
    return OptimaScene(
        path=ctx.file, name=name, title=ctx.string(head.get("title", ""), "scene.title"),
        figure=ctx.string(head.get("figure", ""), "scene.figure"), family=family,
        anisotropy_ratios=ratios.values, max_wavenumbers=kmax, exponents=tuple(exponents),
        delta=delta, n_starts=n_starts, seed=seed, start_scaled_period=start_period,
        optimizer=optimizer, keep=keep, starts_per_task=per_task, execution=execution,
        quick=dict(quick), science=science, text=text)
