"""Ctrl-C around third-party code that would swallow it.

trimesh imports its optional dependencies and some of its own submodules inside ``try: ... except BaseException``
(keeping a placeholder that fails later). A KeyboardInterrupt that lands in one of those imports is swallowed: the
command goes on with a half-imported trimesh and may fail later or write different results. :func:`import_trimesh`
holds a Ctrl-C until the import is over, then delivers it.
"""

from __future__ import annotations

import contextlib
import signal
import threading
from types import ModuleType
from typing import Iterator

__all__ = ["deferred_interrupt", "import_trimesh", "import_pyrender"]


@contextlib.contextmanager
def deferred_interrupt() -> Iterator[None]:
    """Hold SIGINT during the block; when one came, hand it to the previous handler at the end."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    received: list[int] = []
    previous = signal.signal(signal.SIGINT, lambda signum, frame: received.append(signum))
    try:
        yield
    finally:
        signal.signal(signal.SIGINT, previous)
        if received and callable(previous):
            previous(signal.SIGINT, None)   # Python's default handler raises KeyboardInterrupt here


def import_trimesh() -> ModuleType:
    with deferred_interrupt():
        import trimesh
    return trimesh


def import_pyrender() -> ModuleType:
    with deferred_interrupt():
        import pyrender   # imports trimesh
    return pyrender
