"""Atomic writers: every file is written to a temporary sibling and renamed into place.

A crash or Ctrl-C never leaves a half-written file under the final name. A symbolic link is followed: its
final target is replaced (the link stays). A special file (``/dev/null``, ``/dev/full``, ``/dev/stdout``, a FIFO)
is written through instead: the data goes to a temporary file in the system's temporary directory first, then is
copied into the special file, which is opened and written, never replaced (``sot_apps.io.outputs``). An environment failure while writing
(no space, read-only, no permission, a directory or a file in the way) removes the temporary file and raises
:class:`~sot_apps.errors.OutputError` naming the final path and the cause (the CLI prints it on one line, exit
code 2). :func:`ensure_writable` checks an output location before long work starts.
"""

from __future__ import annotations

import contextlib
import errno
import io
import json
import os
import shutil
import sys
import tempfile
from pathlib import Path
from typing import TYPE_CHECKING, Any, Iterator

from ..errors import OutputError
from .outputs import final_target, is_write_through, own_descriptor

if TYPE_CHECKING:
    import numpy as np

# numpy is imported where an array is written, not with this module: `sot-apps run` checks its outputs (this module)
# before it starts its workers' fork server, which should not wait for numpy's import (~0.2 s of CPU)

__all__ = ["atomic_path", "write_bytes", "write_text", "write_json", "write_npz", "ensure_writable",
           "is_environment_error", "output_error", "remove_stale_temporaries"]

# errno values that describe the place an output goes to, not the data or the code
_ENVIRONMENT_ERRNOS = frozenset({errno.ENOSPC, errno.EDQUOT, errno.EROFS, errno.EACCES, errno.EPERM, errno.EISDIR,
                                 errno.ENOTDIR, errno.EFBIG, errno.ENAMETOOLONG, errno.EIO})


def is_environment_error(exc: BaseException) -> bool:
    """True for an OSError caused by where an output goes (full disk, read-only, permissions, path clashes)."""
    return isinstance(exc, OSError) and exc.errno in _ENVIRONMENT_ERRNOS


def output_error(path: str | Path, exc: OSError) -> OutputError:
    """The one-line error for an output ``path`` that could not be written because of ``exc``."""
    return OutputError(path, f"cannot write: {exc.strerror or exc}")


def _nearest_existing(path: Path) -> Path:
    path = path.absolute()
    while not os.path.lexists(path) and path != path.parent:
        path = path.parent
    return path


def ensure_writable(path: str | Path, directory: bool = False) -> None:
    """Check before long work that ``path`` (a file, or with ``directory`` a directory) can be written.

    Creates and removes a probe file in the nearest existing directory on the way (nothing is left behind;
    missing directories are not created). Raises :class:`OutputError` naming ``path`` and the cause.
    """
    path = Path(path)
    if not directory and is_write_through(path):   # a device or FIFO: nothing is created next to it
        if os.path.exists(path) and not os.access(path, os.W_OK):
            raise OutputError(path, f"cannot write: {os.strerror(errno.EACCES)}")
        return
    if path.is_dir() and not directory:
        raise OutputError(path, f"cannot write: {os.strerror(errno.EISDIR)}")
    existing = _nearest_existing(path if directory else path.parent)
    if not existing.is_dir():
        raise OutputError(path, f"cannot write: {os.strerror(errno.ENOTDIR)} ({existing} is a file)")
    try:
        fd, probe = tempfile.mkstemp(prefix=".sot-apps-probe.", dir=existing)
        os.close(fd)
        os.unlink(probe)
    except OSError as exc:
        raise output_error(path, exc) from exc


def _umask() -> int:
    mask = os.umask(0)
    os.umask(mask)
    return mask


@contextlib.contextmanager
def atomic_path(path: str | Path) -> Iterator[Path]:
    """Yield a temporary path next to ``path``; on success it is renamed to ``path``.

    On any exception the temporary file is removed and ``path`` is left untouched. A symbolic link ``path`` is
    followed (its target is replaced); a special file is written through (:func:`_written_through`).
    """
    if is_write_through(path):
        with _written_through(Path(path)) as tmp:
            yield tmp
        return
    path = final_target(path)
    tmp: Path | None = None
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        # The name is ours before the file exists, so a Ctrl-C at any point (the signal may be taken by any
        # thread, so masking it here would not be enough) leaves nothing behind: the except below removes it.
        for _ in range(100):
            tmp = path.parent / f".{path.name}.{os.urandom(4).hex()}.tmp"
            try:
                os.close(os.open(tmp, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o600))
                break
            except FileExistsError:
                continue
        else:
            raise FileExistsError(errno.EEXIST, "no free temporary name", str(path.parent))
        yield tmp
        os.chmod(tmp, 0o666 & ~_umask())  # mkstemp makes 0600 files; give the usual permissions
        os.replace(tmp, path)
    except BaseException as exc:
        if tmp is not None:
            with contextlib.suppress(OSError):
                tmp.unlink()
        if is_environment_error(exc):
            raise output_error(path, exc) from exc   # type: ignore[arg-type]
        raise


@contextlib.contextmanager
def _written_through(path: Path) -> Iterator[Path]:
    """Yield a temporary file in the system's temporary directory; on success copy it into ``path`` (opened for
    writing: a device, a FIFO or a terminal is never replaced; ``/dev/stdout`` and the other names of this process's
    descriptors are written into that descriptor, after this process's own buffered output) and remove it."""
    fd, name = tempfile.mkstemp(prefix=".sot-apps-through.", suffix=".tmp")
    os.close(fd)
    tmp = Path(name)
    try:
        yield tmp
        descriptor = own_descriptor(path)
        if descriptor is not None:
            for stream in (sys.stdout, sys.stderr):
                with contextlib.suppress(Exception):
                    stream.flush()
        with open(tmp, "rb") as source, (open(descriptor, "wb", closefd=False) if descriptor is not None
                                         else open(path, "wb")) as target:
            shutil.copyfileobj(source, target, 1 << 20)
    except OSError as exc:
        if is_environment_error(exc) or exc.errno == errno.ENXIO:
            raise output_error(path, exc) from exc
        raise
    finally:
        with contextlib.suppress(OSError):
            tmp.unlink()


def remove_stale_temporaries(root: str | Path) -> list[Path]:
    """Remove the temporary files (``.NAME.XXXXXXXX.tmp``) that a killed process left under ``root``.

    A process killed outright (SIGKILL, a lost Dask worker, a power cut) cannot clean up; its temporaries never
    carry a final name, but they are litter. Call this only while no other writer works under ``root`` (the
    pipeline calls it at the start of a run).
    """
    removed = []
    for tmp in Path(root).rglob(".*.tmp"):
        if tmp.is_file():
            with contextlib.suppress(FileNotFoundError):
                tmp.unlink()
                removed.append(tmp)
    return removed


def write_bytes(path: str | Path, data: bytes, sync: bool = True) -> None:
    """Write ``data`` atomically. ``sync``: the data reaches the disk (fsync) before the rename; without it the file
    is still whole or absent for every reader (a killed process leaves nothing half-written), but a power cut may
    leave it empty: for outputs whose completeness is checked on a rerun (``sot-apps flow``'s pairs)."""
    with atomic_path(path) as tmp:
        with open(tmp, "wb") as handle:
            handle.write(data)
            if sync:
                handle.flush()
                os.fsync(handle.fileno())


def write_text(path: str | Path, text: str, sync: bool = True) -> None:
    write_bytes(path, text.encode("utf-8"), sync)


def _json_default(value: Any) -> Any:
    np = sys.modules.get("numpy")   # a numpy value exists only once numpy is imported
    if np is not None and isinstance(value, np.ndarray):
        return value.tolist()
    if np is not None and isinstance(value, np.generic):
        return value.item()
    if isinstance(value, Path):
        return str(value)
    raise TypeError(f"not JSON serialisable: {type(value).__name__}")


def write_json(path: str | Path, data: Any, indent: int | None = 1, sync: bool = True) -> None:
    """Write JSON atomically (numpy arrays and scalars are converted; NaN is refused; ``sync``: as
    :func:`write_bytes`)."""
    text = json.dumps(data, indent=indent, default=_json_default, allow_nan=False)
    write_text(path, text + "\n", sync)


def write_npz(path: str | Path, compressed: bool = True, level: int | None = None, **arrays: np.ndarray) -> None:
    """Write an .npz atomically; the same arrays give the same bytes (the zip entries carry a fixed date,
    where ``numpy.savez`` stamps the current time; deflate at zlib's default level, as ``savez_compressed``,
    unless ``level`` (1 = fastest) says otherwise)."""
    import zipfile

    import numpy as np

    buffer = io.BytesIO()
    method = zipfile.ZIP_DEFLATED if compressed else zipfile.ZIP_STORED
    with zipfile.ZipFile(buffer, "w", compression=method, allowZip64=True) as archive:
        for name, value in arrays.items():
            info = zipfile.ZipInfo(f"{name}.npy", date_time=(1980, 1, 1, 0, 0, 0))
            info.compress_type = method
            if compressed and level is not None:   # an entry made here takes its level from itself, not the archive
                setattr(info, "compress_level" if hasattr(info, "compress_level") else "_compresslevel", level)
            with archive.open(info, "w", force_zip64=True) as handle:
                np.lib.format.write_array(handle, np.asanyarray(value), allow_pickle=False)
    write_bytes(path, buffer.getvalue())
