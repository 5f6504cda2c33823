"""``OutputLock``: one sot-apps command at a time writes into an output directory.

Every command that writes a directory (``track``, ``flow``, ``simulate-lidar``, ``benchmark make|build``,
``bank build``, ``convert``, ``autolabel``, ``synth``, ``demo``, ``run``) holds an exclusive ``flock`` on
``OUT/.sot-apps.lock`` from before its work starts to its end. A second command into the same directory is refused
at once (exit code 2) with one line naming the lock file and its holder (pid, host, start time, command line),
instead of redoing the same work and racing on the same files (the last writer would win).

The operating system drops the lock when the holder exits, even on a crash or SIGKILL, so a lock is never stale.
On release the lock file is removed, and so are the directories the lock itself had to create when they are still
empty: a command rejected before it wrote anything leaves nothing behind. (Removal under the lock is safe: a
process that opened the old file and then got its lock checks that the name still leads to the file it locked,
and starts over otherwise.)

The lock is re-entrant inside one process (a nested lock on the same directory reuses it). It is advisory and
local: it protects commands on one machine (or on a file system whose ``flock`` is shared, e.g. a local disk; NFS
``flock`` support depends on the mount).
"""

from __future__ import annotations

import contextlib
import datetime
import fcntl
import os
import shlex
import sys
from pathlib import Path

from ..errors import InputError

__all__ = ["LOCK_NAME", "OutputLock"]

LOCK_NAME = ".sot-apps.lock"

# resolved lock path -> [file descriptor, depth, directories this lock created] of the locks this process holds
_HELD: dict[Path, list] = {}


def _output_error(out: Path, exc: OSError) -> Exception:
    """The one-line error naming the output directory (an environment fault) or the lock file (anything else)."""
    from .atomic import is_environment_error, output_error

    if is_environment_error(exc):
        return output_error(out, exc)
    return InputError(out / LOCK_NAME, f"cannot lock the output directory ({exc.strerror or exc})")


def _make_dirs(directory: Path) -> list[Path]:
    """Create ``directory`` and its missing parents; return the ones created, deepest first."""
    missing = []
    d = directory
    while not d.exists() and d != d.parent:
        missing.append(d)
        d = d.parent
    directory.mkdir(parents=True, exist_ok=True)
    return missing


def _command_line() -> str:
    argv = sys.argv[1:] if sys.argv and sys.argv[0] else []
    return " ".join(shlex.quote(a) for a in ["sot-apps", *argv])[:200]


class OutputLock:
    """Context manager: hold ``out/.sot-apps.lock`` or raise InputError if another process holds it."""

    def __init__(self, out: str | Path):
        self.path = (Path(out).absolute() / LOCK_NAME).resolve()

    def __enter__(self) -> "OutputLock":
        held = _HELD.get(self.path)
        if held is not None:
            held[1] += 1
            return self
        directory = self.path.parent
        try:
            created = _make_dirs(directory)
        except OSError as exc:
            raise _output_error(directory, exc) from None
        try:
            fd = self._acquire()
        except BaseException:
            _remove_empty(created)
            raise
        stamp = datetime.datetime.now(datetime.timezone.utc).strftime("%Y-%m-%d %H:%M:%S UTC")
        try:
            os.ftruncate(fd, 0)
            os.pwrite(fd, os.fsencode(f"pid {os.getpid()} on {os.uname().nodename}, started {stamp}: "
                                      f"{_command_line()}\n"), 0)   # fsencode: a non-UTF-8 path argument
        except OSError as exc:  # e.g. a full disk: the command could not write its outputs either
            self._release(fd, created)
            raise _output_error(directory, exc) from None
        _HELD[self.path] = [fd, 1, created]
        return self

    def _acquire(self) -> int:
        while True:
            try:
                fd = os.open(self.path, os.O_RDWR | os.O_CREAT, 0o644)
            except OSError as exc:
                raise _output_error(self.path.parent, exc) from None
            try:
                fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
            except BlockingIOError:
                holder = os.pread(fd, 512, 0).decode("utf-8", "replace").strip() or "another process"
                os.close(fd)
                raise InputError(self.path, f"another sot-apps command is writing into {self.path.parent} "
                                            f"({holder}); wait for it to finish or choose another output directory"
                                 ) from None
            except OSError as exc:
                os.close(fd)
                raise InputError(self.path, f"cannot lock the output directory ({exc.strerror})") from None
            try:   # the holder we waited for may have removed the file: lock the one the name leads to now
                same = os.path.samestat(os.fstat(fd), os.stat(self.path))
            except FileNotFoundError:
                same = False
            if same:
                return fd
            os.close(fd)

    def _release(self, fd: int, created: list[Path]) -> None:
        try:
            with contextlib.suppress(FileNotFoundError):
                os.unlink(self.path)   # while still locked: see the module docstring
        finally:
            fcntl.flock(fd, fcntl.LOCK_UN)
            os.close(fd)
        _remove_empty(created)

    def __exit__(self, *exc_info) -> None:
        held = _HELD[self.path]
        held[1] -= 1
        if held[1]:
            return
        del _HELD[self.path]
        self._release(held[0], held[2])


def _remove_empty(directories: list[Path]) -> None:
    """Remove the directories a lock created, deepest first, as long as they are empty."""
    for d in directories:
        try:
            d.rmdir()
        except OSError:
            return
