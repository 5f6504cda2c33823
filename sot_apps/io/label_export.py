"""Label files of a sequence for ``convert --labels`` and ``autolabel``: paths, checks and one-line reports.

KITTI: ``OUT/label_02/NNNN.txt`` + ``OUT/calib/NNNN.txt`` (NNNN = the KITTI tracking sequence number when the
source is one, else 0000); AV2: ``OUT/annotations.feather`` and, with scores, ``OUT/submission.feather``
(the detection submission table). The writers are in :mod:`.labels`.
"""

from __future__ import annotations

import os
import re
from pathlib import Path

from ..errors import InputError
from .labels import (
    LabelsWritten,
    kitti_camera,
    write_av2_annotations,
    write_av2_submission,
    write_kitti_tracking,
)
from .object_track import ObjectTrack
from .sequence import Sequence

__all__ = ["LABEL_FORMATS", "kitti_sequence_number", "label_paths", "export_labels"]

LABEL_FORMATS = ("kitti", "av2")


def kitti_sequence_number(seq: Sequence) -> int:
    """A KITTI tracking sequence keeps its number (id ``kitti_tracking_0001`` -> 1, also after conversion to the
    canonical format); any other sequence is 0."""
    match = re.fullmatch(r"kitti_tracking_(\d+)", seq.id)
    return int(match.group(1)) if match else 0


def label_paths(seq: Sequence, fmt: str, out_dir: str | Path, submission: bool = False) -> list[Path]:
    out_dir = Path(out_dir)
    if fmt == "kitti":
        number = kitti_sequence_number(seq)
        return [out_dir / "label_02" / f"{number:04d}.txt", out_dir / "calib" / f"{number:04d}.txt"]
    return [out_dir / "annotations.feather"] + ([out_dir / "submission.feather"] if submission else [])


def _refuse_overwriting_input(seq: Sequence, out_dir: Path) -> None:
    """The label files go where a dataset keeps its own (``LOG/annotations.feather``, ``training/label_02``):
    writing into the input's own directory would replace them."""
    root = Path(seq.root)
    if out_dir.exists() and root.exists() and os.path.samefile(out_dir, root):
        raise InputError(out_dir, f"is the input sequence's directory ({root}): its label files would be "
                                  "overwritten; choose another --out")


def _report(fmt: str, written: LabelsWritten) -> str:
    line = f"wrote {fmt}: {written.path} ({written.boxes} boxes"
    if written.outside_camera:
        line += f"; {written.outside_camera} outside the camera's image left out"
    if written.unmapped:
        line += "; left out, no " + fmt.upper() + " category: " + ", ".join(
            f"{label} ({n})" for label, n in sorted(written.unmapped.items()))
    return line + ")"


def export_labels(seq: Sequence, fmt: str, out_dir: str | Path, tracks: list[ObjectTrack] | None = None,
                  submission: bool = False) -> list[str]:
    """Write ``tracks`` (default: the sequence's annotations) as ``fmt`` label files under ``out_dir``; with
    ``submission`` (AV2) also the submission table. Returns one report line per file. InputError when there is
    nothing to write, no camera for KITTI, or a target is a file of the input."""
    if fmt not in LABEL_FORMATS:
        raise ValueError(f"unknown label format {fmt!r}")
    if tracks is None:
        if not seq.annotations:
            raise InputError(seq.root, "the sequence has no annotations to write as labels")
        tracks = list(seq.tracks().values())
    targets = label_paths(seq, fmt, out_dir, submission)
    _refuse_overwriting_input(seq, Path(out_dir))
    if fmt == "kitti":
        if kitti_camera(seq) is None:
            raise InputError(seq.root, "KITTI labels need a camera for their 2D boxes and the sequence has none")
        written = write_kitti_tracking(out_dir, seq, tracks, kitti_sequence_number(seq))
        return [_report(fmt, written)]
    lines = [_report(fmt, write_av2_annotations(targets[0], seq, tracks))]
    if submission:
        lines.append(_report(fmt, write_av2_submission(targets[1], seq, tracks)))
    return lines
