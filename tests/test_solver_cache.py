"""The source-keyed numba cache directory (``solver._cache``)."""
from __future__ import annotations

import os

import numba

from solver._cache import KEEP_CACHES, prune_caches, restore_cache_dir, source_digest, \
    use_source_keyed_cache


def _old_caches(base, count):
    paths = []
    for k in range(count):
        path = base / f"numba-{k:016x}"
        path.mkdir()
        os.utime(path, (1e9 + k, 1e9 + k))  # k = count - 1 most recently used
        paths.append(path)
    return paths


def test_prune_keeps_the_most_recently_used(tmp_path):
    paths = _old_caches(tmp_path, 6)
    (tmp_path / "other").mkdir()
    prune_caches(tmp_path, 4)
    assert sorted(p.name for p in tmp_path.iterdir()) == sorted(
        [p.name for p in paths[2:]] + ["other"])


def test_a_new_source_key_prunes_stale_caches_and_an_old_one_does_not(tmp_path):
    paths = _old_caches(tmp_path, KEEP_CACHES + 2)
    saved = numba.config.CACHE_DIR
    numba.config.CACHE_DIR = str(tmp_path)
    try:
        previous = use_source_keyed_cache()
        current = tmp_path / f"numba-{source_digest()}"
        assert numba.config.CACHE_DIR == str(current) and current.is_dir()
        restore_cache_dir(previous)
        kept = {p.name for p in tmp_path.iterdir()}
        assert kept == {current.name} | {p.name for p in paths[-(KEEP_CACHES - 1):]}
        # the current key again: nothing new, nothing removed
        restore_cache_dir(use_source_keyed_cache())
        assert {p.name for p in tmp_path.iterdir()} == kept
    finally:
        numba.config.CACHE_DIR = saved
