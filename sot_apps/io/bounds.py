"""The one bound on coordinates (docs/pipeline.md, "Outputs, numbers and locks").

No sequence of a vehicle's sensors spans more than a few hundred kilometres, and float64 keeps millimetres only up
to about 1e9 m; a box or pose coordinate beyond :data:`MAX_COORDINATE_M` (1e6 m = 1000 km from the world origin) is
corrupt input (an exponent typo, 1e300), not a place. Readers' sequences are checked once when opened
(:func:`check_sequence_coordinates`); command-line boxes and scene files use :func:`check_box_values`.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ..errors import InputError

__all__ = ["MAX_COORDINATE_M", "MAX_SIZE_M", "check_box_values", "check_coordinates", "check_sequence_coordinates"]

MAX_COORDINATE_M = 1.0e6   # |x|, |y|, |z| of a box centre or a pose translation, metres
MAX_SIZE_M = 1.0e3         # length, width, height of a box, metres


def _first_bad_box(array: np.ndarray) -> tuple[int, str] | None:
    """(row, problem) of the first box of ``array`` (N, 7) outside the bounds, or None."""
    checks = (
        (~np.isfinite(array).all(axis=1), "values must be finite numbers"),
        ((np.abs(array[:, :3]) > MAX_COORDINATE_M).any(axis=1),
         f"centre beyond the coordinate bound (|x|, |y|, |z| <= {MAX_COORDINATE_M:g} m)"),
        ((array[:, 4:7] <= 0).any(axis=1) | (array[:, 4:7] > MAX_SIZE_M).any(axis=1),
         f"length, width and height must be in (0, {MAX_SIZE_M:g}] m"),
    )
    for mask, problem in checks:
        if mask.any():
            return int(np.argmax(mask)), problem
    return None


def _numbers(row: np.ndarray) -> str:
    return "(" + ",".join(f"{v:.6g}" for v in row) + ")"


def check_box_values(values, where: str | Path | None, what: str = "box") -> None:
    """``values``: (..., 7) x, y, z, heading, length, width, height. Non-finite numbers, a centre beyond
    ``MAX_COORDINATE_M``, a non-positive size or one beyond ``MAX_SIZE_M`` -> InputError naming ``where``."""
    array = np.asarray(values, dtype=np.float64).reshape(-1, 7)
    bad = _first_bad_box(array) if len(array) else None
    if bad is not None:
        i, problem = bad
        label = what if len(array) == 1 else f"{what} #{i}"
        raise InputError(where, f"{label} {_numbers(array[i])}: {problem}")


def check_coordinates(values, where: str | Path | None, what: str) -> None:
    """``values``: (N, K) numbers that are coordinates in metres (or angles): every one finite and within
    ``MAX_COORDINATE_M``, else InputError naming ``where`` and the row (``what`` #i)."""
    array = np.asarray(values, dtype=np.float64)
    array = array.reshape(len(array), -1) if array.ndim else array.reshape(1, 1)
    bad = ~(np.abs(array) <= MAX_COORDINATE_M).all(axis=1)   # NaN counts as bad
    if bad.any():
        i = int(np.argmax(bad))
        raise InputError(where, f"{what} #{i} {_numbers(array[i])}: values must be finite and within the "
                                f"coordinate bound (|value| <= {MAX_COORDINATE_M:g} m)")


def check_sequence_coordinates(sequence) -> None:
    """Every annotated box and every ego pose translation of ``sequence`` within the bounds (InputError naming the
    sequence root and the frame otherwise). Vectorised: one pass over all boxes."""
    if sequence.frames:
        translations = np.array([f.world_from_ego[:3, 3] for f in sequence.frames], dtype=np.float64)
        far = ~(np.abs(translations) <= MAX_COORDINATE_M).all(axis=1)   # NaN counts as far
        if far.any():
            k = int(np.argmax(far))
            raise InputError(sequence.root, f"frame {k}: ego position {translations[k].tolist()} is beyond the "
                                            f"coordinate bound (|x|, |y|, |z| <= {MAX_COORDINATE_M:g} m)")
    rows, where = [], []
    for k, frame_annotations in enumerate(sequence.annotations or []):
        for ann in frame_annotations:
            b = ann.box
            rows.append((b.x, b.y, b.z, b.heading, b.length, b.width, b.height))
            where.append((k, ann.track_id))
    bad = _first_bad_box(np.asarray(rows, dtype=np.float64)) if rows else None
    if bad is not None:
        i, problem = bad
        k, track = where[i]
        raise InputError(sequence.root, f"frame {k}, track {track}: box {_numbers(np.asarray(rows[i]))}: {problem}")
