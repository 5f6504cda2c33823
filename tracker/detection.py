"""Detections as the tracker consumes them, and the paper's association rule for the Detection term.

A frame's detections are (N, 7) WORLD boxes [x, y, z, heading, length, width, height] with (N,) scores.
The Detection term (Pang et al. 2021, "Det+SOT") uses, at frame k, the one detection with the largest
bird's-eye-view IoU with the motion model's prediction S^_k, among those with score >= ``min_score``
and IoU >= ``min_iou``; if none qualifies, the term is off for that frame. With ``max_distance`` > 0
(``TrackerConfig.det_max_distance``), a frame with no such detection takes instead the confident detection
whose centre is nearest the prediction's, if within ``max_distance``: after an occlusion the coasting
prediction drifts off the re-appearing object (BEV IoU 0) and only a detection can re-anchor the track. Its target motion is
S_D - S_{k-1} (:func:`detection_motion`), compared with the estimated motion in
:func:`tracker.terms.detection_block`.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Mapping

import numpy as np

from .geometry import Box, wrap_angle
from .metrics import iou_bev_batch

__all__ = ["FrameDetections", "Detections", "associate_detection", "detection_motion", "align_heading"]


@dataclass(frozen=True)
class FrameDetections:
    """One frame's detections: ``boxes`` (N, 7) world boxes, ``scores`` (N,) in [0, 1], ``labels`` (N,)."""

    boxes: np.ndarray
    scores: np.ndarray
    labels: tuple[str, ...] = ()

    def __post_init__(self) -> None:
        boxes = np.asarray(self.boxes, dtype=np.float64).reshape(-1, 7)
        scores = np.asarray(self.scores, dtype=np.float64).reshape(-1)
        if len(scores) != len(boxes):
            raise ValueError(f"{len(boxes)} boxes but {len(scores)} scores")
        object.__setattr__(self, "boxes", boxes)
        object.__setattr__(self, "scores", scores)
        if self.labels and len(self.labels) != len(boxes):
            raise ValueError(f"{len(boxes)} boxes but {len(self.labels)} labels")

    def __len__(self) -> int:
        return len(self.boxes)

    @classmethod
    def empty(cls) -> "FrameDetections":
        return cls(np.zeros((0, 7)), np.zeros(0))


# frame index -> that frame's detections (frames without an entry have none)
Detections = Mapping[int, FrameDetections]


def align_heading(heading: float, reference: float) -> float:
    """``heading`` + k*pi closest to ``reference``: a detector's heading is often ambiguous by pi."""
    return float(reference + wrap_angle(2.0 * (heading - reference)) / 2.0)


def associate_detection(prediction: Box, detections: FrameDetections | None, min_score: float = 0.5,
                        min_iou: float = 0.1, max_distance: float = 0.0) -> np.ndarray | None:
    """The detection box (7,) with the largest BEV IoU with ``prediction`` among those with score >=
    ``min_score`` and IoU >= ``min_iou``; failing that (``max_distance`` > 0), the one with the nearest
    centre within ``max_distance`` metres (BEV); None when no detection qualifies."""
    if detections is None or len(detections) == 0:
        return None
    candidates = detections.boxes[detections.scores >= min_score]
    if len(candidates) == 0:
        return None
    pred = np.broadcast_to(prediction.to_array(), candidates.shape)
    ious = iou_bev_batch(pred, candidates)
    best = int(np.argmax(ious))
    if ious[best] >= min_iou:
        return candidates[best].copy()
    if max_distance > 0:
        distances = np.hypot(candidates[:, 0] - prediction.x, candidates[:, 1] - prediction.y)
        nearest = int(np.argmin(distances))
        if distances[nearest] <= max_distance:
            return candidates[nearest].copy()
    return None


def detection_motion(previous: Box, detection: np.ndarray, predicted_heading: float) -> np.ndarray:
    """S_D - S_{k-1} as a motion [dx, dy, dz, dtheta]; the detection's heading is first taken modulo pi
    closest to ``predicted_heading`` (the term pulls the box, it never flips it)."""
    heading = align_heading(float(detection[3]), predicted_heading)
    return np.array([detection[0] - previous.x, detection[1] - previous.y, detection[2] - previous.z,
                     wrap_angle(heading - previous.heading)])
