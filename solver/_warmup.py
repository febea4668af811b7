"""Compile the solver's kernels ahead of use, by one small solve per kernel set.

numba compiles a kernel on its first call and caches it on disk (``_cache``): the first
``solve_periodic`` of a fresh checkout compiles for about a minute on 2 cores, later processes
load the kernels in a second or two.  A driver that fans work out to worker processes calls
``warm_up`` first, so the workers load the cache instead of each compiling the same kernels.
The problems solved are fixed and tiny; the kernels depend only on argument types, which every
family, method and force-law exponent share (measured: after ``warm_up`` of a set, a run of the
shipped scenes that use it compiles nothing more).
"""
from __future__ import annotations

import os
import sys
import time
from dataclasses import dataclass

import numpy as np

from .solve import METHODS

#: kernel sets by name, and the calls that compile them: one per method of ``solve_periodic``
KERNEL_SETS = {
    **{method: f"solve_periodic with method {method} (every family, series output)" for method in METHODS},
    "fixed_grid": "solve_fixed_grid with methods periodic and march",
    "gradient": "objective_gradient and optimize_motion",
}

_warm: set[str] = set()


@dataclass(frozen=True)
class KernelCache:
    """numba's on-disk cache of the solver's kernels: ``directory`` (None if caching is off)
    and whether it already holds compiled kernels (``populated``)."""

    directory: str | None
    populated: bool


@dataclass(frozen=True)
class WarmUp:
    """What ``warm_up`` did: the sets it warmed (those not already warm in this process), the
    wall time, and how many kernels it compiled rather than loaded from the cache."""

    kernel_sets: tuple[str, ...]
    seconds: float
    compiled: int


def _dispatchers():
    from numba.core.dispatcher import Dispatcher

    package = __name__.rpartition(".")[0]
    for name, module in list(sys.modules.items()):
        if module is not None and (name == package or name.startswith(package + ".")):
            for value in vars(module).values():
                if isinstance(value, Dispatcher):
                    yield value


def compiled_count() -> int:
    """Kernels compiled in this process so far (numba's cache misses)."""
    return sum(sum(d.stats.cache_misses.values()) for d in set(_dispatchers()))


def kernel_cache() -> KernelCache:
    """Where the solver's kernels are cached, and whether any are there yet."""
    for d in _dispatchers():
        path = getattr(getattr(d, "stats", None), "cache_path", None)
        if path:
            populated = os.path.isdir(path) and any(f.endswith(".nbi") for f in os.listdir(path))
            return KernelCache(path, populated)
    return KernelCache(None, False)


def _solve(kernel_set: str) -> None:
    from .model.kinematics import Fourier, Harmonic, PowerLaw
    from .adjoint.optimize import optimize_motion
    from .model.physics import Physics
    from .solve import solve_fixed_grid, solve_periodic

    # Batches of four points whose grids differ in size: a batch's kernels see strided views of
    # its arrays (numba compiles those apart from contiguous ones), as a chunk of a scene does.
    physics = Physics.from_scaled(anisotropy_ratio=np.array([0.0625, 0.25, 4.0, 16.0]),
                                  scaled_period=np.array([0.5, 1.0, 2.0, 4.0]), p=0.0, delta=1e-5)
    a0, a1 = np.array([1.2, 1.0, 0.6, 0.4]), np.array([0.3, 0.4, 0.5, 0.35])
    harmonic = Harmonic(A0=a0, A1=a1)
    if kernel_set in METHODS:
        ones = np.ones(4, dtype=bool)
        for kinematics in (harmonic, PowerLaw(a0, a1, np.full(4, 0.5), np.full(4, 3.0), ones, np.ones(4), ~ones),
                           Fourier(np.column_stack([a0, a1, 0.1 * a1]), np.column_stack([0 * a1, 0.1 * a1]))):
            solve_periodic(kinematics, physics, method=kernel_set, rtol=1e-3, return_series=True)
    elif kernel_set == "fixed_grid":
        for method in ("periodic", "march"):
            solve_fixed_grid(harmonic, physics, 16, method=method)
    elif kernel_set == "gradient":
        template = Fourier(np.array([[0.5, 0.5]]), np.zeros((1, 1)))
        start = Physics.from_scaled(0.25, 2.0, p=0.0, delta=1e-5)
        optimize_motion(template, start, objective="efficiency", max_iterations=3)
    else:
        raise ValueError(f"kernel set {kernel_set!r}: must be one of {', '.join(KERNEL_SETS)}")


def warm_up(kernel_sets=("periodic",)) -> WarmUp:
    """Compile (or load from the on-disk cache) the kernels of ``kernel_sets``, keys of
    ``KERNEL_SETS``, in this process; sets already warm here are skipped.

    Raises ValueError for an unknown set (before solving anything).
    """
    unknown = [k for k in kernel_sets if k not in KERNEL_SETS]
    if unknown:
        raise ValueError(f"kernel set {unknown[0]!r}: must be one of {', '.join(KERNEL_SETS)}")
    todo = tuple(k for k in dict.fromkeys(kernel_sets) if k not in _warm)
    before, t0 = compiled_count(), time.perf_counter()
    for kernel_set in todo:
        _solve(kernel_set)
        _warm.add(kernel_set)
    return WarmUp(todo, time.perf_counter() - t0, compiled_count() - before)
