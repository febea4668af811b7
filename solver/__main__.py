"""Single-point command: ``python -m solver point --family harmonic --A0 1.2 --A1 0.3 --T 1 ...``.

Prints one JSON object on stdout.  Bad input: one line on stderr naming the
argument, exit code 2.  ``seconds`` is the solve alone; the kernels are compiled (first run of
a checkout) or loaded from numba's on-disk cache before it, and that time is reported apart, as
``compile_seconds``, with ``kernels_compiled`` (0: every kernel came from the cache).
"""
from __future__ import annotations

import argparse
import json
import math
import sys
import time

from . import solve as _solve


class _UsageError(Exception):
    pass


class _Parser(argparse.ArgumentParser):
    def error(self, message):  # one line, exit 2, no usage dump
        raise _UsageError(message)


def _finite(name):
    def convert(text):
        try:
            value = float(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"{name}: not a number: {text!r}")
        if not math.isfinite(value):
            raise argparse.ArgumentTypeError(f"{name}: must be finite, got {text}")
        return value
    return convert


def _float_list(name):
    def convert(text):
        return [_finite(name)(x) for x in text.split(",") if x.strip() != ""]
    return convert


def _stroke(name):
    """'down:10', 'up:3', or a bare exponent (1 is linear; a bare value means concave down)."""
    def convert(text):
        concavity, _, exponent = text.rpartition(":")
        if concavity not in ("", "down", "up"):
            raise argparse.ArgumentTypeError(f"{name}: concavity must be 'down' or 'up', got {concavity!r}")
        value = _finite(name)(exponent)
        if value < 1:
            raise argparse.ArgumentTypeError(f"{name}: exponent must be >= 1, got {value}")
        return concavity == "up", value
    return convert


def build_parser():
    from ._version import VersionAction

    parser = _Parser(prog="python -m solver", description=__doc__)
    parser.add_argument("--version", action=VersionAction)
    sub = parser.add_subparsers(dest="command", required=True)
    pt = sub.add_parser("point", help="solve one parameter point and print JSON")
    pt.error = parser.error
    pt.add_argument("--family", required=True, choices=["harmonic", "powerlaw", "fourier"])
    pt.add_argument("--A0", type=_finite("--A0"))
    pt.add_argument("--A1", type=_finite("--A1"))
    pt.add_argument("--tau0", type=_finite("--tau0"), help="duty cycle (powerlaw)")
    pt.add_argument("--closing", type=_stroke("--closing"), default=(False, 1.0))
    pt.add_argument("--opening", type=_stroke("--opening"), default=(False, 1.0))
    pt.add_argument("--A", type=_float_list("--A"), help="A0,...,AK (fourier)")
    pt.add_argument("--B", type=_float_list("--B"), default=[], help="B1,...,BK (fourier)")
    pt.add_argument("--T", type=_finite("--T"), required=True)
    pt.add_argument("--mu-n", dest="mu_n", type=_finite("--mu-n"), required=True)
    pt.add_argument("--mu-s", dest="mu_s", type=_finite("--mu-s"), required=True)
    pt.add_argument("--p", type=_finite("--p"), default=0.0)
    pt.add_argument("--delta", type=_finite("--delta"), default=1e-5)
    pt.add_argument("--method", choices=list(_solve.METHODS), default="periodic")
    pt.add_argument("--rtol", type=_finite("--rtol"), default=1e-6)
    pt.add_argument("--series", action="store_true", help="include tau and u(tau)")
    return parser


def _kinematics(args):
    import solver

    def need(*names):
        for name in names:
            if getattr(args, name) is None:
                raise _UsageError(f"--{name}: required for --family {args.family}")

    if args.family == "harmonic":
        need("A0", "A1")
        if args.A1 < 0:
            raise _UsageError("--A1: amplitude must be >= 0")
        return solver.Harmonic(args.A0, args.A1)
    if args.family == "powerlaw":
        need("A0", "A1", "tau0")
        if args.A1 < 0:
            raise _UsageError("--A1: amplitude must be >= 0")
        if not 0 < args.tau0 < 1:
            raise _UsageError(f"--tau0: duty cycle must lie in (0, 1), got {args.tau0}")
        (c_up, c_exp), (o_up, o_exp) = args.closing, args.opening
        return solver.PowerLaw(args.A0, args.A1, args.tau0, c_exp, c_up, o_exp, o_up)
    need("A")
    if len(args.A) < 1:
        raise _UsageError("--A: needs at least A0")
    if len(args.B) != len(args.A) - 1:
        raise _UsageError(f"--B: expected {len(args.A) - 1} sine coefficients (one fewer than --A), "
                          f"got {len(args.B)}")
    return solver.Fourier([args.A], [args.B])


def _check_physics(args):
    if args.T <= 0:
        raise _UsageError(f"--T: period must be > 0, got {args.T}")
    for flag, value in (("--mu-n", args.mu_n), ("--mu-s", args.mu_s)):
        if value <= 0:
            raise _UsageError(f"{flag}: friction coefficient must be > 0, got {value}")
    if not 0 <= args.p < 2:
        raise _UsageError(f"--p: force-law exponent must lie in [0, 2), got {args.p}")
    if args.delta < 0 or (args.delta == 0 and args.p == 0):
        raise _UsageError(f"--delta: must be >= 0, and > 0 when p = 0; got {args.delta}")
    if not 0 < args.rtol < 1:
        raise _UsageError(f"--rtol: must lie in (0, 1), got {args.rtol}")


def _timed_solve(kin, phys, args):
    """(result, seconds of the solve alone, ``WarmUp`` of the kernels' compile or load).

    The method's kernels are compiled or loaded first (``solver.warm_up``), outside the timed
    solve. Should the solve still compile a kernel (a specialisation the warm-up missed), it is
    solved again and the second solve is the one timed; the first's extra time counts as compile.
    """
    import solver
    from ._warmup import WarmUp, compiled_count

    kernels = solver.warm_up((args.method,))
    for attempt in range(2):
        before, start = compiled_count(), time.perf_counter()
        res = solver.solve_periodic(kin, phys, method=args.method, rtol=args.rtol, return_series=args.series)
        seconds = time.perf_counter() - start
        compiled = compiled_count() - before
        if compiled == 0:
            return res, seconds, kernels
        first = seconds
        kernels = WarmUp(kernels.kernel_sets, kernels.seconds, kernels.compiled + compiled)
    return res, seconds, WarmUp(kernels.kernel_sets, kernels.seconds + max(first - seconds, 0.0), kernels.compiled)


def run_point(args):
    import numpy as np

    import solver

    _check_physics(args)
    try:
        kin = _kinematics(args)
    except ValueError as exc:
        raise _UsageError(f"--{exc}") from None
    phys = solver.Physics(period=args.T, mu_n=args.mu_n, mu_s=args.mu_s, p=args.p, delta=args.delta)
    res, seconds, kernels = _timed_solve(kin, phys, args)
    out = res.point(0)
    out["status"] = int(out["status"])
    out["reason"] = solver.status_reason(out["status"], args.method)
    out["seconds"] = seconds
    out["compile_seconds"] = kernels.seconds
    out["kernels_compiled"] = kernels.compiled
    out["method"] = args.method
    out["anisotropy_ratio"], out["scaled_period"] = (
        float(x[0]) for x in solver.scaled_from_physical(phys.period, phys.mu_n, phys.mu_s, phys.p))
    if args.series:
        out["tau"] = np.asarray(res.tau[0]).tolist()
        out["u"] = np.asarray(res.u[0]).tolist()
    return {k: (None if isinstance(v, float) and not math.isfinite(v) else v) for k, v in out.items()}


def main(argv=None):
    try:
        args = build_parser().parse_args(argv)
        result = run_point(args)
    except _UsageError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    print(json.dumps(result))
    return 0 if result["converged"] else 1


if __name__ == "__main__":
    sys.exit(main())
