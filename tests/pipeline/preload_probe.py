"""A task for tests/pipeline/test_executors.py, importable in worker processes: what the worker has loaded."""

from __future__ import annotations

import os
import sys


def loaded(name: str) -> tuple[bool, int, int]:
    """Whether module ``name`` is loaded in this process (without importing it), its pid and its parent's pid."""
    return name in sys.modules, os.getpid(), os.getppid()
