"""Middlebury ``.flo`` files: ``b"PIEH"`` (the float 202021.25), int32 width, int32 height, then
height x width x (u, v) float32, all little-endian. Written and read with numpy (the format is that small), so any
path the OS takes works (``cv2.writeOpticalFlow`` crashes on a non-UTF-8 path); OpenCV's
``cv2.readOpticalFlow`` reads the files back identically (tests).

Pixels without flow hold ``UNKNOWN_FLOW`` (1e10; Middlebury tools treat |value| > 1e9 as unknown).
"""

from __future__ import annotations

import functools
import os
from pathlib import Path

import numpy as np

from ..errors import InputError
from ..io.atomic import atomic_path

__all__ = ["write_flo", "read_flo", "flo_arrays", "UNKNOWN_FLOW"]

UNKNOWN_FLOW = np.float32(1e10)
_TAG = b"PIEH"


def _check_flow(flow: np.ndarray) -> None:
    if flow.ndim != 3 or flow.shape[2] != 2:
        raise ValueError(f"flow must be (H, W, 2), got {flow.shape}")


def _header(flow: np.ndarray) -> bytes:
    return _TAG + np.array([flow.shape[1], flow.shape[0]], dtype="<i4").tobytes()


def flo_arrays(flow: np.ndarray, valid: np.ndarray | None = None) -> tuple[bytes, np.ndarray]:
    """(header, (H, W, 2) little-endian float32 data) of the .flo file of ``flow`` (unknown where not ``valid``)."""
    flow = np.asarray(flow)
    _check_flow(flow)
    if valid is None:
        return _header(flow), np.ascontiguousarray(flow, dtype="<f4")
    rows, block = _known_rows(flow, np.asarray(valid, dtype=bool))
    data = np.full(flow.shape, UNKNOWN_FLOW, dtype="<f4")
    data[rows] = block
    return _header(flow), data


def _known_rows(flow: np.ndarray, valid: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The rows holding valid pixels and their .flo values (unknown elsewhere): the valid pixels scattered, each as
    one 8-byte item (the bits copied as they are)."""
    rows = np.flatnonzero(valid.any(axis=1))
    block = np.full((len(rows),) + flow.shape[1:], UNKNOWN_FLOW, dtype="<f4")
    source = np.ascontiguousarray(flow, dtype="<f4").reshape(-1, 2).view(np.uint64).reshape(-1)
    # the valid pixels in the block and in the image: the same pixels in the same order
    block.reshape(-1, 2).view(np.uint64).reshape(-1)[np.flatnonzero(valid[rows])] = source[np.flatnonzero(valid)]
    return rows, block


@functools.lru_cache(maxsize=2)
def _unknown_rows(width: int, height: int) -> memoryview:
    """``height`` rows of unknown flow as .flo bytes (made once per image size: slices of it are written)."""
    return memoryview(np.full((height, width, 2), UNKNOWN_FLOW, dtype="<f4")).cast("B")


def write_flo(path: str | Path, flow: np.ndarray, valid: np.ndarray | None = None, sync: bool = True) -> None:
    """Write ``flow`` as a .flo file (unknown where not ``valid``). With ``valid``, only the rows holding valid
    pixels are filled; the runs of rows without any are written from one shared buffer of unknown rows.
    ``sync``: fsync before the rename (:func:`sot_apps.io.atomic.write_bytes`)."""
    flow = np.asarray(flow)
    _check_flow(flow)
    height, width = flow.shape[:2]
    with atomic_path(path) as tmp:
        with open(tmp, "wb") as handle:
            handle.write(_header(flow))
            if valid is None:
                handle.write(memoryview(np.ascontiguousarray(flow, dtype="<f4")).cast("B"))   # no copy of the 16 MB
            else:
                rows, block = _known_rows(flow, np.asarray(valid, dtype=bool))
                unknown, row_bytes, done = _unknown_rows(width, height), width * 8, 0
                data = memoryview(block).cast("B")
                runs = np.split(np.arange(len(rows)), np.flatnonzero(np.diff(rows) != 1) + 1) if len(rows) else []
                for run in runs:
                    first = int(rows[run[0]])
                    handle.write(unknown[:(first - done) * row_bytes])
                    handle.write(data[run[0] * row_bytes:(run[-1] + 1) * row_bytes])
                    done = first + len(run)
                handle.write(unknown[:(height - done) * row_bytes])
            if sync:
                handle.flush()
                os.fsync(handle.fileno())


def read_flo(path: str | Path) -> tuple[np.ndarray, np.ndarray]:
    """((H, W, 2) float32 flow with unknown pixels set to 0, (H, W) bool known)."""
    try:
        with open(path, "rb") as handle:
            raw = handle.read()
    except IsADirectoryError:
        raise InputError(path, "not a Middlebury .flo file (a directory)") from None
    if len(raw) < 12 or raw[:4] != _TAG:
        raise InputError(path, "not a Middlebury .flo file")
    width, height = (int(v) for v in np.frombuffer(raw, dtype="<i4", count=2, offset=4))
    if width <= 0 or height <= 0 or len(raw) != 12 + 8 * width * height:
        raise InputError(path, f"not a Middlebury .flo file ({width}x{height} does not match {len(raw)} bytes)")
    flow = np.frombuffer(raw, dtype="<f4", offset=12).reshape(height, width, 2).astype(np.float32)
    known = (np.abs(flow) < 1e9).all(axis=-1)
    flow[~known] = 0.0
    return flow, known
