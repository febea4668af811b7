"""Running study scenes (accuracy, stiffness) into resumable Zarr stores.

Store layout (Zarr format 3, same conventions as grid stores: skeleton first, whole chunks per
task, ``pipeline_state/chunk_done`` markers, the ``pipeline`` attributes written by the driver
only; ``pipeline.kind`` names the study kind)::

    point, method, rtol [, n_steps, baseline_tol]       coordinates (method: labels in attrs)
    motion, scan, scan_value, <parameters>, period,     per point, written with the skeleton
      kinematic_speed, phi_min, phi_max
    U_ref, P_ref, ref_*, check_*                       (point,) fine reference and its cross-check
    status, U, P, error_estimate, iterations, n_tau,   (point, method, rtol) one timed solve each
      seconds, error_U, error_P, true_error
      [used_method, U_used, P_used, true_error_used]   stiffness: the answer kept (fallback)
    fixed_*                                            accuracy: (point, method, n_steps) fixed grids
    baseline_*                                         accuracy: (point, baseline_tol) scipy LSODA

Errors are in the solver's own norm (``solver.solve``): for U, |U - U_ref| T / max(|U_ref| T,
1e-3 V) (``solver.tools.bench.relative_u_error``); for P, |P - P_ref| / |P_ref|; ``true_error`` is the
larger, the quantity ``error_estimate`` claims to bound by rtol.
"""

from __future__ import annotations

import math
import time
from pathlib import Path

import numpy as np

from ._kind import RunContext, SceneKind
from ._store import (NOT_COMPUTED, ChunkWrite, SolvedChunk, create_array, finish_skeleton, new_group, read_arrays,
                     status_meanings)
from ._study_scene import STUDY_KINDS, StudyScene, parse_study_scene

__all__ = ["STUDY", "StudyKind", "create_study_skeleton", "result_dims", "study_arrays",
           "solver_norm_errors", "NOT_APPLICABLE", "CHECK_MARCH", "CHECK_FIXED", "NO_ANSWER"]

#: Baseline status of a point the LSODA baseline does not cover (it takes harmonic motions only).
NOT_APPLICABLE = -2
#: ``baseline_status`` 1: LSODA failed or hit its wall-time cap.
BASELINE_FAILED = 1
CHECK_MARCH, CHECK_FIXED = 0, 1
#: ``used_method`` when no method (nor the fallback) converged.
NO_ANSWER = -1
#: Timing of one solve: the fastest of up to 3 calls while they take under 0.5 s in total.
TIMING_REPEATS = 3
TIMING_BUDGET = 0.5


# ---------------------------------------------------------------------------
# Array specification
# ---------------------------------------------------------------------------


def result_dims(scene: StudyScene) -> dict[str, int]:
    """Sizes of the dimensions of the result arrays (point, method, rtol and the accuracy study's
    n_steps, baseline_tol)."""
    d = {"point": scene.n_points, "method": len(scene.methods), "rtol": len(scene.rtols)}
    if scene.kind == "accuracy":
        if scene.fixed_steps:
            d["n_steps"] = len(scene.fixed_steps)
        if scene.baseline_tolerances:
            d["baseline_tol"] = len(scene.baseline_tolerances)
    return d


def study_arrays(scene: StudyScene) -> dict[str, tuple[tuple[str, ...], np.dtype, object, dict]]:
    """{name: (dims, dtype, fill, attrs)} of every array a task writes."""
    f8, i8, i4 = np.dtype(np.float64), np.dtype(np.int8), np.dtype(np.int32)
    meanings = status_meanings()
    sol = ("point", "method", "rtol")
    one = ("point",)
    nan = math.nan
    err_u = "error of U in the solver norm |U - U_ref| T / max(|U_ref| T, 1e-3 V)"
    err_p = "relative error of P, |P - P_ref| / P_ref"
    out = {
        "U_ref": (one, f8, nan, {"long_name": "reference mean speed U (eq. U), periodic at the reference rtol"}),
        "P_ref": (one, f8, nan, {"long_name": "reference mean power P (eq. power)"}),
        "ref_status": (one, i8, NOT_COMPUTED, {"long_name": "solver status of the reference",
                                               "flag_meanings": meanings}),
        "ref_error_estimate": (one, f8, nan, {"long_name": "error estimate of the reference"}),
        "ref_n_tau": (one, i4, 0, {"long_name": "steps per period of the reference's final grid"}),
        "ref_seconds": (one, f8, nan, {"long_name": "wall time of the reference solve", "units": "s"}),
        "check_U": (one, f8, nan, {"long_name": "U of the independent cross-check of the reference"}),
        "check_P": (one, f8, nan, {"long_name": "P of the cross-check"}),
        "check_status": (one, i8, NOT_COMPUTED, {"long_name": "solver status of the cross-check",
                                                 "flag_meanings": meanings}),
        "check_method": (one, i8, NOT_COMPUTED, {"long_name": "cross-check used",
                                                 "labels": ["march (adaptive)", "periodic on a fixed uniform grid"]}),
        "check_difference": (one, f8, nan, {"long_name": "reference minus cross-check, solver norm (max of U, P): "
                                                          "the uncertainty of the reference"}),
        "status": (sol, i8, NOT_COMPUTED, {"long_name": "solver status", "flag_meanings": meanings}),
        "U": (sol, f8, nan, {"long_name": "mean speed U (eq. U), NaN on failure"}),
        "P": (sol, f8, nan, {"long_name": "mean power P (eq. power), NaN on failure"}),
        "error_estimate": (sol, f8, nan, {"long_name": "solver error estimate (claims true_error <= rtol)"}),
        "iterations": (sol, i4, 0, {"long_name": "shooting iterations (periodic) or periods marched (march)"}),
        "n_tau": (sol, i4, 0, {"long_name": "steps per period of the final grid"}),
        "seconds": (sol, f8, nan, {"long_name": "wall time of this single-point solve (after JIT warm-up; one "
                                               "numba thread; fastest of up to 3 calls within 0.5 s; shared machine)",
                                   "units": "s"}),
        "error_U": (sol, f8, nan, {"long_name": err_u}),
        "error_P": (sol, f8, nan, {"long_name": err_p}),
        "true_error": (sol, f8, nan, {"long_name": "max(error_U, error_P): the true error in the solver norm"}),
    }
    if scene.kind == "stiffness":
        out.update({
            "used_method": (sol, i8, NOT_COMPUTED, {
                "long_name": f"method whose answer is kept (fallback {scene.fallback!r}); -1 none converged",
                "labels": list(scene.methods)}),
            "U_used": (sol, f8, nan, {"long_name": "U kept after the fallback"}),
            "P_used": (sol, f8, nan, {"long_name": "P kept after the fallback"}),
            "true_error_used": (sol, f8, nan, {"long_name": "true error of the kept answer"}),
        })
    dims = result_dims(scene)
    if "n_steps" in dims:
        fx = ("point", "method", "n_steps")
        out.update({
            "fixed_status": (fx, i8, NOT_COMPUTED, {"long_name": "status on a fixed uniform grid",
                                                    "flag_meanings": meanings}),
            "fixed_U": (fx, f8, nan, {"long_name": "U on a fixed grid (solve_fixed_grid)"}),
            "fixed_P": (fx, f8, nan, {"long_name": "P on a fixed grid"}),
            "fixed_seconds": (fx, f8, nan, {"long_name": "wall time of the fixed-grid solve", "units": "s"}),
            "fixed_error_U": (fx, f8, nan, {"long_name": err_u}),
            "fixed_error_P": (fx, f8, nan, {"long_name": err_p}),
        })
    if "baseline_tol" in dims:
        bl = ("point", "baseline_tol")
        out.update({
            "baseline_status": (bl, i8, NOT_COMPUTED, {
                "long_name": "scipy LSODA baseline (solver.tools.bench): 0 periodic reached, 1 failed or over the cap, "
                             "-2 not applicable (the baseline takes harmonic motions only)"}),
            "baseline_U": (bl, f8, nan, {"long_name": "U of the LSODA baseline"}),
            "baseline_P": (bl, f8, nan, {"long_name": "P of the LSODA baseline"}),
            "baseline_seconds": (bl, f8, nan, {"long_name": "wall time of the baseline (serial)", "units": "s"}),
            "baseline_periods": (bl, i4, 0, {"long_name": "periods marched by the baseline"}),
            "baseline_error_U": (bl, f8, nan, {"long_name": err_u}),
            "baseline_error_P": (bl, f8, nan, {"long_name": err_p}),
        })
    for _, dtype, _, attrs in out.values():
        _nondimensional(dtype, attrs)
    return out


def _nondimensional(dtype, attrs: dict) -> dict:
    """``attrs`` with ``units`` "1" added where a float array names none: a study's quantities
    are the paper's nondimensional ones (lengths in link lengths, mu_n mu_s = 1; every scanned
    parameter is dimensionless) except those that say otherwise ("s", "rad")."""
    if np.dtype(dtype).kind == "f":
        attrs.setdefault("units", "1")
    return attrs


def point_parameters(scene: StudyScene) -> dict[str, tuple[np.ndarray, dict]]:
    """Per-point parameter arrays written with the skeleton: {name: (values, attrs)}."""
    import solver

    pts = scene.points
    n = len(pts)

    def shape_value(key, default=math.nan):
        return np.array([dict(p.case.shape).get(key, default) for p in pts], dtype=np.float64)

    phi_min, phi_max, vscale, period = (np.full(n, np.nan) for _ in range(4))
    tau = np.linspace(0.0, 1.0, 2001)
    for i, p in enumerate(pts):
        kin, phys = p.case.kinematics(), p.case.physics()
        phi = kin.angle(tau)[0]
        phi_min[i], phi_max[i] = phi.min(), phi.max()
        vscale[i] = solver.kinematic_speed(kin)[0]
        period[i] = phys.period[0]
    a0 = shape_value("A0")
    for i, p in enumerate(pts):
        if p.case.family == "fourier":
            a0[i] = p.case.value("A")[0]
    families = ["harmonic", "powerlaw", "fourier"]
    out = {
        "motion": (np.array([p.motion for p in pts], dtype=np.int32),
                   {"long_name": "motion (case) index", "labels": [m.name for m in scene.motions]}),
        "scan": (np.array([p.scan for p in pts], dtype=np.int32),
                 {"long_name": "scan index (-1: none)", "labels": [s.parameter for s in scene.scans]}),
        "scan_value": (np.array([p.scan_value for p in pts]), {"long_name": "value of the scanned parameter"}),
        "family": (np.array([families.index(p.case.family) for p in pts], dtype=np.int32),
                   {"long_name": "kinematic family", "labels": families}),
        "anisotropy_ratio": (np.array([p.case.anisotropy_ratio for p in pts]), {"long_name": "mu_n/mu_s"}),
        "scaled_period": (np.array([p.case.scaled_period for p in pts]),
                          {"long_name": "scaled period (mu_n mu_s)^(1/(4-2p)) T"}),
        "p": (np.array([p.case.p for p in pts]), {"long_name": "force-law exponent p (eq. frictionp)"}),
        "delta": (np.array([p.case.delta for p in pts]), {"long_name": "regularisation delta (eq. delta)"}),
        "A0": (a0, {"long_name": "mean angle A0", "units": "rad"}),
        "A1": (shape_value("A1"), {"long_name": "amplitude A1 (NaN for Fourier motions)", "units": "rad"}),
        "duty_cycle": (shape_value("duty_cycle"), {"long_name": "tau0 (power laws)"}),
        "closing_shape": (shape_value("closing_shape"), {"long_name": "closing exponent, signed (+ up, - down)"}),
        "opening_shape": (shape_value("opening_shape"), {"long_name": "opening exponent, signed (+ up, - down)"}),
        "period": (period, {"long_name": "period T at mu_n mu_s = 1"}),
        "kinematic_speed": (vscale, {"long_name": "deformation speed scale V = (1/4) int |dphi/dtau| dtau"}),
        "phi_min": (phi_min, {"long_name": "min of phi over a period", "units": "rad"}),
        "phi_max": (phi_max, {"long_name": "max of phi over a period", "units": "rad"}),
    }
    for values, attrs in out.values():
        _nondimensional(values.dtype, attrs)
    return out


# ---------------------------------------------------------------------------
# Skeleton
# ---------------------------------------------------------------------------


def default_points_per_task(scene: StudyScene) -> int:
    # accuracy: one case per task (its march, fixed grids and baseline take seconds);
    # stiffness: a few points, so failing marches spread over the workers.
    return 1 if scene.kind == "accuracy" else 4


def create_study_skeleton(store: Path, scene: StudyScene, points_per_chunk: int) -> None:
    """Every array, coordinate and attribute before any task runs (``skeleton_complete`` last)."""
    g = new_group(store)
    dims = result_dims(scene)
    coords = {"point": np.arange(scene.n_points, dtype=np.int32),
              "method": np.arange(len(scene.methods), dtype=np.int32),
              "rtol": np.asarray(scene.rtols), "n_steps": np.asarray(scene.fixed_steps, dtype=np.int32),
              "baseline_tol": np.asarray(scene.baseline_tolerances)}
    coord_attrs = {"point": {"long_name": "study point"},
                   "method": {"long_name": "solver method", "labels": list(scene.methods)},
                   "rtol": {"long_name": "requested relative tolerance"},
                   "n_steps": {"long_name": "steps per period of a fixed uniform grid"},
                   "baseline_tol": {"long_name": "LSODA rtol of the scipy baseline"}}
    for d, size in dims.items():
        v = coords[d]
        create_array(g, d, shape=(size,), chunks=(size,), dtype=v.dtype, fill=0, dims=(d,),
                     attrs=_nondimensional(v.dtype, coord_attrs[d]))[:] = v
    c = points_per_chunk
    for name, (values, attrs) in point_parameters(scene).items():
        fill = -1 if values.dtype.kind == "i" else np.nan
        create_array(g, name, shape=values.shape, chunks=(c,), dtype=values.dtype, fill=fill, dims=("point",),
                     attrs=attrs)[:] = values
    for name, (adims, dtype, fill, attrs) in study_arrays(scene).items():
        shape = tuple(dims[d] for d in adims)
        create_array(g, name, shape=shape, chunks=(c,) + shape[1:], dtype=dtype, fill=fill, dims=adims, attrs=attrs)
    finish_skeleton(g, scene, store=store, dims=("point",), shape=(scene.n_points,), chunks=(c,), head={"kind": scene.kind},
                    layout={"result_dims": dims}, reductions_complete=True)


# ---------------------------------------------------------------------------
# Numerics of one point
# ---------------------------------------------------------------------------


def solver_norm_errors(U, P, U_ref, P_ref, period, vscale):
    """(error of U, error of P) in the solver's norm (module docstring); NaN where U or P is NaN."""
    from solver.tools.bench import relative_u_error

    with np.errstate(invalid="ignore", divide="ignore"):
        e_u = relative_u_error(np.asarray(U, float), np.asarray(U_ref, float), period, vscale)
        e_p = np.abs(np.asarray(P, float) - P_ref) / np.abs(P_ref)
    return e_u, e_p


def _best_time(solve):
    """(result, seconds) of ``solve()``: the fastest of up to TIMING_REPEATS calls while their total
    stays under TIMING_BUDGET seconds.  The machine is shared, so the minimum, as in ``timeit``,
    is the least disturbed measurement; a solve longer than the budget is timed once."""
    best, result, spent = math.inf, None, 0.0
    for _ in range(TIMING_REPEATS):
        t0 = time.perf_counter()
        result = solve()
        dt = time.perf_counter() - t0
        best, spent = min(best, dt), spent + dt
        if spent > TIMING_BUDGET:
            break
    return result, best


def _timed_solve(case, method, rtol, max_steps):
    import solver

    kin, phys = case.kinematics(), case.physics()
    return _best_time(lambda: solver.solve_periodic(kin, phys, method=method, rtol=rtol,
                                                    max_steps_per_period=max_steps))


def _fixed(case, method, n_steps):
    """U, P, status, seconds on one uniform grid."""
    import solver

    kin, phys = case.kinematics(), case.physics()
    (iu, ip, st), seconds = _best_time(lambda: solver.solve_fixed_grid(kin, phys, n_steps, method=method))
    T, p = phys.period[0], phys.p[0]
    ok = st[0] == 0
    return (iu[0] / T if ok else math.nan, ip[0] * T ** -(p + 1.0) if ok else math.nan, int(st[0]), seconds)


def _reference(case, scene: StudyScene, vscale: float) -> dict:
    """The fine reference (periodic at the reference rtol) and its independent cross-check."""
    r, sec = _timed_solve(case, "periodic", scene.reference_rtol, None)
    out = {"U_ref": r.U[0], "P_ref": r.P[0], "ref_status": r.status[0], "ref_error_estimate": r.error_estimate[0],
           "ref_n_tau": r.n_tau[0], "ref_seconds": sec}
    check = None
    if scene.check == "march":
        c, _ = _timed_solve(case, "march", scene.check_rtol, None)
        if c.status[0] == 0:
            check = (c.U[0], c.P[0], 0, CHECK_MARCH)
    if check is None:
        U, P, st, _ = _fixed(case, "periodic", scene.check_steps)
        check = (U, P, st, CHECK_FIXED)
    out.update(check_U=check[0], check_P=check[1], check_status=check[2], check_method=check[3])
    T = case.physics().period[0]
    e_u, e_p = solver_norm_errors(check[0], check[1], r.U[0], r.P[0], T, vscale)
    out["check_difference"] = float(max(e_u, e_p)) if np.isfinite(e_u) and np.isfinite(e_p) else math.nan
    return out


def _baseline(case, tol, cap, vscale):
    """The scipy LSODA baseline of ``solver.tools.bench`` (any family, phi from the solver's kernel)."""
    from solver.tools import bench

    phys = case.physics()
    U, P, periods, seconds = bench.baseline_point(bench.family_angle(case.kinematics()), phys.mu_n[0],
                                                  phys.mu_s[0], phys.p[0], phys.period[0],
                                                  phys.delta_tau[0], vscale, tol, cap)
    return U, P, (0 if np.isfinite(U) else BASELINE_FAILED), seconds, periods


def _solve_point(scene: StudyScene, point, vscale: float) -> dict[str, np.ndarray]:
    """Every array of one point (without the leading point axis)."""
    case = point.case
    T = case.physics().period[0]
    ref = _reference(case, scene, vscale)
    nm, nr = len(scene.methods), len(scene.rtols)
    v = {k: np.full((nm, nr), np.nan) for k in ("U", "P", "error_estimate", "seconds", "error_U", "error_P",
                                                 "true_error")}
    v.update({k: np.zeros((nm, nr), dtype=np.int64) for k in ("status", "iterations", "n_tau")})
    for a, method in enumerate(scene.methods):
        cap = scene.march_max_steps_per_period if method == "march" else None
        for b, rtol in enumerate(scene.rtols):
            r, sec = _timed_solve(case, method, rtol, cap)
            v["U"][a, b], v["P"][a, b], v["seconds"][a, b] = r.U[0], r.P[0], sec
            v["error_estimate"][a, b], v["status"][a, b] = r.error_estimate[0], r.status[0]
            v["iterations"][a, b], v["n_tau"][a, b] = r.iterations[0], r.n_tau[0]
    v["error_U"], v["error_P"] = solver_norm_errors(v["U"], v["P"], ref["U_ref"], ref["P_ref"], T, vscale)
    v["true_error"] = np.fmax(v["error_U"], v["error_P"])
    v["true_error"][~(np.isfinite(v["error_U"]) & np.isfinite(v["error_P"]))] = np.nan
    v.update({k: np.asarray(x) for k, x in ref.items()})
    if scene.kind == "stiffness":
        v.update(apply_fallback(scene, v))
    if scene.fixed_steps:
        v.update(_fixed_grids(scene, case, ref, T, vscale))
    if scene.baseline_tolerances:
        v.update(_baselines(scene, case, ref, T, vscale))
    return v


def apply_fallback(scene: StudyScene, v) -> dict[str, np.ndarray]:
    """Per (method, rtol): the method's own answer if converged, else the fallback method's
    converged answer at the same rtol (when the scene allows it), else none."""
    nm, nr = v["status"].shape
    used = np.full((nm, nr), NO_ANSWER, dtype=np.int64)
    fb = scene.methods.index(scene.fallback) if scene.fallback in scene.methods else None
    for a in range(nm):
        for b in range(nr):
            if v["status"][a, b] == 0:
                used[a, b] = a
            elif fb is not None and v["status"][fb, b] == 0:
                used[a, b] = fb
    pick = np.maximum(used, 0), np.arange(nr)[None, :].repeat(nm, 0)
    none = used == NO_ANSWER
    out = {"used_method": used}
    for src, dst in (("U", "U_used"), ("P", "P_used"), ("true_error", "true_error_used")):
        x = v[src][pick]
        x[none] = np.nan
        out[dst] = x
    return out


def _fixed_grids(scene, case, ref, T, vscale):
    nm, nn = len(scene.methods), len(scene.fixed_steps)
    U, P, sec = (np.full((nm, nn), np.nan) for _ in range(3))
    st = np.zeros((nm, nn), dtype=np.int64)
    for a, method in enumerate(scene.methods):
        for b, n in enumerate(scene.fixed_steps):
            U[a, b], P[a, b], st[a, b], sec[a, b] = _fixed(case, method, n)
    e_u, e_p = solver_norm_errors(U, P, ref["U_ref"], ref["P_ref"], T, vscale)
    return {"fixed_status": st, "fixed_U": U, "fixed_P": P, "fixed_seconds": sec, "fixed_error_U": e_u,
            "fixed_error_P": e_p}


def _baselines(scene, case, ref, T, vscale):
    rows = [_baseline(case, tol, scene.baseline_cap_seconds, vscale) for tol in scene.baseline_tolerances]
    U, P, st, sec, periods = (np.array(x) for x in zip(*rows))
    e_u, e_p = solver_norm_errors(U, P, ref["U_ref"], ref["P_ref"], T, vscale)
    return {"baseline_status": st, "baseline_U": U, "baseline_P": P, "baseline_seconds": sec,
            "baseline_periods": periods, "baseline_error_U": e_u, "baseline_error_P": e_p}


# ---------------------------------------------------------------------------
# Task and driver
# ---------------------------------------------------------------------------


def solve_study_chunk(scene: StudyScene, chunks: tuple[int], index: tuple[int]) -> SolvedChunk:
    """Solve the points of chunk ``index`` (``chunks``: the layout, (points per chunk,)) by every
    method at every tolerance; whole chunks of every result array, unwritten."""
    import numba

    import solver

    (points_per_chunk,), (index,) = chunks, index
    lo, hi = index * points_per_chunk, min((index + 1) * points_per_chunk, scene.n_points)
    vscale = point_parameters_vscale(scene, lo, hi)
    # One numba thread per solve: a single point gains nothing from the solver's prange over
    # points, and on a loaded machine launching the parallel region costs ~50 ms per call,
    # which would swamp the timings (the workers give the parallelism).
    threads = numba.get_num_threads()
    numba.set_num_threads(1)
    try:
        solver.warm_up(STUDY.kernel_sets(scene))  # no timed solve pays for loading the kernels
        t0 = time.perf_counter()
        rows = [_solve_point(scene, scene.points[i], vscale[i - lo]) for i in range(lo, hi)]
        seconds = time.perf_counter() - t0
    finally:
        numba.set_num_threads(threads)
    spec = study_arrays(scene)
    groups: dict[tuple, dict] = {}
    for name, (adims, dtype, _, _) in spec.items():
        value = np.stack([np.asarray(r[name]) for r in rows]).astype(dtype)
        groups.setdefault(value.shape[1:], {})[name] = value
    writes = tuple(ChunkWrite((slice(lo, hi),) + tuple(slice(0, n) for n in rest), (index,) + (0,) * len(rest),
                              (points_per_chunk,) + rest, (scene.n_points,) + rest, values)
                   for rest, values in groups.items())
    failures = int(sum(np.count_nonzero(r["status"] != 0) for r in rows))
    return SolvedChunk(writes=writes, points=hi - lo, failures=failures, seconds=seconds)


def point_parameters_vscale(scene: StudyScene, lo: int, hi: int) -> np.ndarray:
    import solver

    return np.array([solver.kinematic_speed(scene.points[i].case.kinematics())[0] for i in range(lo, hi)])


class StudyKind(SceneKind):
    """Studies: chunks of points, each solved by every method at every tolerance; no reductions
    (the report compares them across the whole store)."""

    names = STUDY_KINDS
    rate_unit = "points/s"
    solve_chunk = staticmethod(solve_study_chunk)

    def parse(self, doc, ctx, text):
        return parse_study_scene(doc, ctx, text)

    def create_skeleton(self, run: RunContext) -> None:
        scene = run.scene
        create_study_skeleton(run.store, scene, scene.execution.points_per_task or default_points_per_task(scene))

    def failures(self, store: Path, scene) -> int:
        """(point, method, rtol) solves with a failure status (> 0)."""
        return int(np.count_nonzero(read_arrays(store, ["status"])["status"] > 0))

    def kernel_sets(self, scene) -> tuple[str, ...]:
        """The reference's periodic method, every compared method, and the fixed grids."""
        return tuple(dict.fromkeys(("periodic", *scene.methods, "fixed_grid")))


STUDY = StudyKind()
