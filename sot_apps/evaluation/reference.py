"""Frame-by-frame comparison of tracked boxes with reference boxes (e.g. the authors' implementation).

A reference file is JSON ``{track_id_prefix: {frame: [x, y, z, heading, length, width, height]}}`` in
the world frame (``../shared/data/upstream_lidar_sot/*.json``). :func:`compare_boxes` scores a tracked run
given to it, per frame the reference holds: IoU with the ground truth (ours and the reference's), IoU between
ours and the reference, and the BEV centre distance and heading difference between them.
``sot-apps bench reference`` (:mod:`sot_apps.bench.reference`) runs a preset and prints the comparison.
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path
from typing import Sequence

import numpy as np

from tracker import Box, accuracy, iou_3d_batch, robustness, wrap_angle

from ..errors import InputError

__all__ = ["ReferenceComparison", "load_reference", "compare_boxes", "format_comparison"]


@dataclass(frozen=True)
class ReferenceComparison:
    """Per-frame comparison of one track over frames ``frames`` (the start frame excluded)."""

    track_id: str
    frames: np.ndarray            # (n,) frame indices
    iou_ours_gt: np.ndarray       # (n,)
    iou_ref_gt: np.ndarray        # (n,)
    iou_ours_ref: np.ndarray      # (n,)
    centre_dist: np.ndarray       # (n,) BEV distance between our centre and the reference's (m)
    heading_diff: np.ndarray      # (n,) our heading minus the reference's, wrapped (rad)

    def summary(self) -> dict[str, float]:
        return {"acc": 100 * accuracy([self.iou_ours_gt]), "rob": 100 * robustness([self.iou_ours_gt]),
                "ref_acc": 100 * accuracy([self.iou_ref_gt]), "ref_rob": 100 * robustness([self.iou_ref_gt]),
                "iou_to_ref": float(np.mean(self.iou_ours_ref)), "centre_dist": float(np.mean(self.centre_dist)),
                "max_centre_dist": float(np.max(self.centre_dist)),
                "first_diverged": int(self.frames[np.argmax(self.centre_dist > 0.5)])
                if np.any(self.centre_dist > 0.5) else -1}


def load_reference(path: str | Path) -> dict[str, dict[int, np.ndarray]]:
    """Reference boxes per track prefix and frame (each a (7,) array)."""
    path = Path(path)
    try:
        data = json.loads(path.read_text())
        return {str(tid): {int(k): np.asarray(v, dtype=np.float64).reshape(7) for k, v in frames.items()}
                for tid, frames in data.items()}
    except (OSError, ValueError, AttributeError, TypeError) as exc:
        raise InputError(path, f"not a reference box file ({exc})") from exc


def compare_boxes(track_id: str, frames: Sequence[int], ours: Sequence[Box], gt_boxes: Sequence[Box],
                  reference: dict[int, np.ndarray]) -> ReferenceComparison:
    """Our boxes ``ours`` and the ground truth ``gt_boxes`` (both one per frame of ``frames``; the first, the
    start frame, is never scored) against ``reference`` on the frames the reference holds."""
    keep = [i for i, k in enumerate(frames) if i > 0 and k in reference]
    mine = np.array([ours[i].to_array() for i in keep])
    gt = np.array([gt_boxes[i].to_array() for i in keep])
    ref = np.array([reference[frames[i]] for i in keep])
    return ReferenceComparison(track_id, np.array([frames[i] for i in keep]), iou_3d_batch(mine, gt),
                               iou_3d_batch(ref, gt), iou_3d_batch(mine, ref),
                               np.linalg.norm(mine[:, :2] - ref[:, :2], axis=1),
                               np.asarray(wrap_angle(mine[:, 3] - ref[:, 3])))


def format_comparison(rows: list[ReferenceComparison], per_frame: bool = False) -> str:
    lines = ["track     ours Acc/Rob  ref Acc/Rob  IoU(ours,ref)  dist mean/max (m)  first >0.5 m"]
    for r in rows:
        s = r.summary()
        lines.append(f"{r.track_id:8s}  {s['acc']:5.1f}/{s['rob']:5.1f}  {s['ref_acc']:5.1f}/{s['ref_rob']:5.1f}"
                     f"  {s['iou_to_ref']:13.3f}  {s['centre_dist']:8.3f}/{s['max_centre_dist']:6.3f}"
                     f"  {s['first_diverged']:12d}")
        if per_frame:
            for k, a, b, c, d, h in zip(r.frames, r.iou_ours_gt, r.iou_ref_gt, r.iou_ours_ref, r.centre_dist,
                                        r.heading_diff, strict=True):
                lines.append(f"    {k:3d}  gt {a:.3f}  ref-gt {b:.3f}  ours-ref {c:.3f}  d {d:.3f}  dh {h:+.3f}")
    ours = [r.iou_ours_gt for r in rows]
    refs = [r.iou_ref_gt for r in rows]
    lines.append(f"pooled    {100 * accuracy(ours):5.1f}/{100 * robustness(ours):5.1f}"
                 f"  {100 * accuracy(refs):5.1f}/{100 * robustness(refs):5.1f}")
    return "\n".join(lines)
