"""Honesty harness: is each periodic engine's error estimate true?

Run as ``python -m solver.tools.honesty [--method M ...] [--set S ...] [--rtol R ...] [--points N]
[--refresh] [--reuse-references] [--reference-method periodic] [--reference-rtol 1e-9] [--check-method M]
[--check-rtol R] [--agreement 0.1] [--cache-dir out/honesty] [--sweeps]``.

With ``--sweeps`` the engine solves each set as warm-started sweeps
(``solve_periodic(..., sweeps=...)``) of ``solver.SWEEP_POINTS`` in a neighbour order
(``neighbour_order``), so that the warm path meets the same standard as cold solves.

A solve that returns status 0 claims an error of at most ``rtol`` in the solver's norm
(``error_estimate`` <= rtol, see ``solver.solve``).  This harness solves seeded sets of
parameter points with each engine at each rtol, on the same points in one run, and measures
the true error against references.  Everything is batched: one ``solve_periodic`` call per
(set, method, rtol).

Sets
----
``SETS``: the stress sweeps earlier sessions ran by hand, rebuilt as seeded generators (the
points those sessions named are not reproduced by index); each ``PointSet`` carries its
generator's parameters, printed above its table.  400 points each, seeded:
``harmonic_extreme`` (mu_n/mu_s 2^+-12, scaled period 2^-4 .. 2^6, delta to 1e-10),
``stress_powerlaw_21`` / ``_22`` / ``_23`` (power laws, exponents 1 .. 12, same ranges),
``long_period_powerlaw`` (scaled period 2^4 .. 2^8, delta 10^U(-10, -5)),
``fourier_clapping`` (K = 4; phi leaves (0, pi) on 60 % of the points), ``p0.5_harmonic``
and ``p1.5_fourier`` (half of them at delta = 0), ``short_period_harmonic`` (scaled period
2^-7 .. 2^-1), ``flat_inflection_fourier`` (sin^3 motions: omega vanishes at tau = 0, 1/2
without changing sign; scaled period 2^-7 .. 1); and ``tools.bench``, the 2,000 points of
``python -m solver.tools.bench``.

Error norm
----------
The solver's own (``solver.tools.bench.solution_error``): e = max(e_U, e_P) with
e_U = |U - U_ref| T / max(|U_ref| T, 1e-3 V) (``relative_u_error``, V =
``solver.kinematic_speed``) and e_P = |P - P_ref| / |P_ref|; ``error_estimate`` promises
that maximum.

References
----------
By default the harness judges against frozen references (``--reference-method frozen``):
``honesty_references.npz`` beside this module holds, for every point of every set, U, P and
status of the reference (the former order-3 engine, then ``periodic``, at rtol 1e-9) and of
its cross-check (the order-5 engine, now ``periodic``, at rtol 1e-9), with the commit,
seeds, settings and each set's largest disagreement (``freeze``; ``python -m solver.tools.honesty
--freeze`` made it, in 2 h 20 min on 2 shared cores).  So the engine never checks itself,
and a fresh clone judges in minutes.  A set whose generator changed is refused (its points'
signature no longer matches within
``SIGNATURE_RTOL``) until it is frozen again.

With ``--reference-method METHOD`` every point is instead solved now by that engine (rtol
``--reference-rtol``, default 1e-9) and cross-checked by a second method (default the
explicit ``march`` at 1e-7; ``--check-method none`` skips it), cached under ``--cache-dir``.  Where the stiff friction makes the march unstable it says so (status UNSTABLE),
and the point keeps one reference: on the first 24 points of each set it converged at 1e-7
on 112 of 240 and at 1e-8 on 54 (none of the long periods, 3-8 of 24 of the stress power
laws), disagreeing with the reference by at most 6.3e-8 and 5.6e-9 (medians 1.3e-8 and
1.1e-9); 1e-7 is the default for twice the points confirmed, at the same cost.  The
disagreement d of the two, in the norm above, decides at each judged rtol r:

- reference failed: the reference engine's status != 0 or its U or P non-finite;
- reference uncertain at r: both converged and d > ``agreement`` r (default 0.1 r: 1e-8 at
  rtol 1e-7, so with the march at 1e-7 as the check about half of the cross-checked points
  are uncertain at rtol 1e-7, and none at 1e-3 .. 1e-6);
- single reference: the check failed (or was skipped); judged on the reference alone;
- otherwise judged.

Points not judged are counted and printed per set (and per rtol), never dropped silently.
References are cached under ``--cache-dir`` (default ``out/honesty``), one file per
(set, points, seed, method, rtol, hash of the solver's engine sources: every
``solver/*.py`` but the harness and benchmarks), holding the points' parameters, which must
match on reading; ``--refresh`` recomputes.  Any edit in solver/ changes the digest;
``--reuse-references`` then takes the newest cached references of the same points made by
an earlier version (each set's header line says which), instead of two hours of
recomputing them: for iterating on one engine, not for judging a change to the reference
or check method itself.

Outcomes of one solve of a judged point at rtol r
-------------------------------------------------
- failure: status != 0 (an honest NaN with a reason code; counted by code, and counted
  over all points, judged or not, since it needs no reference);
- within rtol: status 0 and e <= r; within 10 rtol: status 0 and e <= 10 r;
- silent failure: status 0 and (U or P non-finite, on any point, or e > 10 r on a judged
  point): a converged status whose number is wrong beyond ten times its tolerance.

Shares are over all judged solves: a failed solve counts as outside rtol.  ``worst`` is the
largest e / r over the judged converged solves.

Output
------
Per set a header (generator, references, their cost, points not judged) and a table of
(method, rtol): judged solves, % within rtol, % within 10 rtol, worst e / rtol, failures by
code, silent failures, mean / median n_tau of the converged, wall seconds of the batched
call; then one line per point outside rtol or failed, with its parameters.  The last line
is one JSON object: ``methods`` (per method, over every set and rtol: ``within_rtol`` and
``within_10_rtol`` shares, ``worst_over_rtol``, ``silent_failures``, ``failures``, ``solves``
(judged solves), ``solves_total``), ``sets`` (per set: references and, per method and rtol,
the same figures) and ``settings``.
"""
from __future__ import annotations

import argparse
import hashlib
import json
import math
import sys
import time
from dataclasses import dataclass, fields
from pathlib import Path
from typing import Callable

import numpy as np

import solver
from solver.tools.bench import (DEFAULT_POINTS as BENCH_POINTS, DEFAULT_SEED as BENCH_SEED,
                          draw_points, json_value, solution_error, status_counts)

RTOLS = (1e-3, 1e-4, 1e-5, 1e-6, 1e-7)
REFERENCE_METHOD = "periodic"
REFERENCE_RTOL = 1e-9
#: the cross-check when there is no second implicit engine: the explicit march converges at
#: 1e-7 on 112 of 240 probe points (24 per set), at 1e-8 on 54 (module docstring); on the
#: full sets it cost 4-26x the reference (2 cores, shared machine)
MARCH_CHECK_RTOL = 1e-7
#: references must agree within this share of the judged rtol
AGREEMENT = 0.1
SET_POINTS = 400
WARMUP_POINTS = 4
DEFAULT_CACHE = Path("out") / "honesty"
#: the frozen references (``freeze``): every set's every point, committed with the package
REFERENCE_FILE = Path(__file__).with_name("honesty_references.npz")
#: ``--reference-method`` that judges against REFERENCE_FILE (the default)
FROZEN = "frozen"
#: outcome of a point's references
JUDGED, SINGLE, FAILED = 0, 1, 2


# ----------------------------------------------------------------------------- point sets

def _log2_uniform(rng, low, high, n):
    return 2.0 ** rng.uniform(low, high, n)


def _harmonic(n, rng):
    A0 = 0.5 * np.pi * (1.0 - rng.random(n))      # (0, pi/2]
    return solver.Harmonic(A0, A0 * (1.0 - rng.random(n)))  # A1 / A0 in (0, 1]


def _power_law(n, rng):
    A0 = rng.uniform(0.2, np.pi - 0.2, n)
    A1 = np.minimum(A0, np.pi - A0) * (1.0 - rng.random(n))  # phi within (0, pi)
    duty = rng.uniform(0.05, 0.95, n)
    closing, opening = (_log2_uniform(rng, 0.0, math.log2(12.0), n) for _ in range(2))
    closing_up, opening_up = (rng.random(n) < 0.5 for _ in range(2))
    return solver.PowerLaw(A0, A1, duty, closing, closing_up, opening, opening_up)


def _fourier(n, rng, K=4, size=0.8):
    A0 = rng.uniform(0.0, np.pi, n)
    A = np.column_stack([A0] + [rng.uniform(-size, size, n) / k for k in range(1, K + 1)])
    B = np.column_stack([rng.uniform(-size, size, n) / k for k in range(1, K + 1)])
    return solver.Fourier(A, B)


def _physics(rng, n, ratio_log2, period_log2, deltas=None, delta_log10=None, p=0.0):
    ratio = _log2_uniform(rng, -ratio_log2, ratio_log2, n)
    period = _log2_uniform(rng, *period_log2, n)
    delta = (rng.choice(np.asarray(deltas), n) if deltas is not None
             else 10.0 ** rng.uniform(*delta_log10, n))
    return solver.Physics.from_scaled(ratio, period, p=p, delta=delta)


STIFF_DELTAS = (1e-5, 1e-8, 1e-10)


def _harmonic_extreme(n, rng):
    kin = _harmonic(n, rng)
    return kin, _physics(rng, n, 12, (-4, 6), STIFF_DELTAS)


def _stress_power_law(n, rng):
    kin = _power_law(n, rng)
    return kin, _physics(rng, n, 12, (-4, 6), STIFF_DELTAS)


def _long_period_power_law(n, rng):
    kin = _power_law(n, rng)
    return kin, _physics(rng, n, 12, (4, 8), delta_log10=(-10, -5))


def _fourier_clapping(n, rng):
    kin = _fourier(n, rng)
    return kin, _physics(rng, n, 8, (-3, 3), (1e-5, 1e-8))


def _harmonic_p05(n, rng):
    kin = _harmonic(n, rng)
    return kin, _physics(rng, n, 8, (-4, 4), (1e-5, 0.0), p=0.5)


def _fourier_p15(n, rng):
    kin = _fourier(n, rng)
    return kin, _physics(rng, n, 8, (-3, 3), (1e-5, 0.0), p=1.5)


def _short_period_harmonic(n, rng):
    A0 = rng.uniform(0.3, 0.5 * np.pi, n)
    kin = solver.Harmonic(A0, A0 * rng.uniform(0.2, 0.95, n))
    return kin, _physics(rng, n, 8, (-7, -1), (1e-5, 1e-8))


def _flat_inflection_fourier(n, rng):
    """phi = A0 + c sin^3(2 pi tau) (B_1 = 3c/4, B_3 = -c/4: flat inflections at tau = 0, 1/2,
    where omega vanishes without changing sign) plus small terms of wavenumbers 2 and 4."""
    A0 = rng.uniform(0.5, np.pi - 0.5, n)
    c = rng.uniform(0.3, 1.2, n) * rng.choice([-1.0, 1.0], n)
    small = rng.uniform(-0.02, 0.02, (n, 4))
    zero = np.zeros(n)
    A = np.column_stack([A0, zero, small[:, 0], zero, small[:, 1]])
    B = np.column_stack([0.75 * c, small[:, 2], -0.25 * c, small[:, 3]])
    kin = solver.Fourier(A, B)
    return kin, _physics(rng, n, 8, (-7, 0), (1e-5, 1e-8))


#: the power-law shapes of the paper's grid scenes (``workflows/power_law.toml``): exponent,
#: concave up
PAPER_SHAPES = ((10.0, False), (3.0, False), (1.0, False), (3.0, True), (10.0, True))


def _paper_power_law(n, rng):
    """The paper's power-law grids (``power_law``, ``exponent_sets``) drawn at random: shapes
    from PAPER_SHAPES, duty cycle 0.1 .. 0.9, A0 in (0, pi/2], A1/A0 in (0, 1); half of the
    points with a concave-up closing (exponent 3 or 10) and a linear opening, where the
    order-5 engine once exceeded its step budget (a linear phase's omega' = 0 on every sample
    made each a turning stop)."""
    A0 = 0.5 * np.pi * (1.0 - rng.random(n))
    A1 = A0 * (1.0 - rng.random(n))
    duty = rng.uniform(0.1, 0.9, n)
    shapes = np.asarray(PAPER_SHAPES)
    closing = shapes[rng.integers(0, len(PAPER_SHAPES), n)]
    opening = shapes[rng.integers(0, len(PAPER_SHAPES), n)]
    steep = rng.random(n) < 0.5
    closing[steep] = shapes[rng.integers(3, 5, int(steep.sum()))]
    opening[steep] = shapes[2]
    kin = solver.PowerLaw(A0, A1, duty, closing[:, 0], closing[:, 1] > 0.5, opening[:, 0],
                          opening[:, 1] > 0.5)
    return kin, _physics(rng, n, 6, (-3, 3), (1e-5,))


def _bench(n, rng):
    kinematics, physics, _ = draw_points(n, rng)
    return kinematics, physics


@dataclass(frozen=True)
class PointSet:
    """A seeded set of parameter points: ``draw(n, rng)`` -> (kinematics, physics).

    ``points`` is the default size; a smaller ``n`` takes the first n of those (so a subset
    is a prefix of the full set, and the ``tools.bench`` set is the benchmark's points), a larger
    one draws n."""

    name: str
    seed: int
    draw: Callable
    generator: str
    points: int = SET_POINTS

    def sample(self, n=None):
        n = self.points if n is None else n
        kinematics, physics = self.draw(max(n, self.points), np.random.default_rng(self.seed))
        if n < len(kinematics):
            index = np.arange(n)
            return kinematics.take(index), physics.take(index)
        return kinematics, physics


_POWER_LAW = ("PowerLaw, A0 ~ U(0.2, pi - 0.2), A1 ~ min(A0, pi - A0) U(0, 1], duty_cycle ~ "
              "U(0.05, 0.95), exponents 2^U(0, log2 12) (1 .. 12), concavities 50/50")
_FOURIER = "Fourier K = 4, A0 ~ U(0, pi), A_k, B_k ~ U(-0.8, 0.8) / k"
SETS = {s.name: s for s in [
    PointSet("harmonic_extreme", 11, _harmonic_extreme,
             "Harmonic, A0 ~ U(0, pi/2], A1/A0 ~ U(0, 1]; mu_n/mu_s 2^U(-12, 12), scaled "
             "period 2^U(-4, 6), delta from {1e-5, 1e-8, 1e-10}, p = 0"),
    *(PointSet(f"stress_powerlaw_{seed}", seed, _stress_power_law,
               f"{_POWER_LAW}; mu_n/mu_s 2^U(-12, 12), scaled period 2^U(-4, 6), delta from "
               "{1e-5, 1e-8, 1e-10}, p = 0") for seed in (21, 22, 23)),
    PointSet("long_period_powerlaw", 31, _long_period_power_law,
             f"{_POWER_LAW}; mu_n/mu_s 2^U(-12, 12), scaled period 2^U(4, 8), delta "
             "10^U(-10, -5), p = 0"),
    PointSet("fourier_clapping", 41, _fourier_clapping,
             f"{_FOURIER}; mu_n/mu_s 2^U(-8, 8), scaled period 2^U(-3, 3), delta from "
             "{1e-5, 1e-8}, p = 0"),
    PointSet("p0.5_harmonic", 51, _harmonic_p05,
             "Harmonic, A0 ~ U(0, pi/2], A1/A0 ~ U(0, 1]; mu_n/mu_s 2^U(-8, 8), scaled period "
             "2^U(-4, 4), delta from {1e-5, 0}, p = 0.5"),
    PointSet("p1.5_fourier", 61, _fourier_p15,
             f"{_FOURIER}; mu_n/mu_s 2^U(-8, 8), scaled period 2^U(-3, 3), delta from "
             "{1e-5, 0}, p = 1.5"),
    PointSet("short_period_harmonic", 71, _short_period_harmonic,
             "Harmonic, A0 ~ U(0.3, pi/2), A1/A0 ~ U(0.2, 0.95); mu_n/mu_s 2^U(-8, 8), scaled "
             "period 2^U(-7, -1), delta from {1e-5, 1e-8}, p = 0"),
    PointSet("flat_inflection_fourier", 81, _flat_inflection_fourier,
             "Fourier phi = A0 + c sin^3(2 pi tau) + terms of size 0.02 at wavenumbers 2 and 4, "
             "A0 ~ U(0.5, pi - 0.5), |c| ~ U(0.3, 1.2); mu_n/mu_s 2^U(-8, 8), scaled period "
             "2^U(-7, 0), delta from {1e-5, 1e-8}, p = 0"),
    PointSet("paper_powerlaw", 91, _paper_power_law,
             "PowerLaw as the paper's grids: shapes from {10 down, 3 down, linear, 3 up, 10 "
             "up} (half of the points: closing 3 or 10 up, opening linear), duty_cycle ~ "
             "U(0.1, 0.9), A0 ~ U(0, pi/2], A1/A0 ~ U(0, 1]; mu_n/mu_s 2^U(-6, 6), scaled "
             "period 2^U(-3, 3), delta 1e-5, p = 0"),
    PointSet("bench", BENCH_SEED, _bench,
             "the points of python -m solver.tools.bench (its draw_points, seed "
             f"{BENCH_SEED}): Harmonic, mu_n/mu_s 2^U(-8, 8), scaled period 2^U(-3, 3), "
             "delta 1e-5, p = 0", BENCH_POINTS),
]}


def clapping_share(kinematics, samples=2001):
    """Share of the points whose phi leaves (0, pi) (clapping, section "Optimal motions")."""
    phi = kinematics.angle(np.linspace(0.0, 1.0, samples))
    return float(np.mean((phi.min(axis=1) < 0.0) | (phi.max(axis=1) > np.pi)))


def describe_point(kinematics, physics, i):
    """One line with point ``i``'s parameters (family fields, scaled physics)."""
    parts = []
    for f in fields(kinematics):
        v = np.asarray(getattr(kinematics, f.name))[i]
        parts.append(f"{f.name}=" + (np.array2string(v, precision=6, separator=",")
                                     if v.ndim else f"{v:.6g}"))
    return (f"{type(kinematics).__name__}({', '.join(parts)}), mu_n/mu_s "
            f"{physics.anisotropy_ratio[i]:.6g}, scaled period {physics.scaled_period[i]:.6g}, "
            f"p {physics.p[i]:g}, delta {physics.delta[i]:.3g}")


# ----------------------------------------------------------------------------- references

def engine_digest(package=Path(solver.__file__).parent):
    """Short hash of the solver's engine sources (every ``*.py`` of the package and its
    subpackages but ``tools/`` and ``__main__.py``)."""
    digest = hashlib.sha256()
    for path in sorted(package.rglob("*.py")):
        relative = path.relative_to(package)
        if relative.parts[0] in ("tools", "__pycache__") or relative.name == "__main__.py":
            continue
        digest.update(relative.as_posix().encode())
        digest.update(path.read_bytes())
    return digest.hexdigest()[:16]


def _fingerprint(kinematics, physics):
    _, params = kinematics.kernel_encoding()
    return np.column_stack([params, physics.period, physics.mu_n, physics.mu_s, physics.p,
                            physics.delta])


@dataclass(frozen=True)
class Solves:
    """The outputs of one batched solve the harness uses; arrays of shape (n_points,)."""

    U: np.ndarray
    P: np.ndarray
    status: np.ndarray
    n_tau: np.ndarray
    error_estimate: np.ndarray
    seconds: float

    @classmethod
    def run(cls, kinematics, physics, method, rtol, order=None):
        """One batched solve; with ``order`` (a permutation of the points, ``neighbour_order``)
        the points are solved in that order as warm-started sweeps of ``solver.SWEEP_POINTS``
        (``solve_periodic(..., sweeps=...)``), the results put back in the set's order."""
        start = time.perf_counter()
        if order is None:
            r = solver.solve_periodic(kinematics, physics, method=method, rtol=rtol)
            return cls(r.U, r.P, r.status, r.n_tau, r.error_estimate, time.perf_counter() - start)
        runs = solver.sweep_runs(order.size)
        r = solver.solve_periodic(kinematics.take(order), physics.take(order), method=method,
                                  rtol=rtol, sweeps=runs)
        back = np.empty_like(order)
        back[order] = np.arange(order.size)
        return cls(r.U[back], r.P[back], r.status[back], r.n_tau[back],
                   r.error_estimate[back], time.perf_counter() - start)

    @property
    def converged(self):
        return (self.status == 0) & np.isfinite(self.U) & np.isfinite(self.P)


def _read_solves(path, fingerprint):
    """The Solves stored at ``path`` if they are of the points ``fingerprint``, else None."""
    with np.load(path) as data:
        if not np.array_equal(data["fingerprint"], fingerprint):
            return None
        return Solves(**{f.name: (data[f.name] if f.name != "seconds" else
                                  float(data["seconds"])) for f in fields(Solves)})


def cached_solves(kinematics, physics, method, rtol, key, cache_dir, refresh=False,
                  reuse=False):
    """``Solves.run`` through a cache file named by ``key``, the method, rtol and
    ``engine_digest``; returns (Solves, source): source "" where they were computed now,
    "cached" where read from this engine's cache file, and, with ``reuse`` where this
    engine has none, "reused from engine <digest>" for the newest file of the same points
    made by another version of the engines (an edit anywhere in solver/ changes the digest,
    and recomputing the references at rtol 1e-9 takes about two hours)."""
    path = Path(cache_dir) / f"{key}-{method}-{rtol:.0e}-{engine_digest()}.npz"
    fingerprint = _fingerprint(kinematics, physics)
    if not refresh:
        if path.exists():
            cached = _read_solves(path, fingerprint)
            if cached is not None:
                return cached, "cached"
        if reuse:
            others = sorted(Path(cache_dir).glob(f"{key}-{method}-{rtol:.0e}-*.npz"),
                            key=lambda other: other.stat().st_mtime, reverse=True)
            for other in others:
                cached = _read_solves(other, fingerprint)
                if cached is not None:
                    return cached, f"reused from engine {other.stem.rsplit('-', 1)[-1]}"
    result = Solves.run(kinematics, physics, method, rtol)
    path.parent.mkdir(parents=True, exist_ok=True)
    np.savez(path, fingerprint=fingerprint,
             **{f.name: getattr(result, f.name) for f in fields(Solves)})
    return result, ""


@dataclass(frozen=True)
class References:
    """A set's reference values and the cross-check's verdict, per point.

    ``kind``: JUDGED (both converged; judged at rtol r where ``disagreement`` <=
    ``agreement`` r), SINGLE (the check failed or was skipped: judged on the reference
    alone) or FAILED (the reference failed: never judged).  ``disagreement`` is NaN where
    the check did not converge."""

    U: np.ndarray
    P: np.ndarray
    kind: np.ndarray
    disagreement: np.ndarray
    vscale: np.ndarray
    agreement: float = AGREEMENT

    @classmethod
    def from_solves(cls, reference, check, physics, vscale, agreement=AGREEMENT):
        """``check`` may be None (no cross-check)."""
        kind = np.where(reference.converged, SINGLE, FAILED)
        disagreement = np.full(kind.shape, np.nan)
        if check is not None:
            both = reference.converged & check.converged
            disagreement[both] = solution_error(check.U, check.P, reference.U, reference.P,
                                                physics.period, vscale)[both]
            kind[both] = JUDGED
        U = np.where(kind != FAILED, reference.U, np.nan)
        P = np.where(kind != FAILED, reference.P, np.nan)
        return cls(U, P, kind, disagreement, vscale, agreement)

    def judged(self, rtol):
        """Points judged at ``rtol``: the reference converged and no check disagrees by
        more than ``agreement`` rtol."""
        return (self.kind == SINGLE) | ((self.kind == JUDGED)
                                        & (self.disagreement <= self.agreement * rtol))

    def uncertain(self, rtol):
        return (self.kind == JUDGED) & ~(self.disagreement <= self.agreement * rtol)


def judge(result, references, physics, rtol):
    """Outcome of one batched solve at ``rtol`` against ``references`` (module docstring).

    ``result`` needs U, P, status, n_tau, error_estimate (a ``SolveResult`` or ``Solves``).
    Returns a dict of counts and figures, and per-point arrays under ``error`` (e / rtol,
    NaN where not judged or failed), ``judged``, ``outside`` (judged and not within rtol)
    and ``silent``."""
    status = np.asarray(result.status)
    judged = references.judged(rtol)
    converged = status == 0
    finite = np.isfinite(result.U) & np.isfinite(result.P)
    error = solution_error(result.U, result.P, references.U, references.P, physics.period,
                           references.vscale) / rtol
    error = np.where(judged & converged, error, np.nan)
    within = judged & converged & finite & (error <= 1.0)
    within_10 = judged & converged & finite & (error <= 10.0)
    silent = converged & (~finite | (judged & ~within_10))
    n_tau = np.asarray(result.n_tau)[converged]
    worst = error[judged & converged & finite]
    return dict(
        solves=int(judged.sum()), solves_total=int(status.size),
        within_rtol=int(within.sum()), within_10_rtol=int(within_10.sum()),
        worst_over_rtol=float(worst.max()) if worst.size else math.nan,
        silent_failures=int(silent.sum()),
        failures=int(np.count_nonzero(~converged)), failure_codes=status_counts(result),
        failures_judged=int(np.count_nonzero(judged & ~converged)),
        uncertain=int(references.uncertain(rtol).sum()),
        mean_n_tau=float(n_tau.mean()) if n_tau.size else math.nan,
        median_n_tau=float(np.median(n_tau)) if n_tau.size else math.nan,
        error=error, judged=judged, outside=judged & ~within, silent=silent)



# ----------------------------------------------------------------------------- driver

def default_methods():
    """Every periodic engine in ``solver.METHODS`` but the march."""
    return [m for m in solver.METHODS if m != "march"]


def default_check():
    """(method, rtol) of the cross-check of references computed now: the march at
    ``MARCH_CHECK_RTOL`` (the frozen references carry their own)."""
    return "march", MARCH_CHECK_RTOL


@dataclass(frozen=True)
class Settings:
    methods: tuple
    sweeps: bool = False
    rtols: tuple = RTOLS
    points: int | None = None
    reference_method: str = REFERENCE_METHOD
    reference_rtol: float = REFERENCE_RTOL
    check_method: str | None = None
    check_rtol: float | None = None
    agreement: float = AGREEMENT
    cache_dir: Path = DEFAULT_CACHE
    refresh: bool = False
    reuse: bool = False
    reference_file: Path = REFERENCE_FILE


def neighbour_order(kinematics, physics):
    """A permutation of the points that walks from neighbour to neighbour: greedy nearest
    neighbour from point 0 in the standardised coordinates of the kinematics' parameters
    and log mu_n, log mu_s, log T, p, log(delta + 1e-12).  For ``--sweeps``: a random set
    in the order a sweep over it would take."""
    _, params = kinematics.kernel_encoding()
    columns = [params[:, k] for k in range(params.shape[1])]
    columns += [np.log(physics.mu_n), np.log(physics.mu_s), np.log(physics.period), physics.p,
                np.log(physics.delta + 1e-12)]
    x = np.array(columns, dtype=np.float64).T
    spread = x.std(axis=0)
    x = (x - x.mean(axis=0)) / np.where(spread > 0, spread, 1.0)
    n = x.shape[0]
    order = np.empty(n, dtype=np.int64)
    left = np.ones(n, dtype=bool)
    here = 0
    for k in range(n):
        order[k] = here
        left[here] = False
        if k + 1 < n:
            d = np.where(left, ((x - x[here]) ** 2).sum(axis=1), np.inf)
            here = int(np.argmin(d))
    return order


def set_references(point_set, kinematics, physics, settings):
    """The set's ``References`` (frozen, or computed through the cache) and a dict
    describing them and their cost."""
    key = f"{point_set.name}-n{len(kinematics)}-seed{point_set.seed}"
    if settings.reference_method == FROZEN:
        ref, check, meta = frozen_references(point_set, kinematics, physics,
                                             settings.reference_file)
        ref_source = check_source = f"frozen at {meta['commit'][:12]}"
        settings = _described_by(settings, meta)
    else:
        ref, ref_source = cached_solves(kinematics, physics, settings.reference_method,
                                        settings.reference_rtol, key, settings.cache_dir,
                                        settings.refresh, settings.reuse)
        check, check_source = None, ""
        if settings.check_method is not None:
            check, check_source = cached_solves(kinematics, physics, settings.check_method,
                                                settings.check_rtol, key, settings.cache_dir,
                                                settings.refresh, settings.reuse)
    vscale = solver.kinematic_speed(kinematics)
    references = References.from_solves(ref, check, physics, vscale, settings.agreement)
    d = references.disagreement[references.kind == JUDGED]
    failed = np.flatnonzero(references.kind == FAILED)
    info = dict(
        reference=f"{settings.reference_method} rtol {settings.reference_rtol:.0e}",
        reference_seconds=ref.seconds, reference_cached=bool(ref_source),
        reference_source=ref_source or "computed",
        reference_failed=int(np.count_nonzero(references.kind == FAILED)),
        reference_failure_codes=status_counts(ref),
        reference_failed_points=[dict(index=int(i), status=int(ref.status[i])) for i in failed],
        check=(f"{settings.check_method} rtol {settings.check_rtol:.0e}"
               if check is not None else None),
        check_seconds=check.seconds if check is not None else 0.0,
        check_cached=bool(check_source), check_source=check_source or "computed",
        check_failure_codes=status_counts(check) if check is not None else {},
        cross_checked=int(d.size),
        single_reference=int(np.count_nonzero(references.kind == SINGLE)),
        disagreement_median=float(np.median(d)) if d.size else math.nan,
        disagreement_max=float(d.max()) if d.size else math.nan)
    return references, info


def set_digest(kinematics, physics):
    """Short hash of a set's points (kernel parameters and physics), bit for bit: the record
    of exactly which points were frozen (``freeze`` stores it beside ``set_signature``)."""
    return hashlib.sha256(np.ascontiguousarray(_fingerprint(kinematics, physics),
                                               dtype=np.float64).tobytes()).hexdigest()[:16]


SIGNATURE_RTOL = 1e-12
"""Tolerance of ``same_points``, relative to each column's sum of magnitudes: a point set's
generator draws through ``exp``, ``**`` and trigonometric functions, whose last bits differ
between CPUs and numpy builds (on 2026-12-06 all twelve sets' bit digests failed on one
machine and held on another, same numpy 2.4.6), so equality is judged to 1e-12, far above
rounding (~1e-16 per value, ~1e-14 summed over 2,000 points) and far below any change of a
generator (a changed seed or range moves every column sum by O(1))."""


def set_signature(kinematics, physics):
    """Two numbers per fingerprint column (kernel parameters and physics) of a set's points,
    shape (2, n_columns): the column sums of magnitudes and the column sums weighted by
    cos(point index), so that a reordering or a change of any one point shows.  Compared
    within ``SIGNATURE_RTOL`` by ``same_points``; stored with the frozen references."""
    fingerprint = np.asarray(_fingerprint(kinematics, physics), dtype=np.float64)
    weights = np.cos(np.arange(fingerprint.shape[0], dtype=np.float64))
    return np.vstack([np.abs(fingerprint).sum(axis=0), weights @ fingerprint])


def same_points(signature, stored):
    """True where ``signature`` (``set_signature`` of today's points) equals the ``stored``
    one within ``SIGNATURE_RTOL`` of each column's sum of magnitudes."""
    signature = np.asarray(signature, dtype=np.float64)
    stored = np.asarray(stored, dtype=np.float64)
    if signature.shape != stored.shape:
        return False
    scale = np.maximum(np.abs(signature[0]), np.abs(stored[0]))
    return bool(np.all(np.abs(signature - stored) <= SIGNATURE_RTOL * scale))


def _git_commit():
    import subprocess
    try:
        here = Path(__file__).parent
        commit = subprocess.run(["git", "rev-parse", "HEAD"], cwd=here, capture_output=True,
                                text=True, check=True).stdout.strip()
        dirty = subprocess.run(["git", "status", "--porcelain", "--", "."], cwd=here,
                               capture_output=True, text=True, check=True).stdout.strip()
        return commit + ("+dirty" if dirty else "")
    except (OSError, subprocess.CalledProcessError):
        return "unknown"


def freeze(names, settings, path=REFERENCE_FILE):
    """Compute every point's reference and check of the sets ``names`` (full size, through
    the cache of ``cached_solves``) and write them to ``path``: per set its U, P and status
    of both, the points' digest, and a JSON ``meta`` (commit, seeds, settings, the
    cross-check's largest disagreement).  Returns the meta dict."""
    arrays = {}
    meta = dict(commit=_git_commit(), engine_digest=engine_digest(),
                created=time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime()),
                reference=[settings.reference_method, settings.reference_rtol],
                check=[settings.check_method, settings.check_rtol], sets={})
    for name in names:
        point_set = SETS[name]
        kinematics, physics = point_set.sample()
        key = f"{point_set.name}-n{len(kinematics)}-seed{point_set.seed}"
        start = time.perf_counter()
        ref, _ = cached_solves(kinematics, physics, settings.reference_method,
                               settings.reference_rtol, key, settings.cache_dir,
                               settings.refresh, settings.reuse)
        check, _ = cached_solves(kinematics, physics, settings.check_method,
                                 settings.check_rtol, key, settings.cache_dir,
                                 settings.refresh, settings.reuse)
        references = References.from_solves(ref, check, physics,
                                            solver.kinematic_speed(kinematics))
        d = references.disagreement[references.kind == JUDGED]
        for label, solves in (("reference", ref), ("check", check)):
            arrays[f"{name}/{label}_U"] = solves.U
            arrays[f"{name}/{label}_P"] = solves.P
            arrays[f"{name}/{label}_status"] = solves.status
        meta["sets"][name] = dict(
            seed=point_set.seed, points=len(kinematics), generator=point_set.generator,
            digest=set_digest(kinematics, physics),
            signature=set_signature(kinematics, physics).tolist(),
            reference_seconds=ref.seconds, check_seconds=check.seconds,
            reference_failed=int(np.count_nonzero(~ref.converged)),
            check_failed=int(np.count_nonzero(~check.converged)),
            disagreement_max=float(d.max()) if d.size else math.nan,
            disagreement_median=float(np.median(d)) if d.size else math.nan)
        print(f"   {name}: {len(kinematics)} points, {time.perf_counter() - start:.0f} s, "
              f"disagreement max {meta['sets'][name]['disagreement_max']:.2e}", flush=True)
    np.savez_compressed(path, meta=np.array(json.dumps(json_value(meta))), **arrays)
    return meta


def frozen_meta(path=REFERENCE_FILE):
    """The ``meta`` dict of the frozen references at ``path``."""
    with np.load(path) as data:
        return json.loads(str(data["meta"]))


def frozen_references(point_set, kinematics, physics, path=REFERENCE_FILE):
    """The frozen (reference, check) ``Solves`` of the first len(kinematics) points of
    ``point_set``.  Raises ValueError where the file lacks the set or holds other points: judged by ``same_points`` on the stored ``set_signature`` (by the
    bit digest where a file predates signatures)."""
    meta = frozen_meta(path)
    stored = meta["sets"].get(point_set.name)
    if stored is None:
        raise ValueError(f"--set: {point_set.name!r} has no frozen references in {path} "
                         "(python -m solver.tools.honesty --freeze makes them)")
    full_kin, full_phys = point_set.sample(stored["points"])
    n = len(kinematics)
    if "signature" in stored:
        same = same_points(set_signature(full_kin, full_phys), stored["signature"])
    else:
        same = set_digest(full_kin, full_phys) == stored["digest"]
    if not same or n > stored["points"]:
        raise ValueError(f"--set: {point_set.name!r}'s points are not those of the frozen "
                         f"references in {path} (its generator changed, or more than "
                         f"{stored['points']} points)")
    out = []
    with np.load(path) as data:
        for label in ("reference", "check"):
            out.append(Solves(U=data[f"{point_set.name}/{label}_U"][:n],
                              P=data[f"{point_set.name}/{label}_P"][:n],
                              status=data[f"{point_set.name}/{label}_status"][:n],
                              n_tau=np.zeros(n, dtype=np.int64),
                              error_estimate=np.zeros(n), seconds=0.0))
    return out[0], out[1], meta


def _described_by(settings, meta):
    """``settings`` with the frozen references' own methods and rtols (for the printout)."""
    from dataclasses import replace
    return replace(settings, reference_method=f"{meta['reference'][0]} (frozen)",
                   reference_rtol=meta["reference"][1], check_method=meta["check"][0],
                   check_rtol=meta["check"][1])


REFERENCE_KINDS = {JUDGED: "cross-checked", SINGLE: "single reference",
                   FAILED: "reference failed"}


def _outliers(outcome, result, references, rtol):
    """Points outside rtol, silent or failed: index, e / rtol, estimate / rtol, status, and
    their reference's kind and disagreement."""
    flagged = np.flatnonzero(outcome["outside"] | outcome["silent"]
                             | (np.asarray(result.status) != 0))
    return [dict(index=int(i), error_over_rtol=float(outcome["error"][i]),
                 estimate_over_rtol=float(result.error_estimate[i] / rtol),
                 status=int(result.status[i]),
                 reference=REFERENCE_KINDS[int(references.kind[i])],
                 disagreement=float(references.disagreement[i])) for i in flagged]


def _share(count, total):
    return count / total if total else math.nan


MAX_PRINTED_OUTLIERS = 20


def run_set(point_set, settings):
    """References, then every method at every rtol on the set's points; prints the set's
    table and returns its JSON detail."""
    kinematics, physics = point_set.sample(settings.points)
    n = len(kinematics)
    print(f"\n== {point_set.name}: {n} points, seed {point_set.seed}\n   {point_set.generator}",
          flush=True)
    detail = dict(generator=point_set.generator, seed=point_set.seed, points=n)
    if isinstance(kinematics, solver.Fourier):
        detail["clapping_share"] = clapping_share(kinematics)
        print(f"   phi leaves (0, pi) (clapping) on {100 * detail['clapping_share']:.1f} % of "
              f"the points", flush=True)
    references, info = set_references(point_set, kinematics, physics, settings)
    detail["references"] = info
    print(f"   reference {info['reference']}: {info['reference_seconds']:.1f} s"
          f" ({info['reference_source']}), failed on "
          f"{info['reference_failed']} {info['reference_failure_codes']} (not judged)",
          flush=True)
    for point in info["reference_failed_points"]:
        print(f"     point {point['index']}, status {point['status']}: "
              + describe_point(kinematics, physics, point["index"]), flush=True)
    if info["check"] is not None:
        print(f"   check {info['check']}: {info['check_seconds']:.1f} s"
              f" ({info['check_source']}), converged on "
              f"{info['cross_checked']} of the reference's points, disagreement median "
              f"{info['disagreement_median']:.1e} max {info['disagreement_max']:.1e}; "
              f"{info['single_reference']} single reference (check failed: "
              f"{info['check_failure_codes']})", flush=True)
    print("   method     rtol   judged uncertain  within  within10    worst failures"
          "       silent  n_tau mean  median   time s", flush=True)
    runs = {m: {} for m in settings.methods}
    lines = []
    order = neighbour_order(kinematics, physics) if settings.sweeps else None
    for rtol in settings.rtols:
        for method in settings.methods:
            result = Solves.run(kinematics, physics, method, rtol,
                                order if method == "periodic" else None)
            outcome = judge(result, references, physics, rtol)
            outliers = _outliers(outcome, result, references, rtol)
            row = {k: v for k, v in outcome.items() if not isinstance(v, np.ndarray)}
            row.update(within_rtol=_share(outcome["within_rtol"], outcome["solves"]),
                       within_10_rtol=_share(outcome["within_10_rtol"], outcome["solves"]),
                       within_rtol_count=outcome["within_rtol"],
                       within_10_rtol_count=outcome["within_10_rtol"],
                       seconds=result.seconds, outliers=outliers)
            runs[method][f"{rtol:.0e}"] = row
            print(f"   {method:9s} {rtol:6.0e} {row['solves']:7d} {row['uncertain']:9d} "
                  f"{100 * row['within_rtol']:6.1f}% {100 * row['within_10_rtol']:7.1f}% "
                  f"{row['worst_over_rtol']:8.3g} {row['failures']:3d} "
                  f"{str(row['failure_codes']):>10s} {row['silent_failures']:4d} "
                  f"{row['mean_n_tau']:10.0f} {row['median_n_tau']:7.0f} {row['seconds']:8.2f}",
                  flush=True)
            for o in outliers[:MAX_PRINTED_OUTLIERS]:
                lines.append(f"   {method} rtol {rtol:.0e} point {o['index']}: error "
                             f"{o['error_over_rtol']:.3g} rtol, estimate "
                             f"{o['estimate_over_rtol']:.3g} rtol, status {o['status']} "
                             f"({o['reference']}, d {o['disagreement']:.1e}): "
                             + describe_point(kinematics, physics, o["index"]))
            if len(outliers) > MAX_PRINTED_OUTLIERS:
                lines.append(f"   {method} rtol {rtol:.0e}: ... and "
                             f"{len(outliers) - MAX_PRINTED_OUTLIERS} more (in the JSON)")
    if lines:
        print("   outside rtol, silent or failed:\n" + "\n".join(lines), flush=True)
    detail["runs"] = runs
    return detail


def totals(set_details, methods):
    """Per method, over every set and rtol: the JSON's ``methods`` figures."""
    out = {}
    for method in methods:
        rows = [row for d in set_details.values() for row in d["runs"][method].values()]
        solves = sum(r["solves"] for r in rows)
        worst = [r["worst_over_rtol"] for r in rows if math.isfinite(r["worst_over_rtol"])]
        out[method] = dict(
            within_rtol=_share(sum(r["within_rtol_count"] for r in rows), solves),
            within_10_rtol=_share(sum(r["within_10_rtol_count"] for r in rows), solves),
            worst_over_rtol=max(worst) if worst else math.nan,
            silent_failures=sum(r["silent_failures"] for r in rows),
            failures=sum(r["failures"] for r in rows),
            solves=solves, solves_total=sum(r["solves_total"] for r in rows),
            seconds=sum(r["seconds"] for r in rows))
    return out


def warm_up(methods, point_set, settings):
    """Compile (or load) every engine the run uses on a few points; not timed."""
    kinematics, physics = point_set.sample(WARMUP_POINTS)
    for method in methods:
        solver.solve_periodic(kinematics, physics, method=method, rtol=settings.rtols[0])


def build_parser():
    parser = argparse.ArgumentParser(prog="python -m solver.tools.honesty",
                                     description=__doc__.split("\n")[0])
    parser.add_argument("--method", nargs="+", default=None,
                        help="engines to judge (default: solver.METHODS but the march)")
    parser.add_argument("--set", nargs="+", default=None, choices=sorted(SETS),
                        help="point sets (default: all)")
    parser.add_argument("--rtol", nargs="+", type=float, default=list(RTOLS))
    parser.add_argument("--points", type=int, default=None,
                        help=f"points per set (default {SET_POINTS}, bench {BENCH_POINTS}; "
                             "fewer: the first ones)")
    parser.add_argument("--refresh", action="store_true", help="recompute cached references")
    parser.add_argument("--reuse-references", action="store_true",
                        help="where this engine version has no cached reference, use the "
                             "newest cached one of the same points made by an earlier "
                             "version (printed per set; for iterating on an engine)")
    parser.add_argument("--reference-method", default=FROZEN,
                        help=f"'{FROZEN}' (default): the committed references "
                             f"({REFERENCE_FILE.name}); or an engine computing them now "
                             f"(cached under --cache-dir)")
    parser.add_argument("--reference-file", type=Path, default=REFERENCE_FILE)
    parser.add_argument("--freeze", action="store_true",
                        help=f"compute every point's reference ({REFERENCE_METHOD} at "
                             f"--reference-rtol) and check of the sets and write them to "
                             "--reference-file; judges nothing")
    parser.add_argument("--reference-rtol", type=float, default=REFERENCE_RTOL)
    parser.add_argument("--check-method", default=None,
                        help="cross-check engine of references computed now, or 'none' "
                             "(default: march)")
    parser.add_argument("--check-rtol", type=float, default=None,
                        help=f"(default: {REFERENCE_RTOL:g} for the engine, "
                             f"{MARCH_CHECK_RTOL:g} for the march)")
    parser.add_argument("--agreement", type=float, default=AGREEMENT,
                        help="references must agree within this share of the judged rtol")
    parser.add_argument("--cache-dir", type=Path, default=DEFAULT_CACHE)
    parser.add_argument("--sweeps", action="store_true",
                        help="solve each set as warm-started sweeps (periodic), in a neighbour order")
    return parser


def settings_from(args):
    methods = tuple(args.method or default_methods())
    check_method, check_rtol = default_check()
    if args.check_method is not None:
        check_method = None if args.check_method == "none" else args.check_method
        check_rtol = REFERENCE_RTOL if check_method != "march" else MARCH_CHECK_RTOL
    if args.check_rtol is not None:
        check_rtol = args.check_rtol
    reference_method = args.reference_method
    if args.freeze and reference_method == FROZEN:
        reference_method = REFERENCE_METHOD
    if args.freeze and check_method is None:
        raise ValueError("--freeze needs a --check-method")
    for m in (*methods, reference_method if reference_method != FROZEN else None,
              check_method):
        if m is not None and m not in solver.METHODS:
            raise ValueError(f"method: expected one of {solver.METHODS}, got {m!r}")
    if args.points is not None and args.points < 1:
        raise ValueError("--points must be >= 1")
    return Settings(methods=methods, sweeps=args.sweeps, rtols=tuple(args.rtol), points=args.points,
                    reference_method=reference_method, reference_rtol=args.reference_rtol,
                    check_method=check_method, check_rtol=check_rtol,
                    agreement=args.agreement, cache_dir=args.cache_dir, refresh=args.refresh,
                    reuse=args.reuse_references, reference_file=args.reference_file)


def main(argv=None):
    args = build_parser().parse_args(argv)
    try:
        settings = settings_from(args)
    except ValueError as exc:
        print(exc, file=sys.stderr)
        return 2
    wall = time.perf_counter()
    names = args.set or list(SETS)
    if args.freeze and settings.reference_file.resolve() == REFERENCE_FILE.resolve():
        # the committed file was made by an engine independent of today's (the former order-3
        # one); frozen anew by today's engine, the harness would judge the engine by itself
        print(f"--reference-file: refusing to overwrite the committed {REFERENCE_FILE.name} "
              "(made by the former order-3 engine, independent of today's); write to another "
              "file and replace it deliberately", file=sys.stderr)
        return 2
    if args.freeze:
        print(f"freezing the references of {', '.join(names)}: {settings.reference_method} "
              f"rtol {settings.reference_rtol:.0e}, check {settings.check_method} rtol "
              f"{settings.check_rtol:.0e} -> {settings.reference_file}", flush=True)
        meta = freeze(names, settings, settings.reference_file)
        print(json.dumps(json_value(dict(frozen=meta,
                                         wall_seconds=time.perf_counter() - wall))))
        return 0
    if settings.reference_method == FROZEN:
        try:
            for name in names:
                frozen_references(SETS[name], *SETS[name].sample(settings.points),
                                  settings.reference_file)
        except (ValueError, OSError) as exc:
            print(str(exc).splitlines()[0], file=sys.stderr)
            return 2
    engines = dict.fromkeys((*settings.methods,
                             settings.reference_method if settings.reference_method != FROZEN
                             else None, settings.check_method
                             if settings.reference_method != FROZEN else None))
    warm_up([m for m in engines if m is not None], SETS[names[0]], settings)
    print(f"honesty of {', '.join(settings.methods)} at rtol "
          f"{', '.join(f'{r:.0e}' for r in settings.rtols)}; references "
          f"{settings.reference_method} {settings.reference_rtol:.0e}, check "
          f"{settings.check_method} {settings.check_rtol if settings.check_rtol else ''}, "
          f"judged where they agree within {settings.agreement:g} rtol", flush=True)
    details = {name: run_set(SETS[name], settings) for name in names}
    report = dict(methods=totals(details, settings.methods), sets=details,
                  settings=dict(methods=list(settings.methods), rtols=list(settings.rtols),
                                points=settings.points,
                                reference=[settings.reference_method, settings.reference_rtol],
                                check=[settings.check_method, settings.check_rtol],
                                agreement=settings.agreement, engine_digest=engine_digest(),
                                wall_seconds=time.perf_counter() - wall))
    print("\nper method over every set and rtol:", flush=True)
    for method, t in report["methods"].items():
        print(f"   {method}: {t['solves']} judged solves ({t['solves_total']} in all), within "
              f"rtol {100 * t['within_rtol']:.2f} %, within 10 rtol "
              f"{100 * t['within_10_rtol']:.2f} %, worst {t['worst_over_rtol']:.3g} rtol, "
              f"{t['failures']} failures, {t['silent_failures']} silent, "
              f"{t['seconds']:.1f} s", flush=True)
    print(json.dumps(json_value(report)))
    return 0


if __name__ == "__main__":
    sys.exit(main())
