"""Keyframe files in (``sot-apps track|autolabel --keyframes FILE``): boxes an annotator gave at some frames.

Three formats, chosen by the file name; each becomes WORLD boxes by track id and frame index:

- ``*.json``: the ``keyframes`` schema (data_schema/keyframes.schema.json): ``{"keyframes": [{"track_id": ..,
  "frame": k, "box": [x, y, z, heading, length, width, height]}, ...]}``, world frame;
- ``*.txt``: KITTI tracking ``label_02`` rows (``frame track_id type truncated occluded alpha l t r b h w l x y z
  rotation_y [score]``; frame numbers are frame indices; DontCare rows skipped). The boxes are converted as the
  KITTI reader converts its labels (:func:`sot_apps.io.kitti.label_box_in_velo`) with the calib file
  ``calib/SSSS.txt`` beside ``label_02/SSSS.txt`` (or the one given); without one the camera sits at the LiDAR
  origin with KITTI's ideal axes (:func:`sot_apps.io.detections.kitti_to_lidar_boxes`); then to the world with
  the frame's ``world_from_ego @ ego_from_lidar``;
- ``*.feather``: Argoverse 2 ``annotations.feather`` rows (:func:`sot_apps.io.av2.read_cuboids`): ego-frame
  cuboids at their ``timestamp_ns``, which must be a frame time of the sequence, moved to the world with that
  frame's pose (the AV2 reader's conversion).

Bad content (schema violations, frames outside the sequence, a track given twice at one frame, impossible
boxes) is an InputError naming the file.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any, Mapping

import numpy as np

from tracker.geometry import Box, wrap_angle

from ..errors import InputError
from ..schemas import load_json, validate
from .bounds import check_box_values
from .sequence import Sequence

__all__ = ["KEYFRAME_FORMATS", "read_keyframes", "pick_keyframe_track", "keyframes_document"]

KEYFRAME_FORMATS = {".json": "json", ".txt": "kitti", ".feather": "av2"}


def _add(out: dict[str, dict[int, Box]], path: Path, track_id: str, frame: int, box: Box, n_frames: int) -> None:
    if not 0 <= frame < n_frames:
        raise InputError(path, f"track {track_id}: keyframe at frame {frame}, but the sequence has frames "
                               f"0..{n_frames - 1}")
    boxes = out.setdefault(track_id, {})
    if frame in boxes:
        raise InputError(path, f"track {track_id}: two keyframes at frame {frame}")
    check_box_values(box.to_array(), path, f"track {track_id} frame {frame}: box")
    boxes[frame] = box


def _read_json(path: Path, n_frames: int) -> dict[str, dict[int, Box]]:
    doc = load_json(path)
    validate("keyframes", doc, path)
    out: dict[str, dict[int, Box]] = {}
    for entry in doc["keyframes"]:
        x, y, z, heading, length, width, height = (float(v) for v in entry["box"])
        _add(out, path, str(entry["track_id"]), int(entry["frame"]),
             Box(x, y, z, float(wrap_angle(heading)), length, width, height), n_frames)
    return out


def _read_kitti(path: Path, sequence: Sequence, calib: str | Path | None) -> dict[str, dict[int, Box]]:
    from .convert_util import read_text_lines
    from .detections import KITTI_CAMERA_FROM_LIDAR, kitti_to_lidar_boxes
    from .kitti import label_box_in_velo, parse_label_line, read_calib

    calib_path = Path(calib) if calib is not None else path.parent.parent / "calib" / path.name
    kitti_calib = read_calib(calib_path) if calib is not None or calib_path.is_file() else None
    out: dict[str, dict[int, Box]] = {}
    for n, line in enumerate(read_text_lines(path), start=1):
        if not line.strip():
            continue
        label = parse_label_line(line, path, n, tracking=True)
        if label is None:
            continue
        if kitti_calib is not None:
            box_lidar = label_box_in_velo(label, kitti_calib)
        else:
            values = kitti_to_lidar_boxes(np.array([label["h"], label["w"], label["l"]]),
                                          np.array([[label["x"], label["y"], label["z"]]]), np.array([label["ry"]]),
                                          KITTI_CAMERA_FROM_LIDAR)[0]
            box_lidar = Box.from_array(values)
        frame = int(label["frame"])
        if not 0 <= frame < len(sequence):
            raise InputError(path, f"line {n}: frame {frame}, but the sequence has frames 0..{len(sequence) - 1}")
        world_from_lidar = np.asarray(sequence.frames[frame].world_from_ego) @ np.asarray(sequence.ego_from_lidar)
        _add(out, path, str(label["track_id"]), frame, box_lidar.transformed(world_from_lidar, keep_tilt=True),
             len(sequence))
    return out


def _read_av2(path: Path, sequence: Sequence) -> dict[str, dict[int, Box]]:
    from .av2 import cuboid_boxes_in_ego, read_cuboids

    cols = read_cuboids(path)
    index = {int(f.timestamp_ns): k for k, f in enumerate(sequence.frames)}
    out: dict[str, dict[int, Box]] = {}
    for i, box_ego in enumerate(cuboid_boxes_in_ego(cols, path)):
        stamp = int(cols["timestamp_ns"][i])
        if stamp not in index:
            raise InputError(path, f"row {i}: timestamp_ns {stamp} is not a frame time of the sequence")
        k = index[stamp]
        _add(out, path, str(cols["track_uuid"][i]), k,
             box_ego.transformed(np.asarray(sequence.frames[k].world_from_ego), keep_tilt=True), len(sequence))
    return out


def read_keyframes(path: str | Path, sequence: Sequence, kitti_calib: str | Path | None = None
                   ) -> dict[str, dict[int, Box]]:
    """Keyframe boxes (WORLD) by track id and frame index (see the module docstring)."""
    path = Path(path)
    if not path.is_file():
        raise InputError(path, "no such keyframe file" if not path.exists() else "not a regular file")
    fmt = KEYFRAME_FORMATS.get(path.suffix.lower())
    if fmt is None:
        raise InputError(path, f"unknown keyframe format {path.suffix!r}: give a .json (keyframes schema), .txt "
                               "(KITTI label_02) or .feather (AV2 annotations) file")
    if fmt == "json":
        out = _read_json(path, len(sequence))
    elif fmt == "kitti":
        out = _read_kitti(path, sequence, kitti_calib)
    else:
        out = _read_av2(path, sequence)
    if not out:
        raise InputError(path, "no keyframe (every row was DontCare or empty)")
    return out


def pick_keyframe_track(tracks: Mapping[str, dict[int, Box]], track_id: str | None,
                        path: str | Path) -> tuple[str, dict[int, Box]]:
    """The track ``track_id`` names (a unique prefix is enough) or, without one, the file's only track."""
    if track_id is None:
        if len(tracks) != 1:
            names = ", ".join(sorted(tracks)[:8])
            raise InputError(path, f"{len(tracks)} tracks ({names}{', ...' if len(tracks) > 8 else ''}); "
                                   "pick one with --track-id")
        name = next(iter(tracks))
        return name, dict(tracks[name])
    matches = [t for t in tracks if t == track_id] or [t for t in tracks if t.startswith(track_id)]
    if len(matches) != 1:
        raise InputError(path, f"--track-id {track_id}: {'no track' if not matches else 'several tracks'} "
                               f"with this id{' prefix' if not matches or len(matches) > 1 else ''} in the file")
    return matches[0], dict(tracks[matches[0]])


def keyframes_document(tracks: Mapping[str, Mapping[int, Box]], sequence_id: str | None = None) -> dict[str, Any]:
    """The ``keyframes`` schema document of ``tracks`` (track by track, frames in order)."""
    doc: dict[str, Any] = {"version": 1}
    if sequence_id:
        doc["sequence"] = sequence_id
    doc["keyframes"] = [{"track_id": track_id, "frame": int(k), "box": [float(v) for v in boxes[k].to_array()]}
                        for track_id, boxes in tracks.items() for k in sorted(boxes)]
    return doc
