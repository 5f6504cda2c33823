"""``RunLock``: one pipeline run per output directory at a time.

``run_pipeline`` (hence ``sot-apps run`` and ``sot-apps demo``) holds an exclusive ``flock`` on
``OUT/.sot-apps-run.lock`` for the whole run. A second run into the same directory is refused at once
with one line naming the holder (pid, host, start time) instead of redoing the same units and racing
on the same files. The operating system drops the lock when the holder exits, even on a crash or
SIGKILL, so a lock is never stale; the file itself stays (empty after a clean run).

The lock is re-entrant inside one process (a nested ``run_pipeline`` into the same directory reuses it).
It is advisory and local: it protects runs on one machine (or on a file system whose ``flock`` is
shared, e.g. a local disk; NFS ``flock`` support depends on the mount).
"""

from __future__ import annotations

import datetime
import fcntl
import os
import socket
from pathlib import Path

from ..errors import InputError

__all__ = ["LOCK_NAME", "RunLock"]


def _output_error(out: Path, exc: OSError) -> Exception:
    """The one-line error naming the output directory (an environment fault) or the lock file (anything else)."""
    from ..io.atomic import is_environment_error, output_error

    if is_environment_error(exc):
        return output_error(out, exc)
    return InputError(out / LOCK_NAME, f"cannot lock the output directory ({exc.strerror or exc})")

LOCK_NAME = ".sot-apps-run.lock"

# resolved lock path -> [file descriptor, depth] of the locks this process holds
_HELD: dict[Path, list[int]] = {}


class RunLock:
    """Context manager: hold ``out/.sot-apps-run.lock`` or raise InputError if another process holds it."""

    def __init__(self, out: str | Path):
        self.path = (Path(out) / LOCK_NAME).resolve()

    def __enter__(self) -> "RunLock":
        held = _HELD.get(self.path)
        if held is not None:
            held[1] += 1
            return self
        try:
            self.path.parent.mkdir(parents=True, exist_ok=True)
            fd = os.open(self.path, os.O_RDWR | os.O_CREAT, 0o644)
        except OSError as exc:
            raise _output_error(self.path.parent, exc) from None
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            holder = os.pread(fd, 512, 0).decode("utf-8", "replace").strip() or "another process"
            os.close(fd)
            raise InputError(self.path.parent, f"another pipeline run is writing into this output directory "
                                               f"({holder}); wait for it to finish or choose another --out") from None
        except OSError as exc:
            os.close(fd)
            raise InputError(self.path, f"cannot lock the output directory ({exc.strerror})") from None
        stamp = datetime.datetime.now(datetime.timezone.utc).strftime("%Y-%m-%d %H:%M:%S UTC")
        try:
            os.ftruncate(fd, 0)
            os.pwrite(fd, f"pid {os.getpid()} on {socket.gethostname()}, started {stamp}\n".encode(), 0)
        except OSError as exc:  # e.g. a full disk: the run could not write its outputs either
            fcntl.flock(fd, fcntl.LOCK_UN)
            os.close(fd)
            raise _output_error(self.path.parent, exc) from None
        _HELD[self.path] = [fd, 1]
        return self

    def __exit__(self, *exc_info) -> None:
        held = _HELD[self.path]
        held[1] -= 1
        if held[1]:
            return
        del _HELD[self.path]
        try:
            os.ftruncate(held[0], 0)   # no holder recorded once the run is over
        finally:
            fcntl.flock(held[0], fcntl.LOCK_UN)
            os.close(held[0])
