"""A task for tests/pipeline/test_executors.py, importable in worker processes: what the worker has loaded."""

from __future__ import annotations

import os
import sys


def loaded(name: str) -> tuple[bool, int, int]:
    """Whether module ``name`` is loaded in this process (without importing it), its pid and its parent's pid."""
    return name in sys.modules, os.getpid(), os.getppid()


def sequence_cache(path: str) -> dict:
    """What this worker's sequence cache held before opening ``path`` through it, whether that opening was a cache
    hit, whether the fork server's objects are frozen out of the garbage collector, and the warm-up variable."""
    import gc

    from sot_apps.io.opened import open_cached
    from sot_apps.pipeline.warm import WARM_VARIABLE

    before = open_cached.cache_info()
    open_cached(path, None)
    after = open_cached.cache_info()
    return {"held": before.currsize, "hit": after.hits == before.hits + 1 and after.misses == before.misses,
            "frozen": gc.get_freeze_count(), "variable": os.environ.get(WARM_VARIABLE), "pid": os.getpid()}
