"""Two optima ensembles cell by cell, judged against a reseeded baseline.

    python -m pipeline.compare_optima BASE NEW [--control RESEED] [--rtol 1e-4]

BASE and NEW are stores of one optima scene (kind "optima", version 2: the optima solved
again by the engine), e.g. the baseline optimiser and a changed one.  Per cell (every
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

__all__ = ["CellTable", "compare_cells", "judge", "read_cells", "STILL"]

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
    """The cells of an optima store (KIND_VERSION 2): the best kept optimum's |lambda| /
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
    args = parser.parse_args(argv)
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
    print(json.dumps(verdict))
    return 0


if __name__ == "__main__":
    sys.exit(main())
