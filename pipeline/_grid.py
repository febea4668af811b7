"""Parameter grid: chunk layout and the mapping from scene parameters to solver inputs.

Pure functions of arrays; no I/O.
"""

from __future__ import annotations

import itertools
import math

import numpy as np

from ._scene import Scene

__all__ = [
    "DEFAULT_POINTS_PER_TASK",
    "chunk_shape",
    "chunk_grid",
    "chunk_region",
    "iter_chunks",
    "region_parameters",
    "solve_points",
]

#: Points per task by family, tuned so a task takes a few seconds with the real solver
#: at rtol ~ 1e-4 (harmonic ~ 2-5k solves/s per core; power law with sticking slower).
DEFAULT_POINTS_PER_TASK = {"harmonic": 4096, "powerlaw": 2048}


def chunk_shape(shape: tuple[int, ...], target: int) -> tuple[int, ...]:
    """Chunk shape with about ``target`` points, filling the trailing axes first.

    Trailing axes are usually the kinematic parameters that reductions run over, so a chunk
    holds whole contiguous slabs of them.
    """
    chunks = [1] * len(shape)
    inner = 1
    for i in range(len(shape) - 1, -1, -1):
        c = max(1, min(shape[i], target // inner))
        chunks[i] = c
        inner *= c
        if c < shape[i]:
            break
    return tuple(chunks)


def chunk_grid(shape, chunks) -> tuple[int, ...]:
    """Number of chunks along each axis."""
    return tuple(math.ceil(s / c) for s, c in zip(shape, chunks))


def chunk_region(index: tuple[int, ...], shape, chunks) -> tuple[slice, ...]:
    """The region of the full grid covered by chunk ``index`` (edge chunks are clipped)."""
    return tuple(slice(i * c, min((i + 1) * c, s)) for i, c, s in zip(index, chunks, shape))


def iter_chunks(shape, chunks):
    """All chunk indices in C order."""
    return itertools.product(*(range(n) for n in chunk_grid(shape, chunks)))


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


def _kinematics(solver, family: str, params: dict[str, np.ndarray]):
    A0 = params["A0"]
    A1 = params["A1_ratio"] * A0
    if family == "harmonic":
        return solver.Harmonic(A0=A0, A1=A1)
    closing, opening = params["closing_shape"], params["opening_shape"]
    return solver.PowerLaw(A0, A1, params["duty_cycle"],
                           np.abs(closing).astype(np.float64), closing > 1,
                           np.abs(opening).astype(np.float64), opening > 1)


def solve_points(family: str, params: dict[str, np.ndarray], outputs, *, method: str, rtol: float):
    """Solve at the points ``params`` (each shape (n,)) and return the requested outputs.

    Returns
    -------
    dict of ndarray, shape (n,)
        One entry per name in ``outputs`` plus ``status`` (int8).
    """
    import solver  # imported here so worker processes import it lazily

    kin = _kinematics(solver, family, params)
    phys, _ = _physics(solver, params)
    res = solver.solve_periodic(kin, phys, method=method, rtol=rtol, return_series=False)
    out = {"status": np.asarray(res.status, dtype=np.int8)}
    for name in outputs:
        if name == "displacement_per_period":
            # T U, the distance per period; scale-free, so equal to scaled_period * scaled_speed.
            period = np.broadcast_to(np.asarray(phys.period, dtype=np.float64), np.shape(res.U))
            out[name] = period * np.asarray(res.U, dtype=np.float64)
        else:
            out[name] = np.asarray(getattr(res, name))
    return out
