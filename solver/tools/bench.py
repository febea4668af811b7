"""Throughput benchmark of the periodic engines against a scipy baseline.

Run as ``python -m solver.tools.bench [--points 2000] [--baseline-points 20] [--seed 0]
[--baseline-cap 20] [--repeats 3] [--methods M ...]``.  Everything is measured in one run, on
one machine, so the ratios printed are like for like.

What is measured
----------------
1. Points.  ``--points`` random harmonic motions phi = A0 + A1 cos(2 pi tau),
   drawn with ``--seed``: anisotropy ratio mu_n / mu_s = 2^U(-8, 8), scaled
   period 2^U(-3, 3), A0 ~ U(0, pi/2], A1 / A0 ~ U(0, 1], p = 0,
   delta = 1e-5 (``Physics.from_scaled``, so sqrt(mu_n mu_s) = 1).
2. Engine throughput.  Every engine of ``--methods`` (default: every method of
   ``solver.METHODS`` but the march; the default engine of ``solve_periodic``, whose
   figures the top-level keys hold, is always included) on the same points.  After a
   JIT warm-up of each engine on 4 points (not timed), ``--repeats`` calls of
   ``solve_periodic(method=...)`` on all points at rtol = 1e-4 and as many at
   rtol = 1e-7, the engines one after the other at each rtol.  Reported per engine:
   solves/s = points / median wall time (failed points included in the count and the
   time; the median because a shared VM's wall times varied by +-25 % from run to run),
   failures (status != 0, by code), median and maximum final grid size n_tau, every
   call's wall time, and its ratio of solves/s to the default engine's.  The engines run
   on all cores (numba ``prange`` over points).
3. Baseline.  What a user would write with scipy: for a random subsample of
   ``--baseline-points`` points, ``solve_ivp(method="LSODA")`` integrates the
   augmented state y = [u, int u dtau, int Pi dtau] of u' = T^(2-p) F(u, tau)
   over one period at a time, from u = 0, restarting each period from the
   end value of u, until |u(1) - u(0)| < tol V (V the deformation speed scale,
   ``kinematic_speed``).  Then U = (int_0^1 u dtau) / T and
   P = T^-(p+1) int_0^1 Pi dtau over the last period.  F, dF/du (passed as the
   analytic Jacobian, which only helps LSODA) and Pi are the solver's own
   kernels ``force_and_slope`` and ``power_density``, called from Python.
   LSODA runs with rtol = tol and atol = 1e-2 tol times the component's scale.
   Each point has a wall-time cap (``--baseline-cap``); a point that exceeds it
   is a failure and is charged the cap, so the baseline's solves/s is an upper
   bound and the speed-up a lower bound.  The baseline is serial (one core),
   as a user's loop over points would be.
4. Matching accuracy.  The error of U is measured against a ``periodic``
   reference at rtol = 1e-8 on the subsample, in the solver's own norm:
   |U - U_ref| T / max(|U_ref| T, 1e-3 V) (see ``solver.solve``).  The
   baseline tolerance tol is lowered 1e-5, 1e-6, ... until the baseline's
   median error is no larger than that of each engine at rtol = 1e-4; for each
   engine the first such tolerance's run (or the tightest's) is its timed baseline.
   Points where the reference, the engine or the baseline failed are left out of
   the medians (the counts are printed).  Each engine's accuracy on the subsample
   (median and maximum U error, and the largest error in the honesty harness's norm
   max(U error, P error) over rtol) is printed at both rtols.
5. Speed-up = (engine solves/s at rtol 1e-4) / (its matched baseline's solves/s).  And
   the force kernel alone: ``force_and_slope`` in a numba-compiled loop over 1e5
   random inputs against a pure-Python loop over ~2e3 inputs calling
   ``force_and_slope.py_func`` (whose inner helpers are still compiled
   dispatchers), and against the same Python loop in a subprocess with
   ``NUMBA_DISABLE_JIT=1`` (fully interpreted).

Output
------
Human-readable lines, then as the last line one JSON object with the keys
``solves_per_s_rtol_1e-4``, ``solves_per_s_rtol_1e-7``,
``baseline_solves_per_s``, ``speedup``, ``failures`` (both rtol runs),
``failures_rtol_1e-4``, ``failures_rtol_1e-7``, ``cores``, ``points``, ``repeats``,
``seconds_rtol_1e-4_runs``, ``seconds_rtol_1e-7_runs``,
``baseline_points``, ``median_rel_error_periodic``,
``median_rel_error_baseline``, ``numba_speedup_force_kernel`` and a few more
(baseline tolerance and failures, reference failures, the fully interpreted
kernel ratio, wall time), all of them for the default engine (the default ``method`` of
``solve_periodic``, named by the key ``default_engine``); and ``engines``: per engine
timed, the same figures
(``solves_per_s_rtol_1e-4``, ..., ``speedup``, ``baseline_tolerance``) plus its failure
codes, n_tau, accuracy on the subsample and ``ratio_to_default_rtol_1e-4`` / ``_1e-7``.
"""
from __future__ import annotations

import argparse
import inspect
import json
import math
import os
import subprocess
import sys
import time

import numpy as np

import solver
from solver.solve import U_FLOOR_FRACTION

RTOLS = (1e-4, 1e-7)
DEFAULT_POINTS = 2000
DEFAULT_SEED = 0
REFERENCE_RTOL = 1e-8
BASELINE_TOLERANCES = (1e-5, 1e-6, 1e-7, 1e-8, 1e-9, 1e-10)
WARMUP_POINTS = 4
COMPILED_KERNEL_CALLS = 100_000
INTERPRETED_KERNEL_CALLS = 2_000
#: disagreements flagged in the per-point table
FLAG_PERIODIC = 1e-4
FLAG_BASELINE = 1e-3


# ----------------------------------------------------------------------------- points

def draw_points(n, rng):
    """Random harmonic parameter points; returns (Harmonic, Physics, table of the draws)."""
    ratio = 2.0 ** rng.uniform(-8.0, 8.0, n)
    scaled_period = 2.0 ** rng.uniform(-3.0, 3.0, n)
    A0 = 0.5 * np.pi * (1.0 - rng.random(n))      # (0, pi/2]
    A1 = A0 * (1.0 - rng.random(n))               # A1 / A0 in (0, 1]
    table = dict(ratio=ratio, scaled_period=scaled_period, A0=A0, A1=A1)
    physics = solver.Physics.from_scaled(ratio, scaled_period, p=0.0, delta=1e-5)
    return solver.Harmonic(A0, A1), physics, table


def subset(kinematics, physics, index):
    return kinematics.take(index), physics.take(index)


# ----------------------------------------------------------------------------- engines

def default_engine():
    """The default ``method`` of ``solve_periodic`` (the engine the top-level keys describe)."""
    return inspect.signature(solver.solve_periodic).parameters["method"].default


def bench_engines(methods=None):
    """The engines to time: ``methods`` (default: ``solver.METHODS`` but the march), with the
    default engine first, always."""
    methods = [m for m in solver.METHODS if m != "march"] if methods is None else list(methods)
    for m in methods:
        if m not in solver.METHODS:
            raise ValueError(f"method: expected one of {solver.METHODS}, got {m!r}")
    default = default_engine()
    return [default] + [m for m in dict.fromkeys(methods) if m != default]


def repeat_timed(run, repeats):
    """(result of the last of ``repeats`` calls of the deterministic ``run``, median seconds,
    every call's seconds): the median because a shared VM's wall times vary by +-25 %."""
    runs = []
    for _ in range(repeats):
        start = time.perf_counter()
        result = run()
        runs.append(time.perf_counter() - start)
    return result, float(np.median(runs)), runs


def time_engine(kinematics, physics, rtol, repeats=1, method="periodic"):
    """``repeats`` batched ``solve_periodic(method=method)`` calls (the engines are
    deterministic: every call returns the same result); returns (SolveResult, median wall
    seconds, every call's)."""
    return repeat_timed(lambda: solver.solve_periodic(kinematics, physics, method=method,
                                                      rtol=rtol), repeats)


def engine_summary(result, seconds, runs):
    n = result.status.shape[0]
    return dict(solves_per_s=n / seconds, failures=int(np.count_nonzero(result.status != 0)),
                failure_codes=status_counts(result),
                median_n_tau=float(np.median(result.n_tau)), max_n_tau=int(result.n_tau.max()),
                seconds=seconds, runs=runs)


def status_counts(result):
    codes, counts = np.unique(result.status[result.status != 0], return_counts=True)
    return {int(c): int(k) for c, k in zip(codes, counts)}


# ----------------------------------------------------------------------------- scipy baseline

class _OverTime(Exception):
    """Raised from inside the ODE right-hand side when a point exceeds its wall-time cap."""


def harmonic_angle(A0, A1):
    """phi(tau), dphi/dtau of a harmonic motion, as a Python function of tau."""
    two_pi = 2.0 * math.pi

    def angle(tau):
        return A0 + A1 * math.cos(two_pi * tau), -two_pi * A1 * math.sin(two_pi * tau)

    return angle


def family_angle(kinematics):
    """phi(tau), dphi/dtau of a one-point family (any kind), through the solver's kernel."""
    from ..model.kinematics import angle_and_rate

    code, params = kinematics.kernel_encoding()
    row = params[0].copy()
    return lambda tau: angle_and_rate(code, row, tau, tau)


def _make_ode(angle, mu_n, mu_s, p, kappa, delta_tau, deadline):
    """Right-hand side and Jacobian of y = [u, int u, int Pi] for one point."""
    force = solver.force_and_slope
    power = solver.power_density

    def rhs(tau, y):
        if time.perf_counter() > deadline:
            raise _OverTime
        phi, omega = angle(tau)
        u = y[0]
        F, _ = force(u, phi, omega, mu_n, mu_s, p, delta_tau)
        return [kappa * F, u, power(u, phi, omega, mu_n, mu_s, p, delta_tau)]

    def jac(tau, y):
        phi, omega = angle(tau)
        _, slope = force(y[0], phi, omega, mu_n, mu_s, p, delta_tau)
        return [[kappa * slope, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 0.0]]

    return rhs, jac


def baseline_point(angle, mu_n, mu_s, p, period, delta_tau, vscale, tol, cap):
    """March one point period by period with LSODA; returns (U, P, periods, seconds).

    ``angle(tau)`` gives (phi, dphi/dtau) (``harmonic_angle``, ``family_angle``).  U and P
    are NaN when the wall-time cap was hit or LSODA failed.
    """
    from scipy.integrate import solve_ivp

    start = time.perf_counter()
    kappa = period ** (2.0 - p)
    rhs, jac = _make_ode(angle, mu_n, mu_s, p, kappa, delta_tau, start + cap)
    atol = 1e-2 * tol * np.array([vscale, vscale, min(mu_n, mu_s) * vscale])
    u = 0.0
    periods = 0
    try:
        while True:
            sol = solve_ivp(rhs, (0.0, 1.0), [u, 0.0, 0.0], method="LSODA", rtol=tol,
                            atol=atol, jac=jac)
            periods += 1
            if not sol.success:
                return math.nan, math.nan, periods, time.perf_counter() - start
            u_end, int_u, int_pi = sol.y[:, -1]
            if abs(u_end - u) < tol * vscale:
                return (int_u / period, int_pi * period ** -(p + 1.0), periods,
                        time.perf_counter() - start)
            u = u_end
    except _OverTime:
        return math.nan, math.nan, periods, time.perf_counter() - start


def run_baseline(kinematics, physics, tol, cap):
    """``baseline_point`` over all points (serially); returns arrays and the total wall time."""
    vscale = solver.kinematic_speed(kinematics)
    n = len(kinematics)
    U, P, periods = np.full(n, np.nan), np.full(n, np.nan), np.zeros(n, dtype=int)
    start = time.perf_counter()
    for i in range(n):
        U[i], P[i], periods[i], _ = baseline_point(
            harmonic_angle(kinematics.A0[i], kinematics.A1[i]), physics.mu_n[i], physics.mu_s[i],
            physics.p[i],
            physics.period[i], physics.delta_tau[i], vscale[i], tol, cap)
    return dict(U=U, P=P, periods=periods, seconds=time.perf_counter() - start,
                failures=int(np.count_nonzero(~np.isfinite(U))), tol=tol)


# ----------------------------------------------------------------------------- accuracy

def relative_u_error(U, U_ref, period, vscale):
    """|U - U_ref| T / max(|U_ref| T, 1e-3 V): the solver's error norm for U."""
    scale = np.maximum(np.abs(U_ref) * period, U_FLOOR_FRACTION * vscale)
    return np.abs(U - U_ref) * period / scale


def solution_error(U, P, U_ref, P_ref, period, vscale):
    """max(U error, P error) in the solver's norm, the quantity ``error_estimate`` bounds:
    U's error is ``relative_u_error``, P's |P - P_ref| / |P_ref|.  NaN where either is NaN."""
    e_u = relative_u_error(U, U_ref, period, vscale)
    with np.errstate(invalid="ignore", divide="ignore"):
        e_p = np.abs(P - P_ref) / np.abs(P_ref)
    return np.where(np.isnan(e_u) | np.isnan(e_p), np.nan, np.maximum(e_u, e_p))


def median_of_common(*errors):
    """Medians of several error arrays over the points where all of them are finite."""
    ok = np.logical_and.reduce([np.isfinite(e) for e in errors])
    if not ok.any():
        return [math.nan] * len(errors), 0
    return [float(np.median(e[ok])) for e in errors], int(ok.sum())


def calibrated_baseline(kinematics, physics, U_ref, engine_errors, cap):
    """Tighten the LSODA tolerance until its median U error is <= each engine's.

    ``engine_errors``: {engine: its U errors at rtol 1e-4 on the subsample}.  Every rung is
    a complete timed baseline run; the ladder stops when every engine is matched.  Returns
    {engine: the first rung that matches it (or the tightest), with its errors,
    ``median_engine``, ``median_baseline`` (over the ``compared`` points where the
    reference, the engine and the baseline all gave a number) and ``matched``}.
    """
    vscale = solver.kinematic_speed(kinematics)
    chosen = {}
    for tol in BASELINE_TOLERANCES:
        run = run_baseline(kinematics, physics, tol, cap)
        run["error"] = relative_u_error(run["U"], U_ref, physics.period, vscale)
        print(f"  LSODA tol {tol:.0e}: {len(kinematics) / run['seconds']:8.2f} solves/s, "
              f"{run['failures']} failures", flush=True)
        for engine, error in engine_errors.items():
            (med_engine, med_base), count = median_of_common(error, run["error"])
            matched = bool(med_base <= med_engine)
            print(f"    median U error {med_base:.2e}, {engine} rtol 1e-4: {med_engine:.2e} "
                  f"(over {count} points){' matched' if matched else ''}", flush=True)
            if engine not in chosen and (matched or tol == BASELINE_TOLERANCES[-1]):
                chosen[engine] = dict(run, median_engine=med_engine, median_baseline=med_base,
                                      compared=count, matched=matched)
        if len(chosen) == len(engine_errors):
            break
    return chosen


def print_point_table(table, index, U_ref, engine_U, baseline, engine_error):
    """Per-point comparison on the subsample (``engine_U``, ``engine_error``: {engine: values
    at rtol 1e-4 on the subsample}); flags errors beyond tolerance.  Returns the flagged
    points."""
    print("  point   ratio  Ts      A0     A1     U_ref          U_baseline     err_base"
          + "".join(f"  err_{engine:<9s}" for engine in engine_U) + " periods")
    flagged = []
    for j, i in enumerate(index):
        e_b = baseline["error"][j]
        flag = ""
        for engine, error in engine_error.items():
            if np.isfinite(U_ref[j]) and not (error[j] <= FLAG_PERIODIC):
                flag += f" <{engine} beyond rtol"
        if np.isfinite(U_ref[j]) and np.isfinite(e_b) and e_b > FLAG_BASELINE:
            flag += " <baseline disagrees"
        if flag:
            flagged.append(int(i))
        print(f"  {i:5d} {table['ratio'][i]:8.3g} {table['scaled_period'][i]:6.3g} "
              f"{table['A0'][i]:6.3f} {table['A1'][i]:6.3f} {U_ref[j]:14.7e} "
              f"{baseline['U'][j]:14.7e} {e_b:9.2e}"
              + "".join(f"  {error[j]:13.2e}" for error in engine_error.values())
              + f" {baseline['periods'][j]:6d}{flag}")
    return flagged


def engine_accuracy(results, reference, index, physics, vscale):
    """An engine's accuracy on the reference subsample at each rtol: median and maximum U
    error, and the largest ``solution_error`` in units of rtol (NaN-free: over the points
    where the reference and the engine converged)."""
    out = {}
    for rtol, (result, _) in results.items():
        e_u = relative_u_error(result.U[index], reference.U, physics.period, vscale)
        e = solution_error(result.U[index], result.P[index], reference.U, reference.P,
                           physics.period, vscale) / rtol
        ok = np.isfinite(e_u)
        out[rtol] = dict(median_rel_error=float(np.median(e_u[ok])) if ok.any() else math.nan,
                         max_rel_error=float(e_u[ok].max()) if ok.any() else math.nan,
                         max_error_over_rtol=float(np.nanmax(e)) if np.isfinite(e).any()
                         else math.nan)
    return out


# ----------------------------------------------------------------------------- force kernel

def kernel_inputs(n, rng):
    """Random arguments of ``force_and_slope`` spanning the benchmark's range (p = 0)."""
    phi = 0.5 * np.pi * rng.random(n)
    omega = 2.0 * np.pi * rng.uniform(-1.5, 1.5, n)
    u = 0.25 * np.abs(omega) * rng.normal(0.0, 1.0, n)
    ratio = 2.0 ** rng.uniform(-8.0, 8.0, n)
    mu_n, mu_s = np.sqrt(ratio), 1.0 / np.sqrt(ratio)
    delta_tau = 1e-5 * 2.0 ** rng.uniform(-3.0, 3.0, n)
    return u, phi, omega, mu_n, mu_s, np.zeros(n), delta_tau


def python_force_loop(force, u, phi, omega, mu_n, mu_s, p, delta_tau):
    total = 0.0
    for i in range(u.shape[0]):
        F, slope = force(u[i], phi[i], omega[i], mu_n[i], mu_s[i], p[i], delta_tau[i])
        total += F + slope
    return total


def compiled_force_loop():
    """``python_force_loop`` compiled by numba around the compiled kernel."""
    import numba

    force = solver.force_and_slope

    @numba.njit
    def loop(u, phi, omega, mu_n, mu_s, p, delta_tau):
        total = 0.0
        for i in range(u.shape[0]):
            F, slope = force(u[i], phi[i], omega[i], mu_n[i], mu_s[i], p[i], delta_tau[i])
            total += F + slope
        return total

    return loop


def evaluations_per_s(loop, args):
    loop(*(a[:10] for a in args))  # compile / warm up
    start = time.perf_counter()
    loop(*args)
    return args[0].shape[0] / (time.perf_counter() - start)


def interpreted_rate(n, seed):
    """Evaluations/s of the Python loop over ``force_and_slope.py_func`` in this process."""
    args = kernel_inputs(n, np.random.default_rng(seed))
    py_func = getattr(solver.force_and_slope, "py_func", solver.force_and_slope)
    return evaluations_per_s(lambda *a: python_force_loop(py_func, *a), args)


def no_jit_rate(n, seed):
    """The same Python loop in a subprocess with NUMBA_DISABLE_JIT=1 (nothing compiled)."""
    env = dict(os.environ, NUMBA_DISABLE_JIT="1")
    cmd = [sys.executable, "-m", "solver.tools.bench", "--interpreted-kernel-rate", str(n),
           "--seed", str(seed)]
    out = subprocess.run(cmd, env=env, capture_output=True, text=True, check=True)
    return float(out.stdout.strip().splitlines()[-1])


def force_kernel_rates(seed):
    rng = np.random.default_rng(seed + 1)
    compiled = evaluations_per_s(compiled_force_loop(), kernel_inputs(COMPILED_KERNEL_CALLS, rng))
    py_func = interpreted_rate(INTERPRETED_KERNEL_CALLS, seed + 2)
    try:
        no_jit = no_jit_rate(INTERPRETED_KERNEL_CALLS, seed + 2)
    except (subprocess.CalledProcessError, ValueError, IndexError) as exc:
        print(f"  fully interpreted measurement failed: {exc}", flush=True)
        no_jit = math.nan
    return dict(compiled=compiled, py_func=py_func, no_jit=no_jit)


# ----------------------------------------------------------------------------- main

def build_parser():
    parser = argparse.ArgumentParser(prog="python -m solver.tools.bench",
                                     description=__doc__.split("\n")[0])
    parser.add_argument("--points", type=int, default=DEFAULT_POINTS)
    parser.add_argument("--baseline-points", type=int, default=20)
    parser.add_argument("--seed", type=int, default=DEFAULT_SEED)
    parser.add_argument("--baseline-cap", type=float, default=20.0,
                        help="wall-time cap per baseline point [s]")
    parser.add_argument("--repeats", type=int, default=3,
                        help="timed calls of each engine per rtol (median reported)")
    parser.add_argument("--methods", nargs="+", default=None,
                        help="engines to time (default: solver.METHODS but the march; the "
                             "default engine is always timed)")
    parser.add_argument("--interpreted-kernel-rate", type=int, default=None,
                        help=argparse.SUPPRESS)  # internal: used by no_jit_rate
    return parser


def _rtol_key(name, rtol):
    return f"{name}_rtol_{rtol:.0e}".replace("e-0", "e-")


def benchmark(n_points, n_baseline, seed, cap, repeats=3, methods=None):
    wall_start = time.perf_counter()
    engines = bench_engines(methods)
    default = engines[0]
    rng = np.random.default_rng(seed)
    kinematics, physics, table = draw_points(n_points, rng)
    print(f"{n_points} harmonic points, seed {seed}, {os.cpu_count()} cores; engines "
          f"{', '.join(engines)} (default: {default})", flush=True)

    warm = np.arange(min(WARMUP_POINTS, n_points))
    for engine in engines:
        solver.solve_periodic(*subset(kinematics, physics, warm), method=engine, rtol=RTOLS[0])

    timed = {engine: {} for engine in engines}
    for rtol in RTOLS:
        for engine in engines:
            result, seconds, runs = time_engine(kinematics, physics, rtol, repeats, engine)
            timed[engine][rtol] = (result, engine_summary(result, seconds, runs))
            s = timed[engine][rtol][1]
            ratio = s["solves_per_s"] / timed[default][rtol][1]["solves_per_s"]
            print(f"{engine} rtol {rtol:.0e}: {s['solves_per_s']:.2f} solves/s"
                  f"{'' if engine == default else f' ({ratio:.2f}x {default})'}, "
                  f"{s['failures']} failures {s['failure_codes']}, n_tau median "
                  f"{s['median_n_tau']:.0f} max {s['max_n_tau']}, {s['seconds']:.2f} s (median "
                  f"of {repeats}: {', '.join(f'{r:.2f}' for r in runs)} s)", flush=True)

    index = np.sort(rng.choice(n_points, size=min(n_baseline, n_points), replace=False))
    kin_sub, phys_sub = subset(kinematics, physics, index)
    reference, ref_seconds, _ = time_engine(kin_sub, phys_sub, REFERENCE_RTOL)
    ref_failures = int(np.count_nonzero(reference.status != 0))
    print(f"reference: periodic rtol {REFERENCE_RTOL:.0e} on {len(index)} points, "
          f"{ref_failures} failures {status_counts(reference)}, {ref_seconds:.2f} s", flush=True)
    vscale = solver.kinematic_speed(kin_sub)
    engine_U = {engine: timed[engine][RTOLS[0]][0].U[index] for engine in engines}
    engine_error = {engine: relative_u_error(U, reference.U, phys_sub.period, vscale)
                    for engine, U in engine_U.items()}
    accuracy = {engine: engine_accuracy(timed[engine], reference, index, phys_sub, vscale)
                for engine in engines}
    for engine in engines:
        print(f"accuracy of {engine} on the subsample: " + "; ".join(
            f"rtol {rtol:.0e}: U error median {a['median_rel_error']:.2e} max "
            f"{a['max_rel_error']:.2e}, worst max(U, P error) {a['max_error_over_rtol']:.3g} "
            f"rtol" for rtol, a in accuracy[engine].items()), flush=True)

    baseline_point(harmonic_angle(1.0, 0.3), 1.0, 1.0, 0.0, 1.0, 1e-5, 0.3, 1e-4, cap)  # warm up scipy/dispatch
    print(f"baseline: LSODA period by period from rest, cap {cap:g} s per point", flush=True)
    matched = calibrated_baseline(kin_sub, phys_sub, reference.U, engine_error, cap)
    base = matched[default]
    base_rate = len(index) / base["seconds"]
    for engine in engines:
        if not matched[engine]["matched"]:
            print(f"  WARNING: no LSODA tolerance matched the accuracy of {engine}", flush=True)
    flagged = print_point_table(table, index, reference.U, engine_U, base, engine_error)
    if flagged:
        print(f"  flagged points (an engine's error > {FLAG_PERIODIC:g} or baseline error > "
              f"{FLAG_BASELINE:g} against the reference): {flagged}", flush=True)

    kernel = force_kernel_rates(seed)
    print(f"force kernel: compiled loop {kernel['compiled']:.3e} evals/s, Python loop over "
          f"py_func {kernel['py_func']:.3e} evals/s (ratio {kernel['compiled'] / kernel['py_func']:.1f}), "
          f"fully interpreted {kernel['no_jit']:.3e} evals/s "
          f"(ratio {kernel['compiled'] / kernel['no_jit']:.1f})", flush=True)

    per_engine = {}
    for engine in engines:
        fast, slow = (timed[engine][rtol][1] for rtol in RTOLS)
        rate = len(index) / matched[engine]["seconds"]
        per_engine[engine] = {
            "solves_per_s_rtol_1e-4": fast["solves_per_s"],
            "solves_per_s_rtol_1e-7": slow["solves_per_s"],
            "ratio_to_default_rtol_1e-4":
                fast["solves_per_s"] / timed[default][RTOLS[0]][1]["solves_per_s"],
            "ratio_to_default_rtol_1e-7":
                slow["solves_per_s"] / timed[default][RTOLS[1]][1]["solves_per_s"],
            "failures": fast["failures"] + slow["failures"],
            "failures_rtol_1e-4": fast["failures"],
            "failures_rtol_1e-7": slow["failures"],
            "failure_codes_rtol_1e-4": fast["failure_codes"],
            "failure_codes_rtol_1e-7": slow["failure_codes"],
            "seconds_rtol_1e-4_runs": fast["runs"],
            "seconds_rtol_1e-7_runs": slow["runs"],
            **{_rtol_key(k, rtol): timed[engine][rtol][1][k]
               for rtol in RTOLS for k in ("median_n_tau", "max_n_tau")},
            **{_rtol_key(k, rtol): accuracy[engine][rtol][k]
               for rtol in RTOLS for k in ("median_rel_error", "max_rel_error",
                                           "max_error_over_rtol")},
            "baseline_tolerance": matched[engine]["tol"],
            "baseline_accuracy_matched": matched[engine]["matched"],
            "baseline_solves_per_s": rate,
            "speedup": fast["solves_per_s"] / rate,
        }
        print(f"speed-up {engine} (rtol 1e-4, {os.cpu_count()} cores) / LSODA baseline "
              f"(tol {matched[engine]['tol']:.0e}, 1 core): "
              f"{per_engine[engine]['speedup']:.2f}", flush=True)
    for engine in engines[1:]:
        print(f"{engine} / {default}: {per_engine[engine]['ratio_to_default_rtol_1e-4']:.2f}x "
              f"at rtol 1e-4, {per_engine[engine]['ratio_to_default_rtol_1e-7']:.2f}x at rtol "
              f"1e-7", flush=True)
    wall = time.perf_counter() - wall_start
    print(f"wall time {wall:.1f} s", flush=True)
    fast, slow = (timed[default][rtol][1] for rtol in RTOLS)
    return {
        "solves_per_s_rtol_1e-4": fast["solves_per_s"],
        "solves_per_s_rtol_1e-7": slow["solves_per_s"],
        "baseline_solves_per_s": base_rate,
        "speedup": fast["solves_per_s"] / base_rate,
        "failures": fast["failures"] + slow["failures"],
        "failures_rtol_1e-4": fast["failures"],
        "failures_rtol_1e-7": slow["failures"],
        "cores": os.cpu_count(),
        "points": n_points,
        "repeats": repeats,
        "seconds_rtol_1e-4_runs": fast["runs"],
        "seconds_rtol_1e-7_runs": slow["runs"],
        "baseline_points": int(len(index)),
        "median_rel_error_periodic": base["median_engine"],
        "median_rel_error_baseline": base["median_baseline"],
        "numba_speedup_force_kernel": kernel["compiled"] / kernel["py_func"],
        "numba_speedup_force_kernel_no_jit": kernel["compiled"] / kernel["no_jit"],
        "baseline_tolerance": base["tol"],
        "baseline_accuracy_matched": base["matched"],
        "baseline_failures": base["failures"],
        "reference_failures": ref_failures,
        "error_compared_points": base["compared"],
        "flagged_points": flagged,
        "wall_seconds": wall,
        "default_engine": default,
        "engines": per_engine,
    }


def json_value(value):
    """NaN and inf are not JSON: null, in nested dicts and lists too."""
    if isinstance(value, dict):
        return {str(k): json_value(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [json_value(v) for v in value]
    if isinstance(value, (np.floating, np.integer, np.bool_)):
        value = value.item()
    if isinstance(value, float) and not math.isfinite(value):
        return None
    return value


def main(argv=None):
    args = build_parser().parse_args(argv)
    if args.interpreted_kernel_rate is not None:
        print(interpreted_rate(args.interpreted_kernel_rate, args.seed))
        return 0
    if args.points < WARMUP_POINTS or args.baseline_points < 1 or args.repeats < 1:
        print("--points must be >= 4, --baseline-points and --repeats >= 1", file=sys.stderr)
        return 2
    try:
        bench_engines(args.methods)
    except ValueError as exc:
        print(exc, file=sys.stderr)
        return 2
    report = benchmark(args.points, args.baseline_points, args.seed, args.baseline_cap,
                       args.repeats, args.methods)
    print(json.dumps(json_value(report)))
    return 0


if __name__ == "__main__":
    sys.exit(main())
