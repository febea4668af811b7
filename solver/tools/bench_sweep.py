"""Sweep benchmark: the same grids solved cold and as warm-started sweeps, in one run.

Run as ``python -m solver.tools.bench_sweep [--n 32] [--repeats 2] [--cache-dir out/bench_sweep]``.

What is measured
----------------
1. Grids.  ``--n`` x ``--n`` points in A0 x A1/A0 (A0 from 0.1 to 1.5, A1/A0 from 0.03 to
   0.97) at two anisotropy ratios (mu_n/mu_s = 2^-4, 2^4) and two scaled periods (0.5, 4),
   for a harmonic and a power-law family (duty cycle 0.5, closing exponent 2, opening 3):
   8 grids, 8,192 points at ``--n`` 32; p = 0, delta = 1e-3.
2. Cold: ``solve_periodic`` on every point of a grid, each from nothing.  Warm: the grid's
   points in snake order (``solver.snake_order``) cut into sweeps of ``solver.SWEEP_POINTS``
   (``solve_periodic(..., sweeps=...)``), as the pipeline solves a chunk with
   ``[solver] sweeps = true``.  Both at rtol 1e-4 and 1e-7, the median wall time of
   ``--repeats`` calls, after one untimed call that compiles.  solves/s = points / time.
3. Accuracy.  Both against references at rtol 1e-9 (the engine, cold), computed once and
   cached in ``--cache-dir`` under the engine's source digest, in the harness's norm
   (``honesty.judge``): the share of converged results within rtol and within 10 rtol,
   failures, the worst error over rtol.
4. Cost.  Force evaluations per solve by phase (loose shooting, adaptive sweeps, frozen
   sweeps, estimates) and the mean steps per period, and how the warm solves started
   (``periodic.point.START_*``).

Output: the figures, then one JSON line with ``warm_over_cold_rtol_1e-4``,
``warm_over_cold_rtol_1e-7``, ``warm_solves_per_s_rtol_1e-4``, ``cold_solves_per_s_rtol_1e-4``
(and at 1e-7), ``within_rtol``, ``within_10_rtol`` (warm results, both rtols),
``failures`` (warm, both rtols), ``cold_failures``, ``worst_over_rtol``, ``points``,
``cores``.
"""
from __future__ import annotations

import argparse
import json
import os
import statistics
import time
from pathlib import Path

import numpy as np

import solver
from solver.periodic.point import N_COSTS
from solver.tools.honesty import References, Solves, engine_digest, judge

RTOLS = (1e-4, 1e-7)
REFERENCE_RTOL = 1e-9
RATIOS = (2.0 ** -4, 2.0 ** 4)
SCALED_PERIODS = (0.5, 4.0)
FAMILIES = ("harmonic", "power_law")
START_NAMES = ("cold", "warm", "warm failed, then cold")


def grid(family, ratio, scaled_period, n):
    """(kinematics, physics) of one n x n grid in snake order."""
    A0, R = np.meshgrid(np.linspace(0.1, 1.5, n), np.linspace(0.03, 0.97, n), indexing="ij")
    order = solver.snake_order((n, n))
    a0, a1 = A0.ravel()[order], (R * A0).ravel()[order]
    if family == "harmonic":
        kin = solver.Harmonic(A0=a0, A1=a1)
    else:
        m = a0.size
        kin = solver.PowerLaw(a0, a1, np.full(m, 0.5), np.full(m, 2.0), np.zeros(m, bool),
                              np.full(m, 3.0), np.zeros(m, bool))
    phys = solver.Physics.from_scaled(anisotropy_ratio=ratio, scaled_period=scaled_period,
                                      p=0.0, delta=1e-3).take(np.zeros(n * n, dtype=int))
    return kin, phys


def grids(n):
    return [((f, r, t), *grid(f, r, t, n)) for f in FAMILIES for r in RATIOS
            for t in SCALED_PERIODS]


def references(cases, cache_dir, n):
    """Per grid: ``honesty.References`` at REFERENCE_RTOL, cached under the engine digest."""
    path = Path(cache_dir) / f"references-n{n}-{engine_digest()}.npz"
    if path.exists():
        data = np.load(path)
        U, P = data["U"], data["P"]
    else:
        U, P = [], []
        for _, kin, phys in cases:
            r = solver.solve_periodic(kin, phys, rtol=REFERENCE_RTOL)
            U.append(r.U)
            P.append(r.P)
        U, P = np.array(U), np.array(P)
        path.parent.mkdir(parents=True, exist_ok=True)
        np.savez(path, U=U, P=P)
    out = []
    for k, (_, kin, phys) in enumerate(cases):
        status = np.where(np.isfinite(U[k]) & np.isfinite(P[k]), 0, 1)
        reference = Solves(U[k], P[k], status, np.zeros(len(kin), dtype=np.int64),
                           np.zeros(len(kin)), 0.0)
        out.append(References.from_solves(reference, None, phys, solver.kinematic_speed(kin)))
    return out


def timed(run, repeats):
    """(result of the last call, median seconds) of ``repeats`` calls."""
    seconds = []
    result = None
    for _ in range(repeats):
        t0 = time.perf_counter()
        result = run()
        seconds.append(time.perf_counter() - t0)
    return result, statistics.median(seconds)


def solve_all(cases, rtol, warm, repeats):
    """Every grid cold or as sweeps: (results, seconds summed over grids)."""
    results, total = [], 0.0
    for _, kin, phys in cases:
        runs = solver.sweep_runs(len(kin)) if warm else None
        r, s = timed(lambda: solver.solve_periodic(kin, phys, rtol=rtol, sweeps=runs), repeats)
        results.append(r)
        total += s
    return results, total


def summary(results, refs, cases, rtol):
    """Counts and figures of one mode at one rtol over all grids."""
    points = sum(len(k) for _, k, _ in cases)
    judged = [judge(r, ref, phys, rtol) for r, ref, (_, _, phys) in zip(results, refs, cases)]
    solves = sum(j["solves"] for j in judged)
    evaluations = np.concatenate([r.force_evaluations for r in results]).reshape(-1, N_COSTS)
    starts = np.concatenate([r.start for r in results])
    return dict(
        points=points, solves=solves,
        within=sum(j["within_rtol"] for j in judged),
        within_10=sum(j["within_10_rtol"] for j in judged),
        worst=max((j["worst_over_rtol"] for j in judged if np.isfinite(j["worst_over_rtol"])),
                  default=float("nan")),
        failures=sum(j["failures"] for j in judged),
        silent=sum(j["silent_failures"] for j in judged),
        evaluations=evaluations.mean(axis=0),
        n_tau=float(np.mean(np.concatenate([r.n_tau for r in results]))),
        starts=np.bincount(starts.astype(np.int64), minlength=len(START_NAMES)))


def benchmark(n, repeats, cache_dir):
    cases = grids(n)
    points = sum(len(k) for _, k, _ in cases)
    print(f"bench_sweep: {len(cases)} grids of {n} x {n}, {points} points, {os.cpu_count()} cores, "
          f"sweeps of {solver.SWEEP_POINTS} points in snake order, median of {repeats} calls")
    for _, kin, phys in cases[::4]:  # compile (not timed)
        solver.solve_periodic(_head(kin, 4), phys.take(np.arange(4)), rtol=1e-3,
                              sweeps=np.array([0, 2, 4]))
    t0 = time.perf_counter()
    refs = references(cases, cache_dir, n)
    print(f"references at rtol {REFERENCE_RTOL:g}: {time.perf_counter() - t0:.1f} s (cached in {cache_dir})")
    figures = {}
    warm_within = warm_within_10 = warm_solves = warm_failures = cold_failures = 0
    worst = 0.0
    for rtol in RTOLS:
        rows = {}
        for mode in ("cold", "warm"):
            results, seconds = solve_all(cases, rtol, mode == "warm", repeats)
            s = summary(results, refs, cases, rtol)
            s["rate"] = points / seconds
            rows[mode] = s
            e = s["evaluations"]
            print(f"rtol {rtol:g} {mode:>4}: {s['rate']:8.0f} solves/s, failures {s['failures']}, "
                  f"within rtol {s['within']}/{s['solves']}, within 10 rtol {s['within_10']}, "
                  f"worst {s['worst']:.3f} rtol, mean n_tau {s['n_tau']:.1f}; evaluations/solve "
                  f"loose {e[0]:.0f} adaptive {e[1]:.0f} frozen {e[2]:.0f} estimate {e[3]:.0f} "
                  f"(total {e.sum():.0f})")
            if mode == "warm":
                print("          starts: " + ", ".join(f"{name} {c}" for name, c in
                                                         zip(START_NAMES, s["starts"])))
        ratio = rows["warm"]["rate"] / rows["cold"]["rate"]
        print(f"rtol {rtol:g}: warm / cold = {ratio:.2f}")
        key = f"rtol_{rtol:.0e}".replace("e-0", "e-")
        figures[f"warm_over_cold_{key}"] = ratio
        figures[f"warm_solves_per_s_{key}"] = rows["warm"]["rate"]
        figures[f"cold_solves_per_s_{key}"] = rows["cold"]["rate"]
        warm_within += rows["warm"]["within"]
        warm_within_10 += rows["warm"]["within_10"]
        warm_solves += rows["warm"]["solves"]
        warm_failures += rows["warm"]["failures"]
        cold_failures += rows["cold"]["failures"]
        worst = max(worst, rows["warm"]["worst"])
    figures.update(within_rtol=warm_within / max(warm_solves, 1),
                   within_10_rtol=warm_within_10 / max(warm_solves, 1),
                   failures=warm_failures, cold_failures=cold_failures,
                   worst_over_rtol=worst, points=points, cores=os.cpu_count())
    print(json.dumps({k: (round(v, 4) if isinstance(v, float) else int(v))
                      for k, v in figures.items()}))
    return figures


def _head(kinematics, k):
    """The first k points of ``kinematics``."""
    return kinematics.take(np.arange(k))


def main(argv=None):
    parser = argparse.ArgumentParser(prog="python -m solver.tools.bench_sweep",
                                     description=__doc__.split("\n")[0])
    parser.add_argument("--n", type=int, default=32, help="grid points per axis (default 32)")
    parser.add_argument("--repeats", type=int, default=2)
    parser.add_argument("--cache-dir", default="out/bench_sweep")
    args = parser.parse_args(argv)
    if args.n < 3:
        parser.error("--n: at least 3")
    if args.repeats < 1:
        parser.error("--repeats: at least 1")
    benchmark(args.n, args.repeats, args.cache_dir)


if __name__ == "__main__":
    main()
