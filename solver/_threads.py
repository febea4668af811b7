"""One numba thread for a parallel kernel called on a single point.

A ``parallel=True`` kernel launched on one point has one iteration of work, but the launch
still hands it to numba's thread pool and waits for the pool; on a machine whose cores are
busy the waiting dominates: ``fast_limit_velocity`` of one Fourier point took 7.8-8.8 ms
with 2 numba threads at load 3-5 on 2 cores against 0.1-0.2 ms with one, and a whole
``solve_periodic`` of one point at rtol 1e-8 17-20 ms against 6-9 ms (docs/validation.md,
issue 35).  The optimiser, ``adaptive_grid`` and single-point commands call these kernels
one point at a time.  ``numba.set_num_threads`` is per calling thread, so this is safe under
dask's threads scheduler; results do not depend on the thread count (every point is
computed alone).
"""
from __future__ import annotations

from contextlib import contextmanager

import numba

__all__ = ["serial_when_single"]


@contextmanager
def serial_when_single(n_points: int):
    """Inside the block, numba's parallel kernels run on this thread alone where ``n_points``
    is 1 (the thread count is restored after); otherwise nothing changes."""
    threads = numba.get_num_threads()
    if n_points != 1 or threads == 1:
        yield
        return
    numba.set_num_threads(1)
    try:
        yield
    finally:
        numba.set_num_threads(threads)
