"""Paired A/B of the engine's throughput between this checkout and another, in one sitting.

Run as ``python -m solver.tools.bench_ab OTHER [--rounds 20] [--points 2000] [--seed 0]
[--threads N]``, where ``OTHER`` is the root of another checkout of this project (the
baseline, "a"; this checkout is "b").

Why not two ``python -m solver.tools.bench`` runs.  On a shared VM the wall time of one
batched call varies by +-25 % from call to call, and drifts over minutes; each bench run
quotes the median of a few calls, so the ratio of two runs carries that drift.  Measured on
the 2-core VM (docs/validation.md, "The bench A/B"): 8 process pairs of the bench read
main/c1e8687 0.956 at rtol 1e-4 by the pairs' medians and 1.033 by the medians of all their
calls pooled.

What is measured.  Two long-lived processes, one per checkout (``PYTHONPATH`` on it, its
own numba cache under ``NUMBA_CACHE_DIR`` if set, else numba's default), each draws the
bench's points (``solver.tools.bench.draw_points``, ``--points``, ``--seed``; the draws'
digest must agree, else exit 2) and compiles or loads its kernels on 4 of them.  Then, per
rtol of the bench (1e-4, 1e-7), ``--rounds`` rounds of four calls of ``solve_periodic`` on
all points, in the order a b b a or b a a b (alternating), so every call of one side has a
call of the other next to it in time.  Per call: wall (``perf_counter``) and the process's
CPU (``process_time``) around ``solve_periodic`` alone.

Reported per rtol: each side's median and minimum wall time, the speed ratio b/a (a's median
wall / b's), the paired ratio (median over calls of a's wall / b's adjacent wall) with a
95 % bootstrap interval (2,000 resamples of the calls), the CPU ratio, and the failures
(status != 0) of each side, which must be equal for the comparison to mean anything.  The
last line is one JSON object.  A ratio above 1 means this checkout is faster.  Nothing is
judged here: the thresholds belong to whoever asks (issue 37: within 5 %).
"""
from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np

RTOLS = (1e-4, 1e-7)
BOOTSTRAP = 2000

#: the timing server each side runs (its own checkout's solver and bench points)
SERVER = r"""
import hashlib, sys, time
import numpy as np
import solver
from solver.tools import bench
n, seed = int(sys.argv[1]), int(sys.argv[2])
kin, phys, table = bench.draw_points(n, np.random.default_rng(seed))
digest = hashlib.sha256(np.stack([table[k] for k in sorted(table)]).tobytes()).hexdigest()
warm = bench.subset(kin, phys, np.arange(min(4, n)))
for rtol in (1e-4, 1e-7):
    solver.solve_periodic(*warm, rtol=rtol)
print("ready", digest, flush=True)
for line in sys.stdin:
    rtol = float(line)
    t0, c0 = time.perf_counter(), time.process_time()
    result = solver.solve_periodic(kin, phys, rtol=rtol)
    wall, cpu = time.perf_counter() - t0, time.process_time() - c0
    print(f"{wall:.6f} {cpu:.6f} {int(np.count_nonzero(result.status != 0))}", flush=True)
"""


class _Side:
    """One checkout's timing server."""

    def __init__(self, root, n_points, seed, threads):
        env = dict(os.environ, PYTHONPATH=str(root))
        if threads:
            env["NUMBA_NUM_THREADS"] = str(threads)
        self.root = str(root)
        self.proc = subprocess.Popen([sys.executable, "-c", SERVER, str(n_points), str(seed)],
                                     cwd=tempfile.gettempdir(), env=env,
                                     stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True)

    def ready(self):
        line = self.proc.stdout.readline().split()
        if len(line) != 2 or line[0] != "ready":
            raise RuntimeError(f"{self.root}: the timing server did not start "
                               f"(exit {self.proc.wait()})")
        return line[1]

    def call(self, rtol):
        self.proc.stdin.write(f"{rtol!r}\n")
        self.proc.stdin.flush()
        wall, cpu, failures = self.proc.stdout.readline().split()
        return float(wall), float(cpu), int(failures)

    def close(self):
        if self.proc.stdin:
            self.proc.stdin.close()
        self.proc.wait()


def paired_summary(wall_a, wall_b, cpu_a, cpu_b, seed=1):
    """The figures of one rtol from the calls' wall and CPU seconds (equal-length arrays, call
    i of a adjacent in time to call i of b)."""
    wall_a, wall_b = np.asarray(wall_a), np.asarray(wall_b)
    ratio = wall_a / wall_b  # > 1: b faster
    rng = np.random.default_rng(seed)
    boot = np.median(rng.choice(ratio, (BOOTSTRAP, ratio.size)), axis=1)
    return dict(calls=int(ratio.size),
                median_wall_a=float(np.median(wall_a)), median_wall_b=float(np.median(wall_b)),
                min_wall_a=float(wall_a.min()), min_wall_b=float(wall_b.min()),
                speed_ratio=float(np.median(wall_a) / np.median(wall_b)),
                paired_speed_ratio=float(np.median(ratio)),
                paired_ci95=[float(np.percentile(boot, 2.5)), float(np.percentile(boot, 97.5))],
                cpu_ratio=float(np.median(cpu_a) / np.median(cpu_b)))


def run(other, rounds, n_points, seed, threads=None, echo=print):
    here = Path(__file__).resolve().parents[2]
    a, b = _Side(other, n_points, seed, threads), _Side(here, n_points, seed, threads)
    try:
        digests = a.ready(), b.ready()
        if digests[0] != digests[1]:
            raise ValueError(f"OTHER: {other} draws other bench points (seed {seed}) than this "
                             f"checkout; the two would not solve the same problems")
        out = dict(a=str(Path(other).resolve()), b=str(here), points=n_points, seed=seed,
                   rounds=rounds)
        for rtol in RTOLS:
            calls = {"a": [], "b": []}
            for r in range(rounds):
                for side in ("abba" if r % 2 == 0 else "baab"):
                    calls[side].append((a if side == "a" else b).call(rtol))
            wall_a, cpu_a, fail_a = map(np.array, zip(*calls["a"]))
            wall_b, cpu_b, fail_b = map(np.array, zip(*calls["b"]))
            row = paired_summary(wall_a, wall_b, cpu_a, cpu_b)
            row.update(failures_a=int(fail_a[0]), failures_b=int(fail_b[0]))
            out[f"rtol_{rtol:g}"] = row
            lo, hi = row["paired_ci95"]
            echo(f"rtol {rtol:g}: a median {row['median_wall_a']:.4f} s (min "
                 f"{row['min_wall_a']:.4f}), b median {row['median_wall_b']:.4f} s (min "
                 f"{row['min_wall_b']:.4f}); speed b/a {row['speed_ratio']:.3f}, paired "
                 f"{row['paired_speed_ratio']:.3f} (95 % {lo:.3f}-{hi:.3f}), CPU a/b "
                 f"{row['cpu_ratio']:.3f}; failures {row['failures_a']} / {row['failures_b']}")
        return out
    finally:
        a.close()
        b.close()


def _parser():
    parser = argparse.ArgumentParser(prog="python -m solver.tools.bench_ab",
                                     description=__doc__.split("\n\n")[0])
    parser.add_argument("other", help="root of the baseline checkout (a)")
    parser.add_argument("--rounds", type=int, default=20, help="rounds of 4 calls per rtol")
    parser.add_argument("--points", type=int, default=2000)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--threads", type=int, default=None,
                        help="NUMBA_NUM_THREADS of both sides (default: numba's)")
    return parser


def main(argv=None) -> int:
    args = _parser().parse_args(argv)
    for name, value in (("--rounds", args.rounds), ("--points", args.points)):
        if value < 1:
            print(f"error: {name}: must be >= 1, got {value}", file=sys.stderr)
            return 2
    if args.threads is not None and args.threads < 1:
        print(f"error: --threads: must be >= 1, got {args.threads}", file=sys.stderr)
        return 2
    if not (Path(args.other) / "solver" / "__init__.py").is_file():
        print(f"error: other: not a checkout of this project (no solver/ package): {args.other}",
              file=sys.stderr)
        return 2
    try:
        out = run(args.other, args.rounds, args.points, args.seed, args.threads)
    except ValueError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    print(json.dumps(out))
    return 0


if __name__ == "__main__":
    sys.exit(main())
