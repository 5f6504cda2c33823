"""The pipeline's run lock is the lock of every command that writes a directory: :mod:`sot_apps.io.lock`."""

from __future__ import annotations

from ..io.lock import LOCK_NAME, OutputLock

RunLock = OutputLock

__all__ = ["LOCK_NAME", "RunLock"]
