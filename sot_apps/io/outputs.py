"""The rules for where a command may write (docs/pipeline.md, "Outputs, numbers and locks").

* An output is never one of the command's inputs: an output file that is an input file (same real path, or the
  same inode and device), an output that would replace an existing file inside an input directory
  (``--json W/sequence.json``), an output directory that is an input, and two outputs of one command that are the
  same file (``--out X.mcap --parquet X.mcap``) are refused before any work, with one line naming both paths.
* Special files (character or block devices, FIFOs, sockets: ``/dev/null``, ``/dev/full``, a terminal) and the
  names of open file descriptors (``/dev/stdout``, ``/dev/stderr``, ``/dev/fd/N``, ``/proc/self/fd/N``) are
  written through: opened and written, never replaced by a temporary file and a rename (:func:`is_write_through`).
  A name of this process's own descriptor is written into that descriptor (so ``--json /dev/stdout > file``
  continues the file after the command's printed lines).
* A symbolic link is followed: its final target is replaced atomically and the link stays (:func:`final_target`).
"""

from __future__ import annotations

import os
import re
import stat
from dataclasses import dataclass
from pathlib import Path
from typing import Iterable

from ..errors import InputError

__all__ = ["PathArg", "is_descriptor_name", "own_descriptor", "is_write_through", "final_target", "check_no_clobber"]

_DESCRIPTOR_NAME = re.compile(r"^/dev/(stdin|stdout|stderr|fd/\d+)$|^/proc/(self|\d+)/fd/\d+$")


def is_descriptor_name(path: str | Path) -> bool:
    """``/dev/stdout``, ``/dev/stderr``, ``/dev/fd/N``, ``/proc/self/fd/N``: a name of an open file descriptor."""
    return bool(_DESCRIPTOR_NAME.match(os.path.abspath(path)))


def own_descriptor(path: str | Path) -> int | None:
    """The number of this process's open file descriptor that ``path`` names (``/dev/stdout`` -> 1), or None."""
    match = _DESCRIPTOR_NAME.match(os.path.abspath(path))
    if not match:
        return None
    if match.group(1):
        name = match.group(1)
        return {"stdin": 0, "stdout": 1, "stderr": 2}.get(name) if not name.startswith("fd/") else int(name[3:])
    if match.group(2) not in ("self", str(os.getpid())):
        return None
    return int(os.path.basename(path))


def is_write_through(path: str | Path) -> bool:
    """True when ``path`` must be opened and written in place: an existing target that is not a regular file or a
    directory (device, FIFO, socket), or a file descriptor's name (:func:`is_descriptor_name`: ``/dev/stdout``
    redirected to a file is a link to that file; replacing it would detach the shell's redirection)."""
    absolute = os.path.abspath(path)
    if is_descriptor_name(absolute):
        return True
    try:
        mode = os.stat(absolute).st_mode   # follows symbolic links
    except OSError:
        return False
    return not (stat.S_ISREG(mode) or stat.S_ISDIR(mode))


def final_target(path: str | Path) -> Path:
    """The file a write to ``path`` replaces: ``path`` itself, or the final target of a symbolic link (which may
    not exist yet: a dangling link's target is created)."""
    path = Path(path)
    return Path(os.path.realpath(path)) if path.is_symlink() else path


@dataclass(frozen=True)
class PathArg:
    """One path a command reads or writes, with the option that named it (``--json``, ``SEQUENCE``)."""

    option: str
    path: Path
    is_dir: bool = False   # for outputs: a directory the command writes into

    def describe(self) -> str:
        return f"{self.option} {self.path}"


def _identity(path: Path) -> tuple[str, tuple[int, int] | None]:
    real = os.path.realpath(path)
    try:
        st = os.stat(real)
        return real, (st.st_dev, st.st_ino)
    except OSError:
        return real, None


def _same(a: Path, b: Path) -> bool:
    real_a, id_a = _identity(a)
    real_b, id_b = _identity(b)
    return real_a == real_b or (id_a is not None and id_a == id_b)


def _inside(path: Path, directory: Path) -> bool:
    real, real_dir = os.path.realpath(path), os.path.realpath(directory)
    return real != real_dir and real.startswith(real_dir.rstrip(os.sep) + os.sep)


def input_path(text: str | Path) -> Path:
    """The file or directory an input argument names (``DIR#scene`` and ``DIR#SSSS`` name ``DIR``)."""
    path = Path(text)
    if not os.path.lexists(path) and "#" in str(text):
        return Path(str(text).rsplit("#", 1)[0])
    return path


def check_no_clobber(inputs: Iterable[PathArg], outputs: Iterable[PathArg]) -> None:
    """Refuse (:class:`InputError`, one line naming both paths) an output that is an input, that would replace an
    existing file inside an input directory, or that is another output of the same command. Special files
    (:func:`is_write_through`) are never refused: writing into /dev/null replaces nothing."""
    inputs = [i for i in inputs if os.path.lexists(i.path)]
    outputs = [o for o in outputs if not is_write_through(o.path)]
    for n, out in enumerate(outputs):
        for other in outputs[:n]:
            if _same(out.path, other.path):
                raise InputError(out.path, f"{out.option} is the same file as {other.describe()}; give each output "
                                           "its own path")
        for source in inputs:
            if _same(out.path, source.path):
                raise InputError(out.path, f"{out.option} is the input {source.describe()}; an output never "
                                           "overwrites an input: choose another path")
            if not out.is_dir and os.path.isdir(source.path) and _inside(out.path, source.path) \
                    and os.path.lexists(out.path):
                raise InputError(out.path, f"{out.option} would replace a file inside the input {source.describe()}; "
                                           "an output never overwrites an input: choose another path")
