"""Sequence readers and writers. ``open_sequence(path)`` auto-detects the format."""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING

from ..errors import InputError

if TYPE_CHECKING:
    from .sequence import Sequence

_SEQUENCE_NAMES = ("BoxAnnotation", "Camera", "CameraFrame", "FrameInfo", "Sequence", "Sweep")

__all__ = ["open_sequence", "detect_format", "FORMATS", "Sequence", "Sweep", "FrameInfo", "Camera",
           "CameraFrame", "BoxAnnotation"]

FORMATS = ("sequence", "pandaset", "waymo_v1", "waymo_v2",
           # dataset readers of issue 14 (av2.py, nuscenes.py, kitti.py)
           "av2", "nuscenes", "kitti_tracking", "kitti_object")


def detect_format(path: str | Path) -> str:
    """Name of the format of the sequence at ``path`` (see FORMATS)."""
    from .convert_util import split_selector
    from .pandaset import is_pandaset

    path = Path(path)
    base, name = split_selector(path)
    if name is not None:
        from .dataset_readers import detect_dataset

        if base.exists() and detect_dataset(base):
            return detect_dataset(base)
    if not path.exists():
        raise InputError(path, "no such file or directory")
    if path.is_file() and path.name == "sequence.json":
        return "sequence"
    waymo = _detect_waymo(path) if path.is_file() else None
    if waymo:
        return waymo
    if not path.is_dir():
        from .dataset_readers import detect_dataset

        found = detect_dataset(path)  # a dataset may name a sequence by one of its files
        if found:
            return found
        raise InputError(path, "not a sequence directory")
    if (path / "sequence.json").is_file():
        return "sequence"
    if is_pandaset(path):
        return "pandaset"
    waymo = _detect_waymo(path)
    if waymo:
        return waymo
    from .dataset_readers import detect_dataset

    found = detect_dataset(path)
    if found:
        return found
    raise InputError(path, "unknown sequence format: expected sequence.json (canonical), lidar/poses.json with "
                           "lidar/NN.npz|.pkl.gz (PandaSet), a Waymo v1 .tfrecord, Waymo v2 component parquet files, "
                           "or another dataset layout of docs/data-formats.md")


def _detect_waymo(path: Path) -> str | None:
    from .waymo import is_waymo_v1, is_waymo_v2

    if is_waymo_v1(path):
        return "waymo_v1"
    if is_waymo_v2(path):
        return "waymo_v2"
    return None


def open_sequence(path: str | Path, format: str | None = None, cache: bool = False) -> Sequence:
    """Open a sequence; ``format`` forces a reader (one of FORMATS). Boxes and poses beyond the coordinate bound
    (``sot_apps.io.bounds``) are an InputError. ``cache``: read the sweeps through the one-time conversion cache
    (:mod:`sot_apps.io.sweep_cache`; bulk work such as the pipeline)."""
    from .bounds import check_sequence_coordinates

    sequence = _read_sequence(Path(path), format)
    check_sequence_coordinates(sequence)
    if cache:
        from .sweep_cache import with_sweep_cache

        with_sweep_cache(sequence)
    return sequence


def _read_sequence(path: Path, format: str | None) -> Sequence:
    fmt = format or detect_format(path)
    if fmt == "pandaset":
        from .pandaset import read_pandaset

        return read_pandaset(path)
    if fmt == "sequence":
        from .canonical import read_sequence

        return read_sequence(path.parent if path.name == "sequence.json" else path)
    if fmt in ("waymo_v1", "waymo_v2"):
        from .waymo import read_waymo_v1, read_waymo_v2

        return (read_waymo_v1 if fmt == "waymo_v1" else read_waymo_v2)(path)
    from .dataset_readers import DATASET_READERS

    if fmt in DATASET_READERS:
        return DATASET_READERS[fmt](path)
    raise InputError(path, f"unknown format {fmt!r}; known: {', '.join(FORMATS)}")


def __getattr__(name: str):
    """The records of :mod:`.sequence`, imported on first use (``sot-apps --help`` needs FORMATS, not numpy)."""
    if name in _SEQUENCE_NAMES:
        from . import sequence

        return getattr(sequence, name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
