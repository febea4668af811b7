"""numba's on-disk cache, keyed on the solver's sources.

numba (``cache=True``) invalidates a cached kernel only when its own file changes, not when
a kernel it calls, in another module, does: a stale cached ``_gradient._forward`` kept the
old ``_periodic.radau_step`` compiled into it, and once loaded its copy was linked into
freshly compiled kernels of the same signature too (measured: a test of ``radau_step``'s
new behaviour failed after the gradient tests had run, and passed alone or after the cache
was cleared; numba PR 8396, dependency-aware invalidation, is not merged).  Keying the
cache directory on a hash of every source file of the package makes any edit start a
fresh cache.  An explicit NUMBA_CACHE_DIR is kept, with the hash as a subdirectory.
"""
from __future__ import annotations

import hashlib
import os
from pathlib import Path

import numba


def source_digest(package=Path(__file__).parent):
    """Short hash of the contents of the package's ``*.py`` files."""
    digest = hashlib.sha256()
    for path in sorted(package.glob("*.py")):
        digest.update(path.name.encode())
        digest.update(path.read_bytes())
    return digest.hexdigest()[:16]


def use_source_keyed_cache():
    """Point numba's cache at a directory named by ``source_digest``; call it before the
    kernels are decorated (numba resolves the directory then)."""
    base = os.environ.get("NUMBA_CACHE_DIR") or str(Path(__file__).parent / "__pycache__")
    numba.config.CACHE_DIR = os.path.join(base, f"numba-{source_digest()}")
