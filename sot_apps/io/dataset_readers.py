"""Detection and dispatch of the dataset readers (Argoverse 2, nuScenes, KITTI tracking, KITTI object).

Each reader converts its dataset to the project's conventions inside its own module; this module
only says which layout a path has and which function opens it. A multi-sequence directory takes a
selector: ``DIR#NAME`` (see each reader).
"""

from __future__ import annotations

from pathlib import Path
from typing import Callable

from .convert_util import split_selector
from .sequence import Sequence

__all__ = ["detect_dataset", "DATASET_READERS"]


def _open_av2(path: str | Path) -> Sequence:
    from .av2 import read_av2

    return read_av2(path)


def _open_nuscenes(path: str | Path) -> Sequence:
    from .nuscenes import read_nuscenes

    root, scene = split_selector(path)
    return read_nuscenes(root, scene)


def _open_kitti_tracking(path: str | Path) -> Sequence:
    from .kitti import read_kitti_tracking

    return read_kitti_tracking(path)


def _open_kitti_object(path: str | Path) -> Sequence:
    from .kitti import read_kitti_object

    return read_kitti_object(path)


DATASET_READERS: dict[str, Callable[[str | Path], Sequence]] = {
    "av2": _open_av2,
    "nuscenes": _open_nuscenes,
    "kitti_tracking": _open_kitti_tracking,
    "kitti_object": _open_kitti_object,
}


def detect_dataset(path: str | Path) -> str | None:
    """The dataset format of ``path`` (a key of DATASET_READERS), or None."""
    from .av2 import is_av2_log
    from .kitti import is_kitti_object, kitti_tracking_parts
    from .nuscenes import is_nuscenes

    path, _ = split_selector(path)
    if path.is_dir() and is_av2_log(path):
        return "av2"
    if is_nuscenes(path):
        return "nuscenes"
    if kitti_tracking_parts(path) is not None:
        return "kitti_tracking"
    if is_kitti_object(path):
        return "kitti_object"
    return None
