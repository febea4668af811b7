"""Two optima ensembles cell by cell, judged against a reseeded baseline.

    python -m pipeline.compare_optima BASE NEW [--control RESEED] [--rtol 1e-4] [--independent N]

BASE and NEW are stores of one optima scene (kind "optima", version 2 or later: the optima
solved again by the engine; 3: certified), e.g. the baseline optimiser and a changed one.  Per cell (every
coordinate but the start and the rank) it compares the best kept optimum, |lambda| /
lambda_ub of rank 0, and the number of distinct optima kept, by issue 35's test: the best
within ``rtol`` relative of BASE's or higher, the distinct optima within +-1 or 20 % of
BASE's.  Cells whose best is below ``STILL`` (no motion: e.g. ratio 1 at p >= 1, lambda 1e-34 .. 1e-8)
are left out of the relative test and counted apart.

That test is a sample's: an identical optimiser with other random starts (``[starts]
seed``) fails it in 10 of fourier_optima's 36 cells and 9 of force_laws' 45
(docs/validation.md, "The cell test against a reseeded baseline").  So ``--control RESEED``
(the BASE optimiser on other starts, same scene otherwise) gives the test its positive
control: RESEED against BASE says how many cells fail by chance alone, and NEW is judged
against it (``judge``): NEW passes where it fails no more cells than the control, and no
cell's best falls below the lower of BASE's and RESEED's by more than ``rtol``.  Without a
control the verdict is the raw test's and says so.

Two further comparisons of the starts themselves (issue 47), where the stores hold them:

- Cost: BASE and NEW on the same starts (equal ``start_A0``, ``start_A1`` and cells), the
  per-start CPU ratio NEW / BASE (``cpu_seconds``; a store without it, before kind_version 3,
  gives its wall ``seconds`` and the summary says so) with its spread: median, quartiles,
  min, max, and the ratio of the totals (``cost_ratios``).
- Basins: every start labelled by the BASE kept optimum it ends at (``basin_labels``: the
  reduction's equality, phi within ``keep.phi_tolerance`` up to a cyclic shift and sign and the
  period within ``keep.period_tolerance``; -1 an optimum BASE did not keep, -2 no optimum: a
  start the reduction would not keep).  ``moved`` is how many starts would have to move for a
  cell's occupation of the basins to be BASE's (half the L1 distance of the label counts),
  summed over the cells; NEW changes which basin starts reach no more than chance where it
  moves no more than the reseeded control does (``basins_pass``).  ``switched``: the starts of
  NEW whose label differs from the same start's in BASE (informative: the control has other
  starts, so it has no such number).

``--independent N`` re-checks the best optimum of up to N cells that keep a single distinct
optimum: scipy's BFGS on the engine's lambda (``solver.solve_periodic`` at rtol 1e-8; no frozen
steps, no adjoint, finite-difference gradients) from NEW's optimum, the relative difference of
the two values (``independent_check``; issue 47 asks 1e-5).

Prints the failing cells, then a summary; the last line is JSON.  Bad arguments: one line
naming the argument, exit code 2.
"""

from __future__ import annotations

import argparse
import json
import sys
from dataclasses import dataclass
from pathlib import Path

import numpy as np

__all__ = ["CellTable", "StartTable", "basin_labels", "basin_moves", "compare_cells", "cost_ratios",
           "independent_check", "judge", "read_cells", "read_starts", "STILL"]

#: a cell's best |lambda| / lambda_ub below this is no motion (isotropic friction at p >= 1:
#: 1e-34 .. 1e-8 in the shipped stores): no relative test.  The paper prints relative
#: efficiencies of 0.05-0.6 to three digits; 1e-6 is far below any value it reads.
STILL = 1e-6


@dataclass(frozen=True)
class CellTable:
    """One ensemble per cell: ``coords`` {dimension: values} over ``dims``; ``best`` and
    ``distinct`` of shape [cells of dims]."""

    dims: tuple
    coords: dict
    best: np.ndarray
    distinct: np.ndarray


def read_cells(store) -> CellTable:
    """The cells of an optima store (KIND_VERSION 2 or later): the best kept optimum's |lambda| /
    lambda_ub and the number of distinct optima kept (multiplicity > 0)."""
    from ._store import read_arrays, store_meta

    store = Path(store)
    meta = store_meta(store)
    if meta.get("kind") != "optima" or int(meta.get("kind_version", 1)) < 2:
        raise ValueError(f"{store}: not an optima store of version 2 (kind {meta.get('kind')!r}, "
                         f"version {meta.get('kind_version', 1)})")
    if not meta.get("state", {}).get("reductions_complete"):
        raise ValueError(f"{store}: its reductions are not complete (run it to the end first)")
    dims = tuple(meta["layout"]["dims"])[:-1]  # the last is the start
    a = read_arrays(store, ["optimum_relative_efficiency", "optimum_multiplicity", *dims])
    best = np.abs(a["optimum_relative_efficiency"][..., 0])
    distinct = (a["optimum_multiplicity"] > 0).sum(axis=-1)
    return CellTable(dims, {d: a[d] for d in dims}, best, distinct)


def compare_cells(base: CellTable, new: CellTable, rtol: float = 1e-4) -> dict:
    """Issue 35's test, cell by cell: {"relative": (new - base) / base (NaN where base is
    still or not finite), "lower": bool, "distinct_off": bool, "still": bool, "fails": bool},
    arrays over the cells."""
    if base.dims != new.dims or any(not np.array_equal(base.coords[d], new.coords[d]) for d in base.dims):
        raise ValueError("the two stores are not of one scene's cells (dimensions or coordinates differ)")
    still = ~(base.best >= STILL)
    with np.errstate(invalid="ignore", divide="ignore"):
        rel = np.where(still, np.nan, (new.best - base.best) / base.best)
    lower = ~still & ~(rel >= -rtol)  # NaN in new (a cell without optimum) counts as lower
    off = np.abs(new.distinct - base.distinct) > np.maximum(1, 0.2 * base.distinct)
    return {"relative": rel, "lower": lower, "distinct_off": off, "still": still, "fails": lower | off}


def judge(base: CellTable, new: CellTable, control: CellTable | None = None, rtol: float = 1e-4) -> dict:
    """The verdict on NEW against BASE: the raw test's failing cells and, with ``control``
    (BASE's optimiser on other starts), the control's failing cells and the calibrated verdict:
    NEW passes where it fails no more cells than the control and no cell's best is below the
    lower of BASE's and the control's by more than ``rtol`` (still cells left out)."""
    cmp = compare_cells(base, new, rtol)
    out = {"cells": int(base.best.size), "still_cells": int(cmp["still"].sum()),
           "failing": int(cmp["fails"].sum()), "lower": int(cmp["lower"].sum()),
           "distinct_off": int(cmp["distinct_off"].sum()), "rtol": rtol}
    if control is None:
        out.update(verdict="pass" if out["failing"] == 0 else "fail", calibrated=False)
        return out
    ctl = compare_cells(base, control, rtol)
    floor = np.fmin(base.best, control.best)
    with np.errstate(invalid="ignore", divide="ignore"):
        below = ~cmp["still"] & ~((new.best - floor) / floor >= -rtol)
    out.update(control_failing=int(ctl["fails"].sum()), below_both_baselines=int(below.sum()), calibrated=True)
    out["verdict"] = "pass" if out["failing"] <= out["control_failing"] and not below.any() else "fail"
    return out


@dataclass(frozen=True)
class StartTable:
    """The starts of one optima store, arrays over (cells..., start): ``cost`` [s] (``cost_name``
    says which: "cpu_seconds", or "seconds" for wall time), ``eligible`` (the reduction would keep
    it), ``phi`` (..., n_tau) oriented U < 0, ``period`` (scaled), the starts (``start_values``,
    shape (n_starts, 2)), the kept optima (``kept_phi`` (cells..., rank, n_tau),
    ``kept_period``, NaN where none) and the scene's ``keep``."""

    cells: CellTable
    cost: np.ndarray
    cost_name: str
    eligible: np.ndarray
    phi: np.ndarray
    period: np.ndarray
    start_values: np.ndarray
    kept_phi: np.ndarray
    kept_period: np.ndarray
    keep: object
    coefficients: np.ndarray
    relative_efficiency: np.ndarray
    kept_start: np.ndarray
    scene: object


def read_starts(store) -> StartTable:
    """The starts of an optima store (its scene from the store's provenance)."""
    from ._optima import STILL_AMPLITUDE, accepted_starts, fourier_samples, reflect_about_half_pi
    from ._registry import parse_scene
    from ._store import read_arrays, store_meta

    store = Path(store)
    cells = read_cells(store)
    meta = store_meta(store)
    scene = parse_scene(meta["provenance"]["scene_toml"], meta["provenance"]["scene_file"])
    names = ["status", "U", "relative_efficiency", "scaled_period", "gradient_norm", "period_at_bound",
             "coefficients", "seconds", "start_A0", "start_A1", "optimum_phi", "optimum_scaled_period",
             "optimum_start"]
    have = set(_array_names(store))
    extra = [n for n in ("certified", "cpu_seconds") if n in have]
    a = read_arrays(store, names + extra)
    coefficients = a["coefficients"].copy()
    forward = a["U"] > 0
    coefficients[forward] = reflect_about_half_pi(coefficients[forward])
    phi = fourier_samples(coefficients, scene.keep.n_tau)
    eligible = (accepted_starts(scene, a) & np.isfinite(a["relative_efficiency"])
                & (np.ptp(phi, axis=-1) > STILL_AMPLITUDE))
    cost_name = "cpu_seconds" if "cpu_seconds" in a else "seconds"
    return StartTable(cells, a[cost_name], cost_name, eligible, phi, a["scaled_period"],
                      np.stack([a["start_A0"], a["start_A1"]], axis=-1), a["optimum_phi"],
                      a["optimum_scaled_period"], scene.keep, coefficients, a["relative_efficiency"],
                      a["optimum_start"], scene)


def _array_names(store: Path) -> list[str]:
    return [p.name for p in Path(store).iterdir() if (p / "zarr.json").is_file()]


def _same_starts(base: StartTable, new: StartTable) -> bool:
    return (base.cost.shape == new.cost.shape and np.array_equal(base.start_values, new.start_values)
            and all(np.array_equal(base.cells.coords[d], new.cells.coords[d]) for d in base.cells.dims))


def cost_ratios(base: StartTable, new: StartTable) -> dict:
    """Per-start cost NEW / BASE on the same starts: {"starts", "median", "q1", "q3", "min", "max",
    "total" (sum NEW / sum BASE), "base_cost", "new_cost"}; ValueError where the starts differ."""
    if not _same_starts(base, new):
        raise ValueError("the two stores are not of the same starts (start_A0, start_A1 or cells differ)")
    ok = np.isfinite(base.cost) & np.isfinite(new.cost) & (base.cost > 0) & (new.cost > 0)
    ratio = new.cost[ok] / base.cost[ok]
    q = np.quantile(ratio, [0.0, 0.25, 0.5, 0.75, 1.0]) if ratio.size else np.full(5, np.nan)
    return {"starts": int(ok.sum()), "min": float(q[0]), "q1": float(q[1]), "median": float(q[2]),
            "q3": float(q[3]), "max": float(q[4]),
            "total": float(new.cost[ok].sum() / base.cost[ok].sum()) if ok.any() else float("nan"),
            "base_cost": base.cost_name, "new_cost": new.cost_name}


def basin_labels(reference: StartTable, starts: StartTable) -> np.ndarray:
    """The rank of the ``reference`` kept optimum each start of ``starts`` ends at (cells...,
    start), int: -1 an optimum not among them, -2 no optimum (not eligible).  Equality is the
    reduction's (``_optima.distinct_optima``) with the reference's ``keep``."""
    keep = reference.keep
    labels = np.full(starts.eligible.shape, -2, dtype=np.int64)
    n_tau = reference.kept_phi.shape[-1]
    if starts.phi.shape[-1] != n_tau:
        raise ValueError("the two stores sample phi differently (keep.n_tau)")
    index = (np.arange(n_tau)[:, None] + np.arange(n_tau)[None, :]) % n_tau
    for cell in np.ndindex(*starts.eligible.shape[:-1]):
        copies = []
        for rank in range(reference.kept_phi.shape[len(cell)]):
            period = reference.kept_period[cell][rank]
            if not np.isfinite(period):
                break
            shifted = reference.kept_phi[cell][rank][index]
            copies.append((period, np.concatenate([shifted, -shifted])))
        for i in np.flatnonzero(starts.eligible[cell]):
            labels[cell][i] = -1
            for rank, (period, c) in enumerate(copies):
                p_i = starts.period[cell][i]
                if abs(p_i - period) > keep.period_tolerance * max(p_i, period):
                    continue
                if np.min(np.max(np.abs(c - starts.phi[cell][i]), axis=1)) <= keep.phi_tolerance:
                    labels[cell][i] = rank
                    break
    return labels


def basin_moves(base_labels: np.ndarray, labels: np.ndarray) -> np.ndarray:
    """Per cell, the starts that would have to move for ``labels``' occupation of the basins to
    be ``base_labels``' (half the L1 distance of the label counts), shape (cells...)."""
    out = np.zeros(base_labels.shape[:-1], dtype=np.int64)
    for cell in np.ndindex(*out.shape):
        values = np.union1d(base_labels[cell], labels[cell])
        out[cell] = sum(abs(int(np.sum(base_labels[cell] == v)) - int(np.sum(labels[cell] == v)))
                        for v in values) // 2
    return out


def independent_check(table: StartTable, max_cells: int, rtol: float = 1e-8) -> dict:
    """scipy BFGS on the engine's lambda (``solver.solve_periodic`` at ``rtol``: its own adaptive
    steps, no frozen grid, no adjoint; finite-difference gradients) from the best optimum of each
    cell that keeps one distinct optimum (up to ``max_cells``, the first in cell order; cells at
    rest left out): {"cells", "worst" relative difference, "per_cell": [(cell, ours, scipy, rel)]}.
    Shares no store value but the starting point, no grid and no optimiser with the search."""
    import scipy.optimize
    import solver

    scene = table.scene
    k_largest = max(scene.max_wavenumbers)
    per_cell = []
    distinct = table.cells.distinct
    for cell in np.ndindex(*distinct.shape):
        if len(per_cell) >= max_cells:
            break
        if distinct[cell] != 1 or not table.cells.best[cell] >= STILL:
            continue
        i_r, i_k, i_p = cell
        ratio, kmax, p = (scene.anisotropy_ratios[i_r], scene.max_wavenumbers[i_k], scene.exponents[i_p])
        start = int(table.kept_start[cell][0])
        c = table.coefficients[cell][start]  # oriented U < 0
        physics0 = solver.Physics.from_scaled(ratio, table.period[cell][start], p=p, delta=scene.delta)
        lam_ub = 1.0 / min(float(physics0.mu_n[0]), float(physics0.mu_s[0]))
        x0 = np.concatenate([c[:kmax + 1], c[k_largest + 2:k_largest + 1 + kmax],
                             [np.log(float(physics0.period[0]))]])  # B_1 = 0 (the phase)

        def lam(x, kmax=kmax, physics0=physics0):
            A = x[None, :kmax + 1]
            B = np.concatenate([[0.0], x[kmax + 1:2 * kmax]])[None, :]
            physics = solver.Physics(period=np.exp(x[-1:]), mu_n=physics0.mu_n, mu_s=physics0.mu_s,
                                     p=physics0.p, delta=physics0.delta)
            r = solver.solve_periodic(solver.Fourier(A, B), physics, rtol=rtol)
            value = float(r.efficiency[0])
            return -abs(value) / lam_ub if np.isfinite(value) else np.inf

        ours = -lam(x0)
        res = scipy.optimize.minimize(lam, x0, method="BFGS", options={"gtol": 1e-9, "maxiter": 200})
        theirs = max(-float(res.fun), ours)  # BFGS never ends above where it starts
        rel = (theirs - ours) / theirs
        per_cell.append(([float(table.cells.coords[d][j]) for d, j in zip(table.cells.dims, cell)],
                         ours, theirs, rel))
    return {"cells": len(per_cell), "worst": max((r[3] for r in per_cell), default=float("nan")),
            "per_cell": per_cell}


#: issue 47's cost target: NEW's per-start CPU at most this share of BASE's (median and total)
COST_TARGET = 0.6


def judge_starts(base: StartTable, new: StartTable, control: StartTable | None = None) -> dict:
    """Cost (``cost_ratios``, where the starts are the same) and basins (``basin_labels``) of NEW
    against BASE, calibrated by ``control`` where given: {"cost": ..., "cost_target_met",
    "moved", "switched", "eligible_base", "eligible_new", and with a control "control_moved",
    "basins_pass"}."""
    out = {}
    if _same_starts(base, new):
        cost = cost_ratios(base, new)
        out["cost"] = cost
        out["cost_target_met"] = bool(cost["median"] <= COST_TARGET and cost["total"] <= COST_TARGET)
    base_labels = basin_labels(base, base)
    new_labels = basin_labels(base, new)
    out.update(moved=int(basin_moves(base_labels, new_labels).sum()),
               eligible_base=int(base.eligible.sum()), eligible_new=int(new.eligible.sum()))
    if _same_starts(base, new):
        out["switched"] = int(np.sum(new_labels != base_labels))
    if control is not None:
        out["control_moved"] = int(basin_moves(base_labels, basin_labels(base, control)).sum())
        out["basins_pass"] = out["moved"] <= out["control_moved"]
    return out


def _cell_lines(base: CellTable, new: CellTable, rtol: float, label: str) -> list[str]:
    cmp = compare_cells(base, new, rtol)
    lines = []
    for idx in zip(*np.nonzero(cmp["fails"])):
        where = ", ".join(f"{d} {base.coords[d][i]:g}" for d, i in zip(base.dims, idx))
        what = []
        if cmp["lower"][idx]:
            what.append(f"best {base.best[idx]:.6g} -> {new.best[idx]:.6g} ({cmp['relative'][idx]:+.1e})")
        if cmp["distinct_off"][idx]:
            what.append(f"distinct {base.distinct[idx]} -> {new.distinct[idx]}")
        lines.append(f"  {label}: {where}: " + "; ".join(what))
    return lines


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(prog="python -m pipeline.compare_optima", description=__doc__.split("\n\n")[1])
    parser.add_argument("base", help="store of the baseline ensemble")
    parser.add_argument("new", help="store of the ensemble judged")
    parser.add_argument("--control", help="store of the baseline's optimiser on other starts (positive control)")
    parser.add_argument("--rtol", type=float, default=1e-4, help="relative tolerance of a cell's best (1e-4)")
    parser.add_argument("--independent", type=int, default=0, metavar="N",
                        help="scipy BFGS on the engine's lambda from NEW's optimum of up to N single-optimum cells")
    args = parser.parse_args(argv)
    if args.independent < 0:
        print(f"--independent: {args.independent} is not >= 0", file=sys.stderr)
        return 2
    if not (0 < args.rtol < 1):
        print(f"--rtol: {args.rtol:g} is not in (0, 1)", file=sys.stderr)
        return 2
    tables = {}
    for name in ("base", "new", "control"):
        path = getattr(args, name)
        if path is None:
            continue
        if not (Path(path) / "zarr.json").is_file():
            print(f"{name}: {path} is not a store (no zarr.json)", file=sys.stderr)
            return 2
        try:
            tables[name] = read_cells(path)
        except (ValueError, KeyError) as exc:
            print(f"{name}: {exc}", file=sys.stderr)
            return 2
    try:
        verdict = judge(tables["base"], tables["new"], tables.get("control"), args.rtol)
    except ValueError as exc:
        print(f"new: {exc}", file=sys.stderr)
        return 2
    starts = {}
    for name in tables:
        try:
            starts[name] = read_starts(getattr(args, name))
        except (ValueError, KeyError) as exc:
            print(f"{name}: {exc}", file=sys.stderr)
            return 2
    try:
        verdict.update(judge_starts(starts["base"], starts["new"], starts.get("control")))
    except ValueError as exc:
        print(f"new: {exc}", file=sys.stderr)
        return 2
    if "basins_pass" in verdict:
        verdict["verdict"] = "pass" if verdict["verdict"] == "pass" and verdict["basins_pass"] else "fail"
    if args.independent:
        verdict["independent"] = independent_check(starts["new"], args.independent)
    for line in _cell_lines(tables["base"], tables["new"], args.rtol, "new"):
        print(line)
    if "control" in tables:
        for line in _cell_lines(tables["base"], tables["control"], args.rtol, "control"):
            print(line)
    print(f"cells {verdict['cells']} ({verdict['still_cells']} still, no relative test): new fails "
          f"{verdict['failing']} (best lower {verdict['lower']}, distinct off {verdict['distinct_off']})"
          + (f"; the reseeded control fails {verdict['control_failing']}; new below both baselines in "
             f"{verdict['below_both_baselines']}" if verdict["calibrated"] else "; no control: the raw test")
          + f" -> {verdict['verdict']}")
    if "cost" in verdict:
        c = verdict["cost"]
        print(f"per-start cost new/base over {c['starts']} starts ({c['new_cost']} / {c['base_cost']}): median "
              f"{c['median']:.3g} (quartiles {c['q1']:.3g} .. {c['q3']:.3g}, min {c['min']:.3g}, max {c['max']:.3g}); "
              f"total {c['total']:.3g}; target <= {COST_TARGET:g}: {'met' if verdict['cost_target_met'] else 'not met'}")
    print(f"basins: {verdict['moved']} starts moved between base's kept optima"
          + (f" (the reseeded control: {verdict['control_moved']})" if "control_moved" in verdict else "")
          + (f"; {verdict['switched']} of the same starts end elsewhere" if "switched" in verdict else "")
          + f"; eligible starts base {verdict['eligible_base']}, new {verdict['eligible_new']}")
    if "independent" in verdict:
        ind = verdict["independent"]
        print(f"independent check (scipy BFGS on the engine's lambda, rtol 1e-8) of {ind['cells']} "
              f"single-optimum cells: worst relative gain {ind['worst']:.2g}")
    print(json.dumps(verdict))
    return 0


if __name__ == "__main__":
    sys.exit(main())
