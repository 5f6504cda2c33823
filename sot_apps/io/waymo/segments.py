"""Find a Waymo segment (as LiDAR-SOT names it) in a data directory."""

from __future__ import annotations

from pathlib import Path

from ...errors import InputError

__all__ = ["find_waymo_segment", "segment_context"]

_PREFIX = "segment-"
_SUFFIX = "_with_camera_labels"


def segment_context(segment_name: str) -> str:
    """The context name (``<digits>_<digits>_<digits>_<digits>_<digits>``) of a segment name.

    ``"segment-1024360143612057520_3580_000_3600_000_with_camera_labels"`` -> ``"1024360143612057520_3580_000_3600_000"``;
    a bare context name is returned unchanged.
    """
    name = segment_name.strip()
    if name.endswith(".tfrecord"):
        name = name[: -len(".tfrecord")]
    if name.startswith(_PREFIX):
        name = name[len(_PREFIX):]
    if name.endswith(_SUFFIX):
        name = name[: -len(_SUFFIX)]
    return name


def find_waymo_segment(data_dir: str | Path, segment_name: str) -> Path:
    """The path to give ``open_sequence`` for segment ``segment_name`` under ``data_dir``.

    ``segment_name`` is LiDAR-SOT's ``segment-<context>_with_camera_labels`` (a bare context name works
    too). Looked up, in ``data_dir`` and then in each of its immediate subdirectories (e.g.
    ``validation/``):

    - v1: ``<segment_name>.tfrecord`` (the official file name), or any ``*<context>*.tfrecord``;
    - v2: ``vehicle_pose/<context>.parquet`` (the other components beside it are found by the reader).

    Raises InputError naming ``data_dir``, the segment and the paths tried when none exists. Frame
    indices of the opened sequence are 0-based in file order, as LiDAR-SOT's ``frame_range``.
    """
    data_dir = Path(data_dir)
    if not data_dir.is_dir():
        raise InputError(data_dir, "Waymo data directory does not exist")
    context = segment_context(segment_name)
    if not context:
        raise InputError(data_dir, f"empty Waymo segment name {segment_name!r}")
    full = f"{_PREFIX}{context}{_SUFFIX}"
    folders = [data_dir] + sorted(p for p in data_dir.iterdir() if p.is_dir())
    for folder in folders:
        v1 = folder / f"{full}.tfrecord"
        if v1.is_file():
            return v1
        matches = sorted(folder.glob(f"*{context}*.tfrecord"))
        if len(matches) == 1:
            return matches[0]
        if len(matches) > 1:
            raise InputError(folder, f"segment {context} matches {len(matches)} .tfrecord files: "
                                     f"{', '.join(m.name for m in matches[:3])}")
        v2 = folder / "vehicle_pose" / f"{context}.parquet"
        if v2.is_file():
            return v2
    raise InputError(data_dir, f"Waymo segment {context} not found: expected {full}.tfrecord (v1) or "
                               f"vehicle_pose/{context}.parquet (v2) in {data_dir} or one of its subdirectories")
