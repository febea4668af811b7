"""Parameter grid: block layout and the mapping from scene parameters to solver inputs.

Pure functions of arrays; no I/O.
"""

from __future__ import annotations

import itertools
import math

import numpy as np

from ._grid_scene import DEFAULT_POINTS_PER_CHUNK, Scene

__all__ = [
    "DEFAULT_POINTS_PER_CHUNK",
    "calibrate_points_per_task",
    "chunks_per_task",
    "chunk_shape",
    "scene_chunks",
    "chunk_grid",
    "chunk_region",
    "iter_chunks",
    "region_parameters",
    "solve_points",
    "chunk_sweeps",
]

#: Wall time aimed at for one task: long enough that scheduling and store overheads are
#: negligible, short enough that a killed run loses little and the progress bar moves.
TASK_SECONDS = 4.0
#: Bounds of the calibrated points per task.
MIN_POINTS_PER_TASK, MAX_POINTS_PER_TASK = 16, 16384


def calibrate_points_per_task(scene: Scene, workers: int, n_probe: int = 16) -> tuple[int, float]:
    """Points per task so that a task takes about ``TASK_SECONDS``, from a timed probe.

    The probe solves ``n_probe`` points spread evenly over the scene's grid (after one
    untimed warm-up point, which pays any JIT compilation).  It decides only how many whole
    chunks one task takes (:func:`chunks_per_task`), never where chunks begin
    (:func:`scene_chunks`), so the machine's load changes no stored value.

    Returns
    -------
    points_per_task : int
    rate : float  [solves/s on one core]
    """
    import time

    n = scene.n_points
    flat = np.unique(np.linspace(0, n - 1, min(n_probe, n)).round().astype(np.int64))
    idx = np.unravel_index(flat, scene.shape)
    params = {a.name: a.array()[i] for a, i in zip(scene.axes, idx)}
    for k, v in scene.fixed:
        params[k] = np.full(flat.size, v)
    warm = {k: v[:1] for k, v in params.items()}
    solve_points(scene.family, warm, (), method=scene.method, rtol=scene.rtol)
    t0 = time.perf_counter()
    solve_points(scene.family, params, (), method=scene.method, rtol=scene.rtol)
    rate = flat.size / max(time.perf_counter() - t0, 1e-9)
    target = int(rate * TASK_SECONDS)
    # At least ~4 tasks per worker, so the last tasks do not leave cores idle for long.
    target = min(target, -(-n // (4 * max(1, workers))))
    return int(np.clip(target, MIN_POINTS_PER_TASK, MAX_POINTS_PER_TASK)), rate


def chunk_shape(shape: tuple[int, ...], target: int) -> tuple[int, ...]:
    """Chunk shape of at most ``target`` points (at least one point), filling the trailing axes first.

    Trailing axes are whole while they fit; the axis where ``target`` runs out is cut into the
    fewest pieces that fit, of equal length (the last one shorter by the remainder), and the
    axes before it are cut to length 1.  Trailing axes are usually the kinematic parameters
    that reductions run over, so a chunk holds whole contiguous slabs of them.

    >>> chunk_shape((3, 3, 20, 20), 256)   # 20 rows of 20 fit 12 at a time: 2 pieces of 10
    (1, 1, 10, 20)
    """
    chunks = [1] * len(shape)
    inner = 1
    for i in range(len(shape) - 1, -1, -1):
        fit = max(1, target // inner)
        if shape[i] <= fit:
            chunks[i] = shape[i]
            inner *= shape[i]
            continue
        pieces = -(-shape[i] // fit)
        chunks[i] = -(-shape[i] // pieces)
        break
    return tuple(chunks)


def scene_chunks(scene: Scene) -> tuple[int, ...]:
    """The block shape of ``scene``'s store (what a task solves at a time; its chunks are whole
    blocks, ``_store.storage_chunks``): a function of the scene alone.

    :func:`chunk_shape` of the grid's shape and ``[execution] points_per_chunk`` (default
    :data:`DEFAULT_POINTS_PER_CHUNK`); no timing, worker count or load enters it.
    """
    target = getattr(scene.execution, "points_per_chunk", None) or DEFAULT_POINTS_PER_CHUNK
    return chunk_shape(scene.shape, target)


def chunks_per_task(points_per_task: int, points_per_chunk: int) -> int:
    """Whole chunks one task takes: as many as fit in ``points_per_task`` points, at least one."""
    return max(1, int(points_per_task) // max(1, int(points_per_chunk)))


def chunk_grid(shape, chunks) -> tuple[int, ...]:
    """Number of chunks along each axis."""
    return tuple(math.ceil(s / c) for s, c in zip(shape, chunks))


def chunk_region(index: tuple[int, ...], shape, chunks) -> tuple[slice, ...]:
    """The region of the full grid covered by chunk ``index`` (edge chunks are clipped)."""
    return tuple(slice(i * c, min((i + 1) * c, s)) for i, c, s in zip(index, chunks, shape))


def iter_chunks(shape, chunks):
    """All chunk indices in C order."""
    return itertools.product(*(range(n) for n in chunk_grid(shape, chunks)))


def chunk_sweeps(shape: tuple[int, ...]) -> tuple[np.ndarray, np.ndarray]:
    """How a chunk of ``shape`` is solved as sweeps: (order, runs) for
    ``solver.solve_periodic(..., sweeps=runs)`` on the chunk's points taken in ``order``
    (``solver.snake_order``), runs cutting it into sweeps of ``solver.SWEEP_POINTS`` (so that a task's sweeps share its
    cores; a constant, never a timing).  A function of the
    chunk's shape alone: warm starts never cross a chunk's boundary, so a chunk's values
    depend only on its own points, and a resumed store equals an uninterrupted run."""
    from solver import snake_order, sweep_runs

    order = snake_order(shape)
    runs = sweep_runs(order.size)
    return order, runs


def region_parameters(scene: Scene, region: tuple[slice, ...]) -> dict[str, np.ndarray]:
    """Parameter values at every point of ``region``, each shape (n,) in C order of the region."""
    axes_vals = [a.array()[sl] for a, sl in zip(scene.axes, region)]
    mesh = np.meshgrid(*axes_vals, indexing="ij")
    params = {a.name: m.ravel() for a, m in zip(scene.axes, mesh)}
    n = mesh[0].size if mesh else 1
    for k, v in scene.fixed:
        params[k] = np.full(n, v)
    return params


def _physics(solver, params: dict[str, np.ndarray]):
    """Physics from scene parameters; always through the scaled pair (mu_n mu_s = 1)."""
    p = params["p"]
    if "anisotropy_ratio" in params:
        ratio, scaled_period = params["anisotropy_ratio"], params["scaled_period"]
    else:
        # T^(2-p) mu_n = a, T^(2-p) mu_s = b  =>  mu_n/mu_s = a/b, (mu_n mu_s)^(1/(4-2p)) T = (ab)^(1/(4-2p)).
        a, b = params["T2_mu_n"], params["T2_mu_s"]
        ratio, scaled_period = a / b, (a * b) ** (1.0 / (4.0 - 2.0 * p))
    phys = solver.Physics.from_scaled(anisotropy_ratio=ratio, scaled_period=scaled_period, p=p,
                                      delta=params["delta"])
    return phys, scaled_period


def fourier_kinematics(solver, params: dict[str, np.ndarray]):
    """``solver.Fourier`` from a Fourier grid scene's parameters A0, A1.., B1.. (each shape (n,)
    or a scalar): Kmax is the largest wavenumber given, a coefficient not given is 0."""
    from ._grid_scene import fourier_wavenumber

    K = fourier_wavenumber(params)
    n = np.size(params["A0"])
    zero = np.zeros(n)
    A = np.column_stack([np.broadcast_to(np.asarray(params.get(f"A{k}", zero), dtype=np.float64), (n,))
                         for k in range(K + 1)])
    B = np.column_stack([np.broadcast_to(np.asarray(params.get(f"B{k}", zero), dtype=np.float64), (n,))
                         for k in range(1, K + 1)]) if K else np.zeros((n, 0))
    return solver.Fourier(A, B)


def _kinematics(solver, family: str, params: dict[str, np.ndarray]):
    if family == "fourier":
        return fourier_kinematics(solver, params)
    A0 = params["A0"]
    A1 = params["A1_ratio"] * A0
    if family == "harmonic":
        return solver.Harmonic(A0=A0, A1=A1)
    closing, opening = params["closing_shape"], params["opening_shape"]
    return solver.PowerLaw(A0, A1, params["duty_cycle"],
                           np.abs(closing).astype(np.float64), closing > 1,
                           np.abs(opening).astype(np.float64), opening > 1)


def solve_points(family: str, params: dict[str, np.ndarray], outputs, *, method: str, rtol: float,
                 series: bool = False, sweeps=None):
    """Solve at the points ``params`` (each shape (n,)) and return the requested outputs
    (``sweeps``: ``solver.solve_periodic``'s, the points in sweep order).

    Returns
    -------
    dict of ndarray, shape (n,)
        One entry per name in ``outputs`` plus ``status`` (int8); with ``series`` also ``u`` and
        ``tau``, lists of per-point arrays (the solver's final grid, tau in [0, 1)).
    """
    import solver  # imported here so worker processes import it lazily

    kin = _kinematics(solver, family, params)
    phys, _ = _physics(solver, params)
    res = solver.solve_periodic(kin, phys, method=method, rtol=rtol, return_series=series, sweeps=sweeps)
    out = {"status": np.asarray(res.status, dtype=np.int8)}
    if series:
        out["u"] = [np.asarray(v, dtype=np.float64) for v in res.u]
        out["tau"] = [np.asarray(v, dtype=np.float64) for v in res.tau]
    for name in outputs:
        if name == "displacement_per_period":
            # T U, the distance per period; scale-free, so equal to scaled_period * scaled_speed.
            period = np.broadcast_to(np.asarray(phys.period, dtype=np.float64), np.shape(res.U))
            out[name] = period * np.asarray(res.U, dtype=np.float64)
        else:
            out[name] = np.asarray(getattr(res, name))
    return out
