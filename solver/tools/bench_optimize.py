"""Benchmark: one Kmax = 7 optimisation, adjoint BFGS/Newton against scipy BFGS with differences.

``python -m solver.tools.bench_optimize [--seed S] [--seeds N] [--kmax K] [--ratio-log2 R]
[--repeats 3]``

Both optimisers see the same objective: -|lambda| of the discretised problem on one
fixed grid (the adaptive grid of the start at rtol 1e-6), in the same variables
(A_0..A_K, B_2..B_K, log T; B_1 = 0), from the same random start (A0, A1 uniform on
(0, 1), the rest zero; scaled period 2).  The baseline is
``scipy.optimize.minimize(method="BFGS")`` with its own finite-difference gradient.
Prints seconds per optimisation, gradient evaluations per second and the final
objective of both, then one JSON line.  Each optimiser is run ``--repeats`` times (both
are deterministic) and its median time is reported: wall times on a shared VM varied by
+-25 % from run to run.

Which local optimum a BFGS run ends in depends on its path, so from one start either
optimiser can end higher.  ``--seeds N`` repeats the comparison from N starts (seeds S,
S + 1, ...) and the JSON line then holds the medians of the times and speed-ups, the
per-start values and how many starts each optimiser ended higher.
"""
from __future__ import annotations

import argparse
import json
import math
import sys

import numpy as np
import scipy.optimize

from ..adjoint.gradient import adaptive_grid, discrete_objective, with_family_parameters, with_period
from ..model.kinematics import Fourier
from ..adjoint.optimize import Problem, optimize_motion, variables
from ..model.physics import Physics
from .bench import repeat_timed


def _runs(runs):
    return "median of " + ", ".join(f"{r:.2f}" for r in runs) if len(runs) > 1 else "1 run"


def compare(seed, kmax, ratio_log2, gtol, repeats=1):
    """One start: our optimiser and scipy's BFGS with differences on the same objective,
    each timed ``repeats`` times (median)."""
    rng = np.random.default_rng(seed)
    A = np.zeros((1, kmax + 1))
    A[0, :2] = rng.uniform(0.0, 1.0, 2)
    template = Fourier(A, np.zeros((1, kmax)))
    physics = Physics.from_scaled(2.0 ** ratio_log2, 2.0)
    grid = adaptive_grid(template, physics, rtol=1e-6)
    # warm the compiled kernels outside the timings
    optimize_motion(template, physics, grid=grid, max_iterations=1)
    print(f"seed {seed}: Kmax = {kmax}, mu_n/mu_s = 2^{ratio_log2:g}, start A0 = {A[0, 0]:.4f}, "
          f"A1 = {A[0, 1]:.4f}, fixed grid of {grid.n_steps} steps")

    ours, seconds, runs = repeat_timed(lambda: optimize_motion(
        template, physics, grid=grid, gtol=gtol, max_iterations=2000), repeats)
    print(f"  adjoint BFGS/Newton: {seconds:.2f} s ({_runs(runs)}), {ours.iterations} iterations "
          f"({ours.newton_steps} Newton), {ours.solves} solves and {ours.gradient_evaluations} "
          f"adjoint gradients ({ours.gradient_evaluations / seconds:.1f}/s), "
          f"|grad| = {ours.gradient_norm:.2e}, "
          f"stop: {ours.stop_reason}, lambda = {ours.efficiency:.10f}")

    names, full, free, lower, upper = variables(template, physics, None)
    problem = Problem(template, physics, grid, "efficiency", -1.0, free, full, lower[free],
                      upper[free])
    sign = math.copysign(1.0, ours.efficiency)
    counts = {"objective": 0}
    state = {"u0": None}

    def fun(x):
        counts["objective"] += 1
        full_x = problem.full(x)
        value, _, _, _, status, u0 = discrete_objective(
            with_family_parameters(template, full_x[:-1]), with_period(physics, full_x[-1]),
            grid, u0=state["u0"])
        if status != 0 or not math.isfinite(value):
            return 1e3  # outside the solvable region: a barrier
        state["u0"] = u0
        return -sign * value

    x0 = full[free].copy()
    x0[-1] = math.log(full[-1])

    def baseline():
        counts["objective"] = 0
        state["u0"] = None
        return scipy.optimize.minimize(fun, x0, method="BFGS", options={"gtol": gtol,
                                                                         "maxiter": 2000})

    base, baseline_seconds, runs = repeat_timed(baseline, repeats)
    baseline_objective = -sign * base.fun
    n_grad = getattr(base, "njev", base.nit + 1)
    print(f"  scipy BFGS + differences: {baseline_seconds:.2f} s ({_runs(runs)}), "
          f"{base.nit} iterations, "
          f"{counts['objective']} objective evaluations (~{n_grad / baseline_seconds:.1f} "
          f"gradients/s), stop: {base.message}, lambda = {baseline_objective:.10f}")
    speedup = baseline_seconds / seconds
    print(f"  speedup {speedup:.1f}x; objective difference (ours - baseline in |lambda|) "
          f"{abs(ours.efficiency) - abs(baseline_objective):.3e}")
    return dict(seconds=seconds, baseline_seconds=baseline_seconds, speedup=speedup,
                objective=ours.efficiency, baseline_objective=baseline_objective)


def main(argv=None):
    parser = argparse.ArgumentParser(prog="python -m solver.tools.bench_optimize", description=__doc__)
    parser.add_argument("--seed", type=int, default=1)
    parser.add_argument("--seeds", type=int, default=1,
                        help="number of starts (seed, seed + 1, ...)")
    parser.add_argument("--kmax", type=int, default=7)
    parser.add_argument("--ratio-log2", type=float, default=-4.0)
    parser.add_argument("--gtol", type=float, default=1e-7)
    parser.add_argument("--repeats", type=int, default=3,
                        help="timed runs of each optimiser per start (median reported)")
    args = parser.parse_args(argv)
    if args.seeds < 1:
        parser.error(f"--seeds: must be >= 1, got {args.seeds}")
    if args.repeats < 1:
        parser.error(f"--repeats: must be >= 1, got {args.repeats}")
    runs = [compare(args.seed + k, args.kmax, args.ratio_log2, args.gtol, args.repeats)
            for k in range(args.seeds)]
    if len(runs) == 1:
        print(json.dumps(runs[0]))
        return 0
    higher = sum(abs(r["objective"]) > abs(r["baseline_objective"]) for r in runs)
    summary = {key: float(np.median([r[key] for r in runs]))
               for key in ("seconds", "baseline_seconds", "speedup")}
    print(f"{len(runs)} starts: median speedup {summary['speedup']:.1f}x; ours ended higher "
          f"from {higher}, scipy from {len(runs) - higher}")
    print(json.dumps({**summary, "objective": [r["objective"] for r in runs],
                      "baseline_objective": [r["baseline_objective"] for r in runs],
                      "speedups": [r["speedup"] for r in runs], "seeds": args.seeds,
                      "ours_higher": higher}))
    return 0


if __name__ == "__main__":
    sys.exit(main())
