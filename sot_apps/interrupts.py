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
import time
from types import ModuleType
from typing import Iterator

__all__ = ["deferred_interrupt", "import_trimesh", "import_pyrender", "sigint_ignored_in_children", "ignore_sigint",
           "stop_process_pool"]


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


@contextlib.contextmanager
def sigint_ignored_in_children() -> Iterator[None]:
    """Start worker processes with SIGINT ignored: an ignored signal stays ignored across fork and exec (a blocked
    one does not: the spawn resets the mask) and Python then installs no KeyboardInterrupt handler, so a Ctrl-C
    while a worker starts cannot print its traceback. Only while the processes are created does this process
    ignore Ctrl-C as well."""
    if threading.current_thread() is not threading.main_thread():   # only the main thread may set handlers
        yield
        return
    previous = signal.signal(signal.SIGINT, signal.SIG_IGN)
    try:
        yield
    finally:
        signal.signal(signal.SIGINT, previous)


def ignore_sigint() -> None:
    """Initializer of worker processes that leave Ctrl-C to their parent (which stops them:
    :func:`stop_process_pool`)."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)


def import_trimesh() -> ModuleType:
    with deferred_interrupt():
        import trimesh
    return trimesh


def import_pyrender() -> ModuleType:
    with deferred_interrupt():
        import pyrender  # imports trimesh
    return pyrender


def stop_process_pool(pool, grace_s: float = 1.0) -> None:
    """After Ctrl-C: stop a ``concurrent.futures.ProcessPoolExecutor`` promptly.

    Queued tasks are cancelled; the workers (which got the same SIGINT: their running task stops and its atomic
    writes clean up) have ``grace_s`` seconds to exit; a worker still alive then (in a long C call, or starting a
    task that was already handed to it) is terminated, so the command exits within about ``grace_s`` seconds
    instead of finishing that task first. A terminated worker may leave temporary files (``.NAME.XXXX.tmp``):
    the caller, which holds the output directory's lock, removes them (``io.atomic.remove_stale_temporaries``) or
    its next run does.
    """
    processes = list((getattr(pool, "_processes", None) or {}).values())
    pool.shutdown(wait=False, cancel_futures=True)
    deadline = time.monotonic() + grace_s
    for process in processes:
        process.join(max(0.0, deadline - time.monotonic()))
    for process in processes:
        if process.is_alive():
            process.terminate()
    for process in processes:
        process.join(1.0)
