"""Scene kind "optima": ensembles of local optimisations of Fourier motions (section "Optimal motions").

The scene's schema is ``_optima_scene``; this module holds its compute (one optimisation per
start), its store and its reduction.

A scene ``[scene] kind = "optima"`` runs, for every (anisotropy ratio mu_n/mu_s, Kmax, p),
many optimisations of phi(tau) = A_0 + sum_{k <= Kmax} A_k cos 2 pi k tau + B_k sin 2 pi k tau
(eq. Fourier) and the period from random starts as the paper does: A_0 and A_1 uniform on
(0, 1), the other coefficients zero, the starting scaled period fixed.  Start ``i`` is the
same in every cell (one seeded generator), so a store is reproducible and cells compare.

Store (Zarr v3, the conventions of ``_store``: skeleton first, whole chunks, done markers,
lock, provenance, ``format_version``; ``attrs["pipeline"]["kind"] = "optima"``)::

    anisotropy_ratio, max_wavenumber, p, start        coordinates (the scene's dims)
    coefficient                                       0 .. 2 Kmax_largest; names in attrs
    start_A0, start_A1                                (start,) the random starts
    <per start>                                       (ratio, Kmax, p, start), chunked over start
    coefficients                                      (ratio, Kmax, p, start, coefficient)
    optimum_*                                         (ratio, Kmax, p, rank [, coefficient | tau])
    pipeline_state/chunk_done                         one marker per chunk of starts

Coefficients are stored as [A_0, A_1 .. A_Kmax, B_1 .. B_Kmax] of the scene's largest Kmax,
zero beyond the cell's Kmax (the truncated series itself).

Direction.  By default every start keeps the sign of U it starts with and maximises |lambda|
in that basin (``[optimizer] direction = "start"``); the reflection below then brings the
optima with U > 0 to U < 0.  Minimising lambda as the paper did (``direction = "negative"``,
the convention of the shipped optima scenes since issue 28) sends starts that move forwards
through U = 0, and some end at the zero-amplitude stationary point (lambda = 0; not kept, see
below).  Measured on the fourier_optima scene: 6 of 432 starts at 12 per cell, 43 of 1728 at 48
per cell; and at 2^-8, Kmax = 1 the clapping optimum of |lambda| about phi = 0 that 5 of 12
starts reach under "start" is no longer found (one optimum per cell for mu_n/mu_s < 1).

Reduction.  Per cell, the ten (``keep.best``) best *distinct* local optima by |lambda|/lambda_ub,
among the starts whose stop reason is accepted (``keep.accept``, default: gradient norm below
gtol) or whose final gradient norm is below ``keep.accept_gradient_norm`` (default 0: off), and whose
period did not end on its box (``period_at_bound``: T running off to 0 or infinity, the p -> 2
regime, is no interior optimum even with a zero projected gradient), which is certified
(``certified``: its grid_error within ``optimizer.certify_tolerance``, issue 47: an optimum the
frozen steps flatter is the frozen steps', not the engine's; ``solver.OptimizerOptions``), and
whose phi(tau) moves (spans more than ``STILL_AMPLITUDE``: the zero-amplitude stationary point
is no optimum).
Every optimum is first put in the paper's orientation U < 0 by the reflection
phi -> pi - phi (which maps U to -U and keeps P: "reflecting the motions about phi = pi/2
takes U to -U").  Two optima are the same when their scaled periods agree to
``keep.period_tolerance`` (relative) and max_tau |phi_a(tau) - s phi_b(tau + c)| <=
``keep.phi_tolerance`` on ``keep.n_tau`` uniform samples for some cyclic shift c and s = +-1:
the phase of a periodic motion is arbitrary (B_1 = 0 fixes it only up to c = 1/2), and phi
and -phi are the same body (the halves are reflections of each other in the x axis; the
paper's clapping motions).  Time reversal tau -> -tau is *not* a symmetry: inertia and
dissipation break it (lambda changes), so time-reversed motions are distinct optima.
"""

from __future__ import annotations

import sys
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ._kind import RunContext, SceneKind, Step, tasks_by_count
from ._optima_scene import DIMS, KIND, KIND_VERSION, STOP_CODES, OptimaScene, parse_optima_scene
from ._store import (ChunkWrite, SolvedChunk, create_array, finish_skeleton, new_group, read_arrays,
                     write_arrays)

__all__ = ["OPTIMA", "OptimaKind", "distinct_optima", "fourier_samples", "STOP_CODES", "KIND_VERSION",
           "create_optima_skeleton", "reduce_optima", "accepted_starts",
           "reflect_about_half_pi", "START_FLAGS"]

#: starts one task aims at (``OptimaKind.chunks_per_task``)
TASK_STARTS = 16
NOT_COMPUTED = -1
#: per-start float arrays and their descriptions (mu_n mu_s = 1: scaled = unscaled)
START_FLOATS = {
    "scaled_period": "scaled period (mu_n mu_s)^(1/(4-2p)) T at the optimum",
    "objective": "the optimised objective at the optimum (lambda, U, or U at fixed P), signed; "
                 "by the engine at rtol 1e-8, as U, P, efficiency",
    "U": "time-averaged speed U (eq. U) at mu_n mu_s = 1, signed",
    "P": "time-averaged power P (eq. powerp) at mu_n mu_s = 1",
    "efficiency": "lambda = sign(U)|U|^(p+1)/P (eq. lambdap) at mu_n mu_s = 1",
    "relative_efficiency": "lambda/lambda_ub, lambda_ub = 1/min(mu_n, mu_s) (eq. relefficiency); signed",
    "grid_efficiency": "lambda on the optimiser's final fixed grid (what the search maximised)",
    "grid_error": "|objective on the fixed grid - the engine's| / |the engine's|: the fixed grid's "
                  "discretisation error at the optimum",
    "gradient_norm": "projected gradient norm at the end (variables: coefficients, log T)",
    "condition_number": "condition number of the last difference Hessian (nan if none)",
    "seconds": "wall time of the optimisation [s]",
    "cpu_seconds": "CPU time of the optimisation (its thread), the per-start cost compared by "
                   "compare_optima [s]",
}
START_INTS = {
    "iterations": "accepted optimiser steps (all grid rounds)",
    "gradient_evaluations": "adjoint gradient evaluations",
    "solves": "periodic solves of the search (line-search trials and gradients' solves)",
    "coarse_iterations": "accepted steps of the coarse stage (optimizer.fidelity; 0 without one)",
    "certify_rounds": "searches on finer steps that certification took (0: none was needed)",
    "n_steps": "steps of the final fixed tau grid",
}
#: per-start flags (int8; -1 not computed)
START_FLAGS = {
    "certified": "1: grid_error <= optimizer.certify_tolerance (the frozen steps' optimum is the "
                 "engine's to that tolerance; below STILL_EFFICIENCY lambda_ub measured against "
                 "that floor); only certified starts are kept; 0: not",
    "at_rest": "1: phi(tau) spans no more than STILL_AMPLITUDE (the zero-amplitude stationary "
               "point, no optimum); 0: a motion",
}


# ---------------------------------------------------------------------------------------------
# phi samples and the distinct-optima reduction (pure numpy)


def coefficient_names(k_largest: int) -> list[str]:
    return [f"A{k}" for k in range(k_largest + 1)] + [f"B{k}" for k in range(1, k_largest + 1)]


def fourier_samples(coefficients: np.ndarray, n_tau: int) -> np.ndarray:
    """phi(tau_j), tau_j = j / n_tau, of series stored as [A_0, A_1..A_K, B_1..B_K] (eq. Fourier).

    coefficients : ndarray, shape (..., 2K + 1)  [rad]
    Returns ndarray, shape (..., n_tau)  [rad]
    """
    c = np.asarray(coefficients, dtype=np.float64)
    K = (c.shape[-1] - 1) // 2
    tau = np.arange(n_tau) / n_tau
    k = np.arange(1, K + 1)
    cos = np.cos(2 * np.pi * np.outer(k, tau))
    sin = np.sin(2 * np.pi * np.outer(k, tau))
    return c[..., :1] + c[..., 1:K + 1] @ cos + c[..., K + 1:] @ sin


def reflect_about_half_pi(coefficients: np.ndarray) -> np.ndarray:
    """The series of pi - phi (maps U to -U at the same P)."""
    out = -np.asarray(coefficients, dtype=np.float64)
    out[..., 0] += np.pi
    return out


def _symmetric_copies(phi: np.ndarray) -> np.ndarray:
    """Every cyclic shift of phi and of -phi, shape (2 n_tau, n_tau)."""
    n = phi.size
    index = (np.arange(n)[:, None] + np.arange(n)[None, :]) % n
    shifted = phi[index]
    return np.concatenate([shifted, -shifted])


@dataclass(frozen=True)
class DistinctOptima:
    """Indices of the kept optima (best first) and how many eligible starts each stands for."""

    index: np.ndarray
    multiplicity: np.ndarray


def distinct_optima(phi: np.ndarray, period: np.ndarray, score: np.ndarray, *, best: int,
                    phi_tolerance: float, period_tolerance: float) -> DistinctOptima:
    """The ``best`` highest-``score`` optima that are pairwise distinct (greedy, best first).

    Parameters
    ----------
    phi : ndarray, shape (n, n_tau)
        Samples of each optimum in the common orientation (U < 0) [rad].
    period : ndarray, shape (n,)
        Scaled periods.
    score : ndarray, shape (n,)
        |lambda|/lambda_ub; NaN entries are not eligible.
    best : int
    phi_tolerance, period_tolerance : float
        Two optima are equal when their periods agree to ``period_tolerance`` (relative) and
        max |phi_a - s phi_b(. + c)| <= phi_tolerance for some cyclic shift c and s = +-1.

    Returns
    -------
    DistinctOptima
        ``index`` into the inputs, ``multiplicity``: eligible optima equal to each kept one
        (each counted once, with the first kept optimum it equals).
    """
    eligible = np.flatnonzero(np.isfinite(score))
    order = eligible[np.argsort(-score[eligible], kind="stable")]
    kept: list[int] = []
    copies: list[np.ndarray] = []
    multiplicity: list[int] = []
    for i in order:
        match = -1
        for j, (k, c) in enumerate(zip(kept, copies)):
            if abs(period[i] - period[k]) > period_tolerance * max(period[i], period[k]):
                continue
            if np.min(np.max(np.abs(c - phi[i]), axis=1)) <= phi_tolerance:
                match = j
                break
        if match >= 0:
            multiplicity[match] += 1
        elif len(kept) < best:
            kept.append(int(i))
            copies.append(_symmetric_copies(phi[i]))
            multiplicity.append(1)
    return DistinctOptima(np.asarray(kept, dtype=np.int64), np.asarray(multiplicity, dtype=np.int64))


# ---------------------------------------------------------------------------------------------
# the store


def _start_chunks(scene: OptimaScene) -> tuple[int, ...]:
    return (1, 1, 1, min(scene.starts_per_task, scene.n_starts))


def status_meanings() -> dict[str, str]:
    from solver.adjoint.optimize import STOP_REASONS

    reasons = {**STOP_REASONS, "error": "the optimiser raised (e.g. no periodic solution at the start)"}
    out = {str(NOT_COMPUTED): "not computed yet"}
    out.update({str(code): f"{name}: {reasons[name]}" for name, code in STOP_CODES.items()})
    return out


def reduction_specs(scene: OptimaScene) -> dict[str, tuple]:
    """{array: (dims, dtype, fill, long name)} of the reduction (the kept optima)."""
    cell = DIMS[:3] + ("rank",)
    f8, i4 = np.dtype(np.float64), np.dtype(np.int32)
    return {
        "optimum_start": (cell, i4, -1, "start index of the kept optimum (-1: fewer distinct optima)"),
        "optimum_multiplicity": (cell, i4, 0, "eligible starts equal to this optimum (symmetries)"),
        "optimum_relative_efficiency": (cell, f8, np.nan, "|lambda|/lambda_ub (eq. relefficiency)"),
        "optimum_efficiency": (cell, f8, np.nan, "lambda at mu_n mu_s = 1, orientation U < 0"),
        "optimum_scaled_period": (cell, f8, np.nan, "scaled period (mu_n mu_s)^(1/(4-2p)) T"),
        "optimum_coefficients": (cell + ("coefficient",), f8, np.nan,
                                 "[A_0, A_k, B_k] in the orientation U < 0 (phi -> pi - phi "
                                 "applied where U > 0) [rad]"),
        "optimum_phi": (cell + ("tau",), f8, np.nan,
                        "phi(tau) of the kept optimum at tau = j/n_tau, orientation U < 0 [rad]"),
    }


def _units(long_name: str) -> str:
    """CF units of a float array from its long name: "s" (wall times) and "rad" (angles) where
    it ends so ("[s]", "[rad]"), else "1" (the paper's nondimensional quantities)."""
    return "s" if long_name.endswith("[s]") else "rad" if long_name.endswith("[rad]") else "1"


def create_optima_skeleton(store: Path, scene: OptimaScene) -> None:
    """Every array, coordinate and attribute, before any task runs (``_store`` conventions)."""
    g = new_group(store)
    n_r, n_k, n_p, n_s = scene.shape
    n_c = scene.n_coefficients
    coords = {
        "anisotropy_ratio": (np.asarray(scene.anisotropy_ratios), np.float64,
                             {"long_name": "friction anisotropy ratio mu_n/mu_s", "units": "1",
                              "spacing": "log2"}),
        "max_wavenumber": (np.asarray(scene.max_wavenumbers), np.int32,
                           {"long_name": "Kmax: highest wavenumber of the series (eq. Fourier)"}),
        "p": (np.asarray(scene.exponents), np.float64,
              {"long_name": "exponent p of the resistive force law (eq. frictionp)", "units": "1"}),
        "start": (np.arange(n_s), np.int32, {"long_name": "index of the random start"}),
        "coefficient": (np.arange(n_c), np.int32,
                        {"long_name": "index into [A_0, A_1..A_K, B_1..B_K]",
                         "names": coefficient_names(max(scene.max_wavenumbers))}),
        "rank": (np.arange(scene.keep.best), np.int32,
                 {"long_name": "rank of a kept distinct optimum (0: best)"}),
        "tau": (np.arange(scene.keep.n_tau) / scene.keep.n_tau, np.float64,
                {"long_name": "scaled time tau = t/T", "units": "1"}),
    }
    for name, (values, dtype, attrs) in coords.items():
        create_array(g, name, shape=values.shape, chunks=values.shape, dtype=dtype, fill=0,
                     dims=(name,), attrs=attrs)[:] = values
    starts = scene.start_values()
    for j, name in enumerate(("start_A0", "start_A1")):
        create_array(g, name, shape=(n_s,), chunks=(n_s,), dtype=np.float64, fill=np.nan,
                     dims=("start",), attrs={"long_name": f"A_{j} of the start, uniform on (0, 1) [rad]",
                                             "units": "rad"}
                     )[:] = starts[:, j]
    chunks = _start_chunks(scene)
    create_array(g, "status", shape=scene.shape, chunks=chunks, dtype=np.int8, fill=NOT_COMPUTED,
                 dims=DIMS, attrs={"long_name": "optimiser stop reason", "flag_meanings": status_meanings()})
    create_array(g, "period_at_bound", shape=scene.shape, chunks=chunks, dtype=np.int8,
                 fill=NOT_COMPUTED, dims=DIMS,
                 attrs={"long_name": "1: the period ended at its box (1e-3 .. 1e4 x the start's): no "
                                     "interior optimum (T runs off, as p -> 2); never kept; -1 not computed"})
    create_array(g, "ill_conditioned", shape=scene.shape, chunks=chunks, dtype=np.int8,
                 fill=NOT_COMPUTED, dims=DIMS,
                 attrs={"long_name": "1: ill-conditioned (Hessian condition above threshold, or the period "
                                     "at its bound: p near 2); 0: no; -1 not computed"})
    for name, text_ in START_FLAGS.items():
        create_array(g, name, shape=scene.shape, chunks=chunks, dtype=np.int8, fill=NOT_COMPUTED,
                     dims=DIMS, attrs={"long_name": text_})
    for name, text_ in START_FLOATS.items():
        create_array(g, name, shape=scene.shape, chunks=chunks, dtype=np.float64, fill=np.nan,
                     dims=DIMS, attrs={"long_name": text_, "units": _units(text_)})
    for name, text_ in START_INTS.items():
        create_array(g, name, shape=scene.shape, chunks=chunks, dtype=np.int32, fill=0, dims=DIMS,
                     attrs={"long_name": text_})
    create_array(g, "coefficients", shape=scene.shape + (n_c,), chunks=chunks + (n_c,),
                 dtype=np.float64, fill=np.nan, dims=DIMS + ("coefficient",),
                 attrs={"long_name": "optimal [A_0, A_k, B_k] as found (zero beyond the cell's Kmax) [rad]",
                        "units": "rad"})
    sizes = {"anisotropy_ratio": n_r, "max_wavenumber": n_k, "p": n_p, "rank": scene.keep.best,
             "coefficient": n_c, "tau": scene.keep.n_tau}
    for name, (dims, dtype, fill, long_name) in reduction_specs(scene).items():
        shape = tuple(sizes[d] for d in dims)
        units = {"units": _units(long_name)} if dtype.kind == "f" else {}
        create_array(g, name, shape=shape, chunks=shape, dtype=dtype, fill=fill, dims=dims,
                     attrs={"long_name": long_name, **units, "reduction": "distinct_optima"})
    finish_skeleton(g, scene, store=store, dims=DIMS, shape=scene.shape, chunks=chunks,
                    head={"kind": KIND, "kind_version": KIND_VERSION}, reductions_complete=False)


# ---------------------------------------------------------------------------------------------
# one task: a chunk of starts of one cell


def optimize_start(scene: OptimaScene, ratio: float, kmax: int, p: float, a0: float,
                   a1: float) -> dict:
    """One optimisation from the start (A_0, A_1) = (a0, a1); a record of the store's fields."""
    import solver

    physics = solver.Physics.from_scaled(ratio, scene.start_scaled_period, p=p, delta=scene.delta)
    A = np.zeros((1, kmax + 1))
    A[0, :2] = a0, a1
    template = solver.Fourier(A, np.zeros((1, kmax)))
    opt = scene.optimizer
    t0, c0 = time.perf_counter(), time.thread_time()
    try:
        res = solver.optimize_motion(template, physics, objective=opt.objective, power=opt.power,
                              direction=opt.direction or None,
                              gtol=opt.gtol, max_iterations=opt.max_iterations,
                              grid_rtol=opt.grid_rtol, grid_rounds=opt.grid_rounds,
                              certify_tolerance=opt.certify_tolerance,
                              certify_rounds=opt.certify_rounds,
                              certify_floor=STILL_EFFICIENCY / min(float(physics.mu_n[0]),
                                                                   float(physics.mu_s[0])),
                              certify_gradient_norm=max(opt.gtol, scene.keep.accept_gradient_norm),
                              fidelity=opt.fidelity,
                              fidelity_gtol=opt.fidelity_gtol)
    except (RuntimeError, ValueError, FloatingPointError, ZeroDivisionError) as exc:
        print(f"optima: ratio {ratio:g} Kmax {kmax} p {p:g} start ({a0:.4f}, {a1:.4f}): "
              f"{type(exc).__name__}: {exc}", file=sys.stderr)
        return {"status": STOP_CODES["error"], "seconds": time.perf_counter() - t0,
                "cpu_seconds": time.thread_time() - c0}
    lam_ub = 1.0 / min(float(physics.mu_n[0]), float(physics.mu_s[0]))
    full = np.zeros(scene.n_coefficients)
    k_largest = max(scene.max_wavenumbers)
    full[:kmax + 1] = res.parameters[:kmax + 1]
    full[k_largest + 1:k_largest + 1 + kmax] = res.parameters[kmax + 1:2 * kmax + 1]
    T = float(res.parameters[-1])
    scaled_period = float(solver.scaled_from_physical(T, physics.mu_n[0], physics.mu_s[0], p)[1])
    return {
        "status": STOP_CODES[res.stop_reason], "ill_conditioned": int(res.ill_conditioned),
        "period_at_bound": int("period" in res.at_bounds),
        # the motion's outputs by the engine: the fixed grid's (grid_efficiency) can be off by
        # far more than its rtol where the search exploited its error (issue 35: 15 % of the
        # fourier_optima starts by more than 1e-3, 5 % by more than 1e-2)
        "scaled_period": scaled_period, "objective": res.engine_value, "U": res.engine_U,
        "P": res.engine_P, "efficiency": res.engine_efficiency,
        "relative_efficiency": res.engine_efficiency / lam_ub,
        "grid_efficiency": res.efficiency, "grid_error": res.grid_error,
        "gradient_norm": res.gradient_norm, "condition_number": res.condition_number,
        "seconds": time.perf_counter() - t0, "cpu_seconds": time.thread_time() - c0,
        "iterations": res.iterations, "gradient_evaluations": res.gradient_evaluations,
        "solves": res.solves, "coarse_iterations": res.coarse_iterations,
        "certify_rounds": res.certify_rounds, "n_steps": res.n_steps,
        "certified": int(res.certified),
        "at_rest": int(np.ptp(fourier_samples(full, scene.keep.n_tau)) <= STILL_AMPLITUDE),
        "coefficients": full,
    }


def solve_optima_chunk(scene: OptimaScene, chunks: tuple[int, ...], index: tuple[int, ...]) -> SolvedChunk:
    """Optimise every start of chunk ``index`` (one cell, ``starts_per_task`` starts); its arrays,
    unwritten.  ``chunks`` is the store's layout, (1, 1, 1, starts per task)."""
    i_r, i_k, i_p, i_c = index
    c = scene.starts_per_task
    first, last = i_c * c, min((i_c + 1) * c, scene.n_starts)
    starts = scene.start_values()[first:last]
    ratio, kmax, p = (scene.anisotropy_ratios[i_r], scene.max_wavenumbers[i_k],
                      scene.exponents[i_p])
    records = [optimize_start(scene, ratio, kmax, p, a0, a1) for a0, a1 in starts]
    n = len(records)
    values = {"status": np.array([r["status"] for r in records], dtype=np.int8),
              "ill_conditioned": np.array([r.get("ill_conditioned", 0) for r in records],
                                          dtype=np.int8),
              "period_at_bound": np.array([r.get("period_at_bound", 0) for r in records],
                                          dtype=np.int8)}
    for name in START_FLAGS:
        values[name] = np.array([r.get(name, 0) for r in records], dtype=np.int8)
    for name in START_FLOATS:
        values[name] = np.array([r.get(name, np.nan) for r in records], dtype=np.float64)
    for name in START_INTS:
        values[name] = np.array([r.get(name, 0) for r in records], dtype=np.int32)
    shape4 = (1, 1, 1, n)
    values = {k: v.reshape(shape4) for k, v in values.items()}
    region = (slice(i_r, i_r + 1), slice(i_k, i_k + 1), slice(i_p, i_p + 1), slice(first, last))
    chunks = tuple(chunks)
    n_c = scene.n_coefficients
    coefficients = np.array([r.get("coefficients", np.full(n_c, np.nan)) for r in records])
    writes = (ChunkWrite(region, tuple(index), chunks, scene.shape, values),
              ChunkWrite(region + (slice(0, n_c),), tuple(index) + (0,), chunks + (n_c,), scene.shape + (n_c,),
                         {"coefficients": coefficients.reshape(shape4 + (n_c,))}))
    return SolvedChunk(writes=writes, points=n,
                       failures=int(np.count_nonzero(values["status"] == STOP_CODES["error"])),
                       seconds=float(np.nansum(values["seconds"])))


# ---------------------------------------------------------------------------------------------
# the reduction over a whole store


def accepted_starts(scene: OptimaScene, data: dict[str, np.ndarray]) -> np.ndarray:
    """The starts whose end may be an optimum, bool of the per-start shape: the stop reason
    accepted (``keep.accept``) or the gradient norm below ``keep.accept_gradient_norm``, the
    period not at its box, and certified (where the store has ``certified``).  The reduction
    further drops starts at rest and without a finite efficiency."""
    accepted = np.isin(data["status"], [STOP_CODES[a] for a in scene.keep.accept])
    # converged to the objective's noise: gtol 1e-7 can lie below the rounding level of lambda
    # at stiff cells, where the search ends "no_progress" or "ill_conditioned" at the optimum
    accepted |= (data["status"] >= 0) & (data["status"] != STOP_CODES["error"]) & (
        data["gradient_norm"] <= scene.keep.accept_gradient_norm)
    if "period_at_bound" in data:  # a zero projected gradient with T on its box: not an optimum
        accepted &= data["period_at_bound"] != 1
    if "certified" in data:  # the frozen steps' optimum, not the engine's (issue 47): not kept
        accepted &= data["certified"] == 1
    return accepted


def reduce_optima(scene: OptimaScene, data: dict[str, np.ndarray]) -> dict[str, np.ndarray]:
    """The kept distinct optima of every cell from the per-start arrays ``data`` (whole store)."""
    specs = reduction_specs(scene)
    n_r, n_k, n_p, _ = scene.shape
    sizes = {"anisotropy_ratio": n_r, "max_wavenumber": n_k, "p": n_p, "rank": scene.keep.best,
             "coefficient": scene.n_coefficients, "tau": scene.keep.n_tau}
    out = {name: np.full(tuple(sizes[d] for d in dims), fill, dtype=dtype)
           for name, (dims, dtype, fill, _) in specs.items()}
    accepted = accepted_starts(scene, data)
    keep = scene.keep
    for cell in np.ndindex(n_r, n_k, n_p):
        ok = accepted[cell] & np.isfinite(data["relative_efficiency"][cell])
        coefficients = data["coefficients"][cell].copy()
        forward = data["U"][cell] > 0
        coefficients[forward] = reflect_about_half_pi(coefficients[forward])
        phi = fourier_samples(coefficients, keep.n_tau)
        # a start that ends at the zero-amplitude stationary point (phi constant, no motion,
        # lambda = 0) found no optimum: under the paper's convention starts that move forwards
        # descend to it (issue 28, 48 starts: 43 of 1728 fourier_optima starts, 16 of them
        # accepted, amplitudes 3e-5 .. 2e-4 rad, each kept as a "distinct optimum" at its own
        # constant phi; the smallest amplitude of a kept optimum with lambda != 0 is 0.04 rad)
        ok &= np.ptp(phi, axis=1) > STILL_AMPLITUDE
        score = np.where(ok, np.abs(data["relative_efficiency"][cell]), np.nan)
        found = distinct_optima(phi, data["scaled_period"][cell], score, best=keep.best,
                                phi_tolerance=keep.phi_tolerance,
                                period_tolerance=keep.period_tolerance)
        m = found.index.size
        out["optimum_start"][cell][:m] = found.index
        out["optimum_multiplicity"][cell][:m] = found.multiplicity
        out["optimum_relative_efficiency"][cell][:m] = score[found.index]
        out["optimum_efficiency"][cell][:m] = -np.abs(data["efficiency"][cell][found.index])
        out["optimum_scaled_period"][cell][:m] = data["scaled_period"][cell][found.index]
        out["optimum_coefficients"][cell][:m] = coefficients[found.index]
        out["optimum_phi"][cell][:m] = phi[found.index]
    return out


#: phi(tau) spanning no more than this [rad] is a body at rest, not an optimal motion
STILL_AMPLITUDE = 1e-3
#: |lambda|/lambda_ub below this is no motion (``compare_optima.STILL``: isotropic friction at
#: p >= 1 gives 1e-35 .. 1e-8): certification measures the grid error against this floor
#: there, as a relative error of a value at rounding level certifies nothing
STILL_EFFICIENCY = 1e-6

PER_START = ("status", "U", "efficiency", "relative_efficiency", "scaled_period", "gradient_norm",
             "period_at_bound", "certified", "coefficients")


# ---------------------------------------------------------------------------------------------
# the kind


def reduce_step(run: RunContext) -> None:
    """The kept distinct optima of every cell, in the driver (numpy, seconds)."""
    write_arrays(run.store, reduce_optima(run.scene, read_arrays(run.store, PER_START)))


class OptimaKind(SceneKind):
    """Ensembles of optimisations: chunks of starts of one cell, then the distinct optima."""

    names = (KIND,)
    rate_unit = "optimisations/s"
    solve_chunk = staticmethod(solve_optima_chunk)

    def parse(self, doc, ctx, text):
        return parse_optima_scene(doc, ctx, text)

    def create_skeleton(self, run: RunContext) -> None:
        create_optima_skeleton(run.store, run.scene)

    def chunks_per_task(self, run: RunContext, chunks: tuple[int, ...], pending: list) -> int:
        """Chunks of about ``TASK_STARTS`` starts per task, but at least
        ``_kind.TASKS_PER_WORKER`` tasks per worker (``_kind.tasks_by_count``): fourier_optima's
        432 chunks of 4 starts go 4 to a task on 2 workers (a task writes each chunk while it
        optimises the next), 1 on 16.  The grouping moves no chunk boundary."""
        return tasks_by_count(chunks[-1], TASK_STARTS, len(pending), run.n_workers)

    def chunk_cost(self, scene, index: tuple[int, ...]) -> float:
        """An optimisation's cost grows with Kmax (2 Kmax + 2 variables, a difference Hessian
        of as many gradients): the chunks of the largest Kmax run first, so that no long task
        starts last (per-start times in docs/validation.md, "Pipeline at scale")."""
        return float(scene.max_wavenumbers[index[1]])

    def steps(self, scene) -> tuple[Step, ...]:
        return (Step("reductions", "reductions_complete", reduce_step),)

    def failures(self, store: Path, scene) -> int:
        """Optimisations that raised (stop reason "error"); other stops are outcomes."""
        return int(np.count_nonzero(read_arrays(store, ["status"])["status"] == STOP_CODES["error"]))

    def kernel_sets(self, scene) -> tuple[str, ...]:
        return ("periodic", "gradient")


OPTIMA = OptimaKind()
