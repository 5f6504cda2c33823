"""Sequence readers and writers. ``open_sequence(path)`` auto-detects the format."""

from __future__ import annotations

from pathlib import Path

from ..errors import InputError
from .sequence import AnnotatedTrack, BoxAnnotation, Camera, CameraFrame, FrameInfo, Sequence, Sweep

__all__ = ["open_sequence", "detect_format", "FORMATS", "Sequence", "Sweep", "FrameInfo", "Camera",
           "CameraFrame", "BoxAnnotation", "AnnotatedTrack"]

FORMATS = ("sequence", "pandaset")


def detect_format(path: str | Path) -> str:
    """Name of the format of the sequence directory ``path`` (see FORMATS)."""
    from .pandaset import is_pandaset

    path = Path(path)
    if not path.exists():
        raise InputError(path, "no such file or directory")
    if path.is_file() and path.name == "sequence.json":
        return "sequence"
    if not path.is_dir():
        raise InputError(path, "not a sequence directory")
    if (path / "sequence.json").is_file():
        return "sequence"
    if is_pandaset(path):
        return "pandaset"
    raise InputError(path, "unknown sequence format: expected sequence.json (canonical) or lidar/poses.json with lidar/NN.npz|.pkl.gz (PandaSet)")


def open_sequence(path: str | Path, format: str | None = None) -> Sequence:
    """Open a sequence; ``format`` forces a reader ("sequence" or "pandaset")."""
    path = Path(path)
    fmt = format or detect_format(path)
    if fmt == "pandaset":
        from .pandaset import read_pandaset

        return read_pandaset(path)
    if fmt == "sequence":
        from .canonical import read_sequence

        return read_sequence(path.parent if path.name == "sequence.json" else path)
    raise InputError(path, f"unknown format {fmt!r}; known: {', '.join(FORMATS)}")
