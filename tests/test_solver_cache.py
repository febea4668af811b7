"""The source-keyed numba cache directory (``solver._cache``)."""
from __future__ import annotations

import os

import numba
import pytest

from solver import _cache
from solver._cache import KEEP_CACHES, prune_caches, restore_cache_dir, source_digest, \
    use_source_keyed_cache


def _old_caches(base, count, start=0):
    paths = []
    for k in range(start, start + count):
        path = base / f"numba-{k:016x}"
        path.mkdir()
        os.utime(path, (1e9 + k, 1e9 + k))  # the larger k, the more recently used
        paths.append(path)
    return paths


def _names(base):
    return {p.name for p in base.iterdir()}


def test_prune_keeps_the_most_recently_used_and_only_touches_its_own(tmp_path):
    paths = _old_caches(tmp_path, 6)
    for other in ("other", "numba-not-a-source-key"):
        (tmp_path / other).mkdir()
    prune_caches(tmp_path, 4)
    assert _names(tmp_path) == {p.name for p in paths[2:]} | {"other", "numba-not-a-source-key"}


@pytest.fixture
def default_base(tmp_path, monkeypatch):
    """The package's default cache base redirected to ``tmp_path``, no NUMBA_CACHE_DIR."""
    saved = numba.config.CACHE_DIR
    numba.config.CACHE_DIR = ""
    monkeypatch.setattr(_cache, "package_cache_base", lambda: str(tmp_path))
    yield tmp_path
    numba.config.CACHE_DIR = saved


def test_a_new_source_key_prunes_stale_caches_and_a_known_one_does_not(default_base):
    paths = _old_caches(default_base, KEEP_CACHES + 2)
    previous = use_source_keyed_cache()
    current = default_base / f"numba-{source_digest()}"
    assert numba.config.CACHE_DIR == str(current) and current.is_dir()
    restore_cache_dir(previous)
    assert _names(default_base) == {current.name} | {p.name for p in paths[-(KEEP_CACHES - 1):]}
    # the current key again, with more than KEEP_CACHES around: nothing is removed
    more = _old_caches(default_base, 2, start=100)
    before = _names(default_base)
    assert len(before) > KEEP_CACHES and {p.name for p in more} <= before
    restore_cache_dir(use_source_keyed_cache())
    assert _names(default_base) == before


def test_a_configured_cache_dir_is_not_pruned(tmp_path):
    paths = _old_caches(tmp_path, KEEP_CACHES + 2)
    saved = numba.config.CACHE_DIR
    numba.config.CACHE_DIR = str(tmp_path)
    try:
        restore_cache_dir(use_source_keyed_cache())
    finally:
        numba.config.CACHE_DIR = saved
    assert _names(tmp_path) == {p.name for p in paths} | {f"numba-{source_digest()}"}
