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
    def error(self, message):  # one line, exit 2, no usage dump; "argument --x: ..." -> "--x: ..."
        raise _UsageError(message.removeprefix("argument "))


def _finite(text):
    """A finite number (argparse names the option in the message)."""
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a number, got {text!r}") from None
    if not math.isfinite(value):
        raise argparse.ArgumentTypeError(f"expected a finite number, got {text!r}")
    return value


def _float_list(text):
    """Comma-separated finite numbers: '0.6,0.9,0,0.2'."""
    try:
        return [_finite(x) for x in text.split(",") if x.strip() != ""]
    except argparse.ArgumentTypeError:
        raise argparse.ArgumentTypeError(f"expected comma-separated numbers such as 0.6,0.9,0.2, got {text!r}") from None


_STROKE_FORMS = "'down:G', 'up:G' or G (an exponent G >= 1; G alone is concave down, 1 linear)"


def _stroke(text):
    """'down:10', 'up:3', or a bare exponent (1 is linear; a bare value means concave down):
    (concave_up, exponent)."""
    concavity, _, exponent = text.rpartition(":")
    try:
        value = float(exponent)
    except ValueError:
        value = math.nan
    if concavity not in ("", "down", "up") or not math.isfinite(value) or value < 1:
        raise argparse.ArgumentTypeError(f"expected {_STROKE_FORMS}, got {text!r}")
    return concavity == "up", value


def build_parser():
    from ._version import VersionAction

    parser = _Parser(prog="python -m solver", description=__doc__,
                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--version", action=VersionAction)
    sub = parser.add_subparsers(dest="command", required=True, parser_class=_Parser)
    pt = sub.add_parser("point", help="solve one parameter point and print JSON",
                        description="Solve one parameter point of eq. (Newtonu) and print one JSON object. "
                                    "Angles in rad; the period T and friction coefficients as in the paper.")
    pt.add_argument("--family", required=True, choices=["harmonic", "powerlaw", "fourier"],
                    help="kinematic family of phi(tau): harmonic (--A0, --A1), powerlaw (--A0, --A1, --tau0, "
                         "--closing, --opening) or fourier (--A, --B) (required)")
    pt.add_argument("--A0", type=_finite, metavar="RAD",
                    help="mean half-opening angle A0 [rad] (harmonic, powerlaw; required for them)")
    pt.add_argument("--A1", type=_finite, metavar="RAD",
                    help="amplitude A1 >= 0 [rad]: phi swings between A0 - A1 and A0 + A1 (harmonic, powerlaw; "
                         "required for them)")
    pt.add_argument("--tau0", type=_finite, metavar="TAU0",
                    help="duty cycle tau0 in (0, 1), the closing phase's share of the period (powerlaw; required)")
    pt.add_argument("--closing", type=_stroke, default=(False, 1.0), metavar="SHAPE",
                    help=f"closing stroke's power law (powerlaw): {_STROKE_FORMS} (default: 1, linear)")
    pt.add_argument("--opening", type=_stroke, default=(False, 1.0), metavar="SHAPE",
                    help=f"opening stroke's power law (powerlaw): {_STROKE_FORMS} (default: 1, linear)")
    pt.add_argument("--A", type=_float_list, metavar="A0,...,AK",
                    help="cosine coefficients A0..AK [rad] (fourier; required)")
    pt.add_argument("--B", type=_float_list, default=[], metavar="B1,...,BK",
                    help="sine coefficients B1..BK [rad], one fewer than --A (fourier; default: none, K = 0)")
    pt.add_argument("--T", type=_finite, required=True, help="period T > 0 (required)")
    pt.add_argument("--mu-n", dest="mu_n", type=_finite, required=True, metavar="MU_N",
                    help="normal friction coefficient mu_n > 0 (required)")
    pt.add_argument("--mu-s", dest="mu_s", type=_finite, required=True, metavar="MU_S",
                    help="tangential friction coefficient mu_s > 0 (required)")
    pt.add_argument("--p", type=_finite, default=0.0,
                    help="force-law exponent p in [0, 2): 0 Coulomb friction, else |v|^p (default: 0)")
    pt.add_argument("--delta", type=_finite, default=1e-5,
                    help="velocity regularisation delta >= 0, > 0 when p = 0 (default: 1e-5)")
    pt.add_argument("--method", choices=list(_solve.METHODS), default="periodic",
                    help="periodic: the engine; march: its independent check (default: periodic)")
    pt.add_argument("--rtol", type=_finite, default=1e-6,
                    help="target relative error of U and P, in (0, 1) (default: 1e-6)")
    pt.add_argument("--series", action="store_true",
                    help="also print tau and u(tau) at the final steps' nodes, tau = 0 .. 1 (default: off)")
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
