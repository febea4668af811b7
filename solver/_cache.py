"""numba's on-disk cache for the solver's kernels, keyed on the solver's sources.

numba (``cache=True``) invalidates a cached kernel only when its own file changes, not when
a kernel it calls, in another module, does: a stale cached ``adjoint.gradient._forward`` kept the
old ``_periodic.radau_step`` compiled into it, and once loaded its copy was linked into
freshly compiled kernels of the same signature too (measured: a test of ``radau_step``'s
new behaviour failed after the gradient tests had run, and passed alone or after the cache
was cleared; numba PR 8396, dependency-aware invalidation, is not merged).  Keying the
cache directory on a hash of every source file of the package makes any edit start a
fresh cache.  numba fixes a kernel's cache directory when it is decorated, so the key is
set while the solver's modules are imported and the previous setting restored after: other
packages' kernels keep theirs.  A configured cache directory (NUMBA_CACHE_DIR) is the base;
an unwritable one (a read-only install) falls back to ~/.cache/twolink-numba, keyed too
(numba's own fallbacks are not keyed).  Every edit leaves a directory behind (~8 MB): in
the two default locations (not in a configured NUMBA_CACHE_DIR, which other packages and
checkouts may share) all but the KEEP_CACHES most recently used are removed when a new one
is made.  A process still running an older version whose directory is removed recompiles
what it needs again.
"""
from __future__ import annotations

import hashlib
import os
import re
import shutil
import tempfile
from pathlib import Path

import numba

#: source-keyed cache directories kept (the current one and the most recently used others:
#: switching between a few versions, as in an A/B timing, does not recompile)
KEEP_CACHES = 4


def source_digest(package=Path(__file__).parent):
    """Short hash of the contents of every ``*.py`` file of the package, its subpackages'
    included (a kernel in ``periodic/`` calls kernels in ``model/``)."""
    digest = hashlib.sha256()
    for path in sorted(package.rglob("*.py")):
        if "__pycache__" in path.parts:
            continue
        digest.update(path.relative_to(package).as_posix().encode())
        digest.update(path.read_bytes())
    return digest.hexdigest()[:16]


def _writable(directory):
    try:
        os.makedirs(directory, exist_ok=True)
        with tempfile.NamedTemporaryFile(dir=directory):
            return True
    except OSError:
        return False


def package_cache_base():
    """The default base of the cache directories: the package's ``__pycache__``."""
    return str(Path(__file__).parent / "__pycache__")


def use_source_keyed_cache():
    """Point numba's cache at a directory named by ``source_digest``; call it before the
    kernels are decorated.  Returns the previous setting, for ``restore_cache_dir``."""
    previous = numba.config.CACHE_DIR
    name = f"numba-{source_digest()}"
    fallback = os.path.join(os.path.expanduser("~"), ".cache", "twolink-numba")
    for base, ours in ((previous, False), (package_cache_base(), True), (fallback, True)):
        if not base:
            continue
        path = os.path.join(base, name)
        fresh = not os.path.isdir(path)
        if _writable(path):
            os.utime(path)  # marks it used, for prune_caches
            if fresh and ours:
                prune_caches(base, KEEP_CACHES)
            break
    numba.config.CACHE_DIR = path
    return previous


_CACHE_NAME = re.compile(r"numba-[0-9a-f]{16}")


def prune_caches(base, keep):
    """Remove all but the ``keep`` most recently used source-keyed directories
    (``numba-<16 hex digits>``) in ``base``; entries that vanish meanwhile (another process
    pruning too) are skipped."""
    caches = []
    for path in Path(base).iterdir():
        if _CACHE_NAME.fullmatch(path.name):
            try:
                caches.append((path.stat().st_mtime, path))
            except OSError:
                continue
    caches.sort(reverse=True)
    for _, stale in caches[keep:]:
        shutil.rmtree(stale, ignore_errors=True)


def restore_cache_dir(previous):
    """Give numba back the cache directory ``use_source_keyed_cache`` replaced."""
    numba.config.CACHE_DIR = previous
