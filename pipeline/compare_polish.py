"""A polished maximum checked by a second method, cell by cell (issue 44, item 2).

    python -m pipeline.compare_polish SCENE [--cells N] [--truncate K]

The second method shares no optimiser run with the polish: around the polished arg-max a dense
local grid of 5 points per free axis (spacing 1/8 of the scene's grid step, so it spans one grid
step) and a bounded Nelder-Mead run from the grid's best point moved half a grid step, both at
the polish's solver rtol.  The cell agrees when the better of the two is within the reduction's
``polish_tolerance`` (relative) of the polished value: a polish that stopped short of the
maximum is beaten by its neighbours (the negative control, ``--truncate K``: every start capped
at K solves, must fail).  ``tests/test_polish_agreement.py`` holds it on >= 20 shipped cells.

Bad arguments: one line naming the argument, exit code 2.
"""

from __future__ import annotations

import argparse
import itertools
import json
import sys
from dataclasses import dataclass, replace

import numpy as np

__all__ = ["Agreement", "cell_scene", "solve_grid", "polish_cell", "second_method", "agreement"]

#: points per free axis of the dense local grid, and its spacing in grid steps
DENSE_POINTS, DENSE_SPACING = 5, 1 / 8


def cell_scene(scene, **values):
    """``scene`` with each kept axis named in ``values`` held at that one value (one cell)."""
    from ._scene import Axis

    axes = tuple(Axis(a.name, (float(values[a.name]),), a.spacing) if a.name in values else a
                 for a in scene.axes)
    return replace(scene, axes=axes)


def solve_grid(scene, outputs) -> dict[str, np.ndarray]:
    """Every point of ``scene``'s grid solved at its rtol (no sweeps): {name: shape scene.shape}."""
    from ._grid import region_parameters, solve_points

    params = region_parameters(scene, tuple(slice(0, n) for n in scene.shape))
    vals = solve_points(scene.family, params, tuple(outputs), method=scene.method, rtol=scene.rtol)
    return {k: np.asarray(v).reshape(scene.shape) for k, v in vals.items() if k != "status"}


def polish_cell(scene, r, data, **overrides) -> list[tuple[dict, dict]]:
    """(cell, record) for every cell of ``scene`` (usually one: ``cell_scene``), polished as a
    run polishes it (``overrides``: ``pipeline.polish.polish_cells``'s)."""
    from ._reduce import polish_starts
    from .polish import polish_cells

    cells = polish_starts(scene, r, data)
    return list(zip(cells, polish_cells(scene, r, cells, **overrides)))


def second_method(scene, r, cell, record) -> tuple[float, int]:
    """The best objective the second method finds for ``cell`` (module docstring) and its solver
    calls: a dense local grid around ``record``'s arg-max and Nelder-Mead from the grid's best
    point moved half a grid step."""
    from .polish import PolishSpace, maximise, polish_rtol, solve_objective

    space = PolishSpace(scene, r)
    rtol = polish_rtol(scene, r)
    bounds = space.bounds(cell["subset"])
    best, calls = -np.inf, 0
    if record["values"] is not None:
        x0 = space.to_x(record["params"])
        offsets = (np.arange(DENSE_POINTS) - DENSE_POINTS // 2) * DENSE_SPACING
        seen = set()
        for k in itertools.product(offsets, repeat=len(space.free)):
            x = np.clip(x0 + np.asarray(k) * space.step, bounds[:, 0], bounds[:, 1])
            key = tuple(np.round(x, 13))
            if key in seen:
                continue
            seen.add(key)
            best = max(best, solve_objective(scene, r, space.params(record["params"], x), rtol)[0])
            calls += 1
    start = cell["starts"][0]
    xs = space.to_x(start)
    xs = np.clip(xs + 0.5 * space.step * np.where(xs + 0.5 * space.step <= bounds[:, 1], 1, -1),
                 bounds[:, 0], bounds[:, 1])
    nm = maximise(lambda x: solve_objective(scene, r, space.params(start, x), rtol), xs, bounds, space.step,
                  tolerance=r.polish_tolerance / 10, max_evaluations=2000, method="Nelder-Mead")
    return max(best, nm.value), calls + nm.evaluations


@dataclass(frozen=True)
class Agreement:
    """One cell: polished value, the second method's, their relative difference (second above
    the polish counts positive) and the verdict at ``tolerance``."""

    cell: dict
    polished: float
    second: float
    relative: float
    tolerance: float
    status: int
    evaluations: int
    second_evaluations: int

    @property
    def agrees(self) -> bool:
        return bool(np.isfinite(self.relative) and self.relative <= self.tolerance)


def agreement(scene, r, cell, record) -> Agreement:
    """The second method against ``record`` for ``cell`` (objective values, ``_reduce.objective``)."""
    from ._reduce import objective

    second, calls = second_method(scene, r, cell, record)
    pol = (float(objective(r.statistic, np.array([record["values"][r.quantity]]))[0])
           if record["values"] is not None else -np.inf)
    rel = (second - pol) / max(abs(pol), 1e-300) if np.isfinite(pol) else np.inf
    return Agreement({k: v for k, v in cell.items() if k != "starts"}, pol, second, float(rel),
                     r.polish_tolerance, int(record["status"]), int(record["evaluations"]), calls)


def _kept_cells(scene, r, n: int) -> list[dict]:
    """``n`` kept grid positions of ``r`` spread evenly over the scene's kept grid (C order)."""
    kept = [a for a in scene.axes if a.name not in r.over]
    total = int(np.prod([a.size for a in kept], dtype=np.int64))
    picks = np.unique(np.linspace(0, total - 1, min(n, total)).round().astype(int))
    out = []
    for k in picks:
        idx = np.unravel_index(int(k), tuple(a.size for a in kept))
        out.append({a.name: float(a.values[i]) for a, i in zip(kept, idx)})
    return out


def main(argv=None) -> int:
    class Parser(argparse.ArgumentParser):
        def error(self, message):  # one line, exit 2
            print(f"{self.prog}: {message}", file=sys.stderr)
            raise SystemExit(2)

    parser = Parser(prog="python -m pipeline.compare_polish", description=__doc__.split("\n\n")[1])
    parser.add_argument("scene", help="scene TOML file or a shipped scene's name (a grid scene with a polished reduction)")
    parser.add_argument("--cells", type=int, default=4, help="kept grid cells per polished reduction, spread evenly (4)")
    parser.add_argument("--truncate", type=int, default=None, metavar="K",
                        help="cap every start at K solves (the negative control: the check must fail)")
    args = parser.parse_args(argv)
    from pathlib import Path

    from ._registry import load_scene
    from ._scene import SceneError

    path = Path(args.scene)
    if not path.is_file():
        from .__main__ import WORKFLOWS

        path = WORKFLOWS / f"{args.scene}.toml"
    if not path.is_file():
        print(f"scene: {args.scene} is neither a file nor a shipped scene", file=sys.stderr)
        return 2
    if args.cells < 1:
        print(f"--cells: {args.cells} is not >= 1", file=sys.stderr)
        return 2
    if args.truncate is not None and args.truncate < 1:
        print(f"--truncate: {args.truncate} is not >= 1", file=sys.stderr)
        return 2
    try:
        scene = load_scene(path)
    except SceneError as exc:
        print(str(exc), file=sys.stderr)
        return 2
    reductions = [r for r in getattr(scene, "reductions", ()) if r.polish]
    if not reductions:
        print(f"scene: {scene.name} has no polished reduction", file=sys.stderr)
        return 2
    overrides = {"max_evaluations": args.truncate} if args.truncate else {}
    rows = []
    for r in reductions:
        for where in _kept_cells(scene, r, args.cells):
            one = cell_scene(scene, **where)
            data = solve_grid(one, [r.quantity, *r.report])
            for cell, rec in polish_cell(one, r, data, **overrides):
                a = agreement(one, r, cell, rec)
                rows.append(a)
                label = ", ".join(f"{k} {v:g}" for k, v in where.items())
                sub = f", subset {cell['subset']}" if cell["subset"] is not None else ""
                print(f"  {r.name}: {label}{sub}: polished {a.polished:.7g} (status {a.status}, {a.evaluations} solves), "
                      f"second {a.second:.7g} ({a.second_evaluations} solves): {a.relative:+.1e} -> "
                      f"{'agrees' if a.agrees else 'DIFFERS'}")
    failed = sum(not a.agrees for a in rows)
    verdict = {"scene": scene.name, "cells": len(rows), "differ": failed,
               "worst": max((a.relative for a in rows), default=float("nan")),
               "truncated": args.truncate, "verdict": "pass" if not failed else "fail"}
    print(f"{len(rows)} cells, {failed} differ from the second method by more than the polish tolerance -> {verdict['verdict']}")
    print(json.dumps(verdict))
    return 0


if __name__ == "__main__":
    sys.exit(main())
