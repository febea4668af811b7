"""Throughput benchmark of the ``periodic`` solver against a scipy baseline.

Run as ``python -m solver.bench [--points 2000] [--baseline-points 20] [--seed 0]
[--baseline-cap 20] [--repeats 3]``.  Everything is measured in one run, on one machine, so
the ratios printed are like for like.

What is measured
----------------
1. Points.  ``--points`` random harmonic motions phi = A0 + A1 cos(2 pi tau),
   drawn with ``--seed``: anisotropy ratio mu_n / mu_s = 2^U(-8, 8), scaled
   period 2^U(-3, 3), A0 ~ U(0, pi/2], A1 / A0 ~ U(0, 1], p = 0,
   delta = 1e-5 (``Physics.from_scaled``, so sqrt(mu_n mu_s) = 1).
2. Solver throughput.  After a JIT warm-up on 4 points (not timed), ``--repeats``
   calls of ``solve_periodic(method="periodic")`` on all points at rtol = 1e-4 and
   as many at rtol = 1e-7.  Reported: solves/s = points / median wall time (failed
   points included in the count and the time; the median because a shared VM's wall
   times varied by +-25 % from run to run), failures (status != 0), median and
   maximum final grid size n_tau, every call's wall time.  The solver runs on all
   cores (numba ``prange`` over points).
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
   |U - U_ref| T / max(|U_ref| T, 1e-3 V) (see ``solver._solve``).  The
   baseline tolerance tol is lowered 1e-5, 1e-6, ... until the baseline's
   median error is no larger than that of the ``periodic`` solver at
   rtol = 1e-4; that tolerance's run is the timed baseline.  Points where
   the reference, the solver or the baseline failed are left out of the
   medians (the counts are printed).
5. Speed-up = (periodic solves/s at rtol 1e-4) / (baseline solves/s).  And the
   force kernel alone: ``force_and_slope`` in a numba-compiled loop over 1e5
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
kernel ratio, wall time).
"""
from __future__ import annotations

import argparse
import json
import math
import os
import subprocess
import sys
import time

import numpy as np

import solver
from solver._solve import U_FLOOR_FRACTION

RTOLS = (1e-4, 1e-7)
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


# ----------------------------------------------------------------------------- periodic solver

def repeat_timed(run, repeats):
    """(result of the last of ``repeats`` calls of the deterministic ``run``, median seconds,
    every call's seconds): the median because a shared VM's wall times vary by +-25 %."""
    runs = []
    for _ in range(repeats):
        start = time.perf_counter()
        result = run()
        runs.append(time.perf_counter() - start)
    return result, float(np.median(runs)), runs


def time_periodic(kinematics, physics, rtol, repeats=1):
    """``repeats`` batched ``solve_periodic`` calls (the solver is deterministic: every call
    returns the same result); returns (SolveResult, median wall seconds, every call's)."""
    return repeat_timed(lambda: solver.solve_periodic(kinematics, physics, method="periodic",
                                                      rtol=rtol), repeats)


def periodic_summary(result, seconds, runs):
    n = result.status.shape[0]
    return dict(solves_per_s=n / seconds, failures=int(np.count_nonzero(result.status != 0)),
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
    from ._kinematics import angle_and_rate

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


def median_of_common(*errors):
    """Medians of several error arrays over the points where all of them are finite."""
    ok = np.logical_and.reduce([np.isfinite(e) for e in errors])
    if not ok.any():
        return [math.nan] * len(errors), 0
    return [float(np.median(e[ok])) for e in errors], int(ok.sum())


def calibrated_baseline(kinematics, physics, U_ref, periodic_error, cap):
    """Tighten the LSODA tolerance until its median U error is <= the solver's.

    Every rung is a complete timed baseline run; the first rung that matches
    (or the tightest) is returned with its errors and ``matched``.
    """
    vscale = solver.kinematic_speed(kinematics)
    for tol in BASELINE_TOLERANCES:
        run = run_baseline(kinematics, physics, tol, cap)
        run["error"] = relative_u_error(run["U"], U_ref, physics.period, vscale)
        (med_periodic, med_base), count = median_of_common(periodic_error, run["error"])
        run.update(median_periodic=med_periodic, median_baseline=med_base, compared=count)
        print(f"  LSODA tol {tol:.0e}: {len(kinematics) / run['seconds']:8.2f} solves/s, "
              f"{run['failures']} failures, median U error {med_base:.2e} "
              f"(periodic rtol 1e-4: {med_periodic:.2e}, over {count} points)", flush=True)
        run["matched"] = bool(med_base <= med_periodic)
        if run["matched"]:
            break
    return run


def print_point_table(table, index, physics, U_ref, U_periodic, baseline, periodic_error):
    """Per-point comparison on the subsample; flags errors beyond tolerance."""
    print("  point   ratio  Ts      A0     A1     U_ref          U_periodic     U_baseline"
          "     err_per   err_base  periods")
    flagged = []
    for j, i in enumerate(index):
        e_p, e_b = periodic_error[j], baseline["error"][j]
        flag = ""
        if np.isfinite(U_ref[j]) and not (e_p <= FLAG_PERIODIC):
            flag += " <periodic beyond rtol"
        if np.isfinite(U_ref[j]) and np.isfinite(e_b) and e_b > FLAG_BASELINE:
            flag += " <baseline disagrees"
        if flag:
            flagged.append(int(i))
        print(f"  {i:5d} {table['ratio'][i]:8.3g} {table['scaled_period'][i]:6.3g} "
              f"{table['A0'][i]:6.3f} {table['A1'][i]:6.3f} {U_ref[j]:14.7e} "
              f"{U_periodic[j]:14.7e} {baseline['U'][j]:14.7e} {e_p:9.2e} {e_b:9.2e} "
              f"{baseline['periods'][j]:6d}{flag}")
    return flagged


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
    cmd = [sys.executable, "-m", "solver.bench", "--interpreted-kernel-rate", str(n),
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
    parser = argparse.ArgumentParser(prog="python -m solver.bench",
                                     description=__doc__.split("\n")[0])
    parser.add_argument("--points", type=int, default=2000)
    parser.add_argument("--baseline-points", type=int, default=20)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--baseline-cap", type=float, default=20.0,
                        help="wall-time cap per baseline point [s]")
    parser.add_argument("--repeats", type=int, default=3,
                        help="timed calls of the periodic solver per rtol (median reported)")
    parser.add_argument("--interpreted-kernel-rate", type=int, default=None,
                        help=argparse.SUPPRESS)  # internal: used by no_jit_rate
    return parser


def benchmark(n_points, n_baseline, seed, cap, repeats=3):
    wall_start = time.perf_counter()
    rng = np.random.default_rng(seed)
    kinematics, physics, table = draw_points(n_points, rng)
    print(f"{n_points} harmonic points, seed {seed}, {os.cpu_count()} cores", flush=True)

    warm = np.arange(min(WARMUP_POINTS, n_points))
    solver.solve_periodic(*subset(kinematics, physics, warm), method="periodic", rtol=RTOLS[0])

    periodic = {}
    for rtol in RTOLS:
        result, seconds, runs = time_periodic(kinematics, physics, rtol, repeats)
        periodic[rtol] = (result, periodic_summary(result, seconds, runs))
        s = periodic[rtol][1]
        print(f"periodic rtol {rtol:.0e}: {s['solves_per_s']:.2f} solves/s, "
              f"{s['failures']} failures {status_counts(result)}, n_tau median "
              f"{s['median_n_tau']:.0f} max {s['max_n_tau']}, {s['seconds']:.2f} s (median of "
              f"{repeats}: {', '.join(f'{r:.2f}' for r in runs)} s)", flush=True)

    index = np.sort(rng.choice(n_points, size=min(n_baseline, n_points), replace=False))
    kin_sub, phys_sub = subset(kinematics, physics, index)
    reference, ref_seconds, _ = time_periodic(kin_sub, phys_sub, REFERENCE_RTOL)
    ref_failures = int(np.count_nonzero(reference.status != 0))
    print(f"reference: periodic rtol {REFERENCE_RTOL:.0e} on {len(index)} points, "
          f"{ref_failures} failures {status_counts(reference)}, {ref_seconds:.2f} s", flush=True)
    vscale = solver.kinematic_speed(kin_sub)
    U_periodic = periodic[RTOLS[0]][0].U[index]
    periodic_error = relative_u_error(U_periodic, reference.U, phys_sub.period, vscale)

    baseline_point(harmonic_angle(1.0, 0.3), 1.0, 1.0, 0.0, 1.0, 1e-5, 0.3, 1e-4, cap)  # warm up scipy/dispatch
    print(f"baseline: LSODA period by period from rest, cap {cap:g} s per point", flush=True)
    base = calibrated_baseline(kin_sub, phys_sub, reference.U, periodic_error, cap)
    base_rate = len(index) / base["seconds"]
    if not base["matched"]:
        print("  WARNING: no LSODA tolerance matched the periodic solver's accuracy", flush=True)
    flagged = print_point_table(table, index, phys_sub, reference.U, U_periodic, base,
                                periodic_error)
    if flagged:
        print(f"  flagged points (periodic error > {FLAG_PERIODIC:g} or baseline error > "
              f"{FLAG_BASELINE:g} against the reference): {flagged}", flush=True)

    kernel = force_kernel_rates(seed)
    print(f"force kernel: compiled loop {kernel['compiled']:.3e} evals/s, Python loop over "
          f"py_func {kernel['py_func']:.3e} evals/s (ratio {kernel['compiled'] / kernel['py_func']:.1f}), "
          f"fully interpreted {kernel['no_jit']:.3e} evals/s "
          f"(ratio {kernel['compiled'] / kernel['no_jit']:.1f})", flush=True)

    fast, slow = periodic[RTOLS[0]][1], periodic[RTOLS[1]][1]
    speedup = fast["solves_per_s"] / base_rate
    print(f"speed-up periodic (rtol 1e-4, {os.cpu_count()} cores) / LSODA baseline "
          f"(tol {base['tol']:.0e}, 1 core): {speedup:.2f}", flush=True)
    wall = time.perf_counter() - wall_start
    print(f"wall time {wall:.1f} s", flush=True)
    return {
        "solves_per_s_rtol_1e-4": fast["solves_per_s"],
        "solves_per_s_rtol_1e-7": slow["solves_per_s"],
        "baseline_solves_per_s": base_rate,
        "speedup": speedup,
        "failures": fast["failures"] + slow["failures"],
        "failures_rtol_1e-4": fast["failures"],
        "failures_rtol_1e-7": slow["failures"],
        "cores": os.cpu_count(),
        "points": n_points,
        "repeats": repeats,
        "seconds_rtol_1e-4_runs": fast["runs"],
        "seconds_rtol_1e-7_runs": slow["runs"],
        "baseline_points": int(len(index)),
        "median_rel_error_periodic": base["median_periodic"],
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
    }


def _json_value(value):
    """NaN and inf are not JSON: write them as null."""
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
    report = benchmark(args.points, args.baseline_points, args.seed, args.baseline_cap,
                       args.repeats)
    print(json.dumps({k: _json_value(v) for k, v in report.items()}))
    return 0


if __name__ == "__main__":
    sys.exit(main())
