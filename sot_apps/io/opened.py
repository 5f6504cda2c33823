"""The process-local cache of opened sequences: a sequence is opened once per process and kept between tasks."""

from __future__ import annotations

import functools

from . import open_sequence
from .sequence import Sequence

__all__ = ["open_cached"]


@functools.lru_cache(maxsize=8)
def open_cached(path: str, format: str | None = None) -> Sequence:
    """The worker-local sequence cache: every pipeline stage and app opens its sequence through this, so no task
    pays for opening a sequence another task of the same process opened. The pipeline runner fills it in every
    Dask worker before the first batch. Sweeps are read through the one-time conversion cache
    (:mod:`sot_apps.io.sweep_cache`)."""
    return open_sequence(path, format=format, cache=True)
