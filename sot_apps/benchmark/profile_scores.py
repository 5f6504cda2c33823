"""Scores of the profiles that provoke unseen-vehicle failures, beyond Acc and Rob (scoring only).

Per tracklet (:func:`tracklet_figures`, frame indices relative to the tracklet's first frame, as the list
records them):

- ``relocked`` (``hidden``): the track is locked within 3 frames of re-appearing and stays locked: in the
  window from the re-appearing frame to 3 frames after it (cut at the tracklet's end), the tracker's box overlaps
  the truth with 3D IoU >= 0.3 (:data:`LOCK_IOU`) at some frame and at every later frame of the window (a box
  that touches the object and is captured by something else before the window ends is not re-locked);
- ``relocked_any`` (``hidden``): the looser count, IoU >= 0.3 at any frame of that window;
- ``found_near`` (``far_approach`` that comes within 30 m): the box overlaps the truth with IoU >= 0.3 at
  the first frame within 30 m;
- ``heading_err_last_deg`` (``oblique``): |heading error| at the last frame, in degrees (0-180).

Pooled over tracklets (:func:`pool_figures`): ``relock_share``, ``relock_any_share`` and ``found_near_share``
(fractions of the tracklets that have the figure) and ``heading_err_last_med_deg`` (the median).
"""

from __future__ import annotations

import math
from typing import Iterable, Mapping, Sequence

import numpy as np

__all__ = ["LOCK_IOU", "RELOCK_WITHIN", "tracklet_figures", "pool_figures", "heading_error_deg"]

LOCK_IOU = 0.3
RELOCK_WITHIN = 3


def heading_error_deg(predicted: float, truth: float) -> float:
    """|predicted - truth| wrapped to [0, 180] degrees."""
    return abs(math.degrees((predicted - truth + math.pi) % (2 * math.pi) - math.pi))


def _iou_at(ious: np.ndarray, frame: int) -> float:
    """IoU of tracklet frame ``frame`` (``ious`` score frames 1..n-1); NaN outside."""
    i = int(frame) - 1
    return float(ious[i]) if 0 <= i < len(ious) else float("nan")


def tracklet_figures(extra: Mapping, ious: np.ndarray, predicted_headings: Sequence[float],
                     true_headings: Sequence[float]) -> dict[str, float]:
    """The profile figures one tracklet has (``extra``: its list entry's fields, e.g. ``reappear_frame``)."""
    out: dict[str, float] = {}
    profile = extra.get("profile")
    ious = np.asarray(ious, dtype=np.float64)
    if extra.get("reappear_frame") is not None:
        window = [_iou_at(ious, k) for k in range(int(extra["reappear_frame"]),
                                                  int(extra["reappear_frame"]) + RELOCK_WITHIN + 1)]
        locked = np.array([v >= LOCK_IOU for v in window if np.isfinite(v)])
        if locked.size:
            first = int(np.argmax(locked))                 # the first locked frame of the window (0 if none)
            out["relocked"] = float(locked.any() and locked[first:].all())
            out["relocked_any"] = float(locked.any())
    if extra.get("near_frame") is not None:
        v = _iou_at(ious, int(extra["near_frame"]))
        if np.isfinite(v):
            out["found_near"] = float(v >= LOCK_IOU)
    if profile == "oblique" and len(predicted_headings):
        out["heading_err_last_deg"] = heading_error_deg(float(predicted_headings[-1]), float(true_headings[-1]))
    return out


def pool_figures(figures: Iterable[Mapping[str, float]]) -> dict[str, float]:
    """Shares and the median heading error over tracklets (only the figures some tracklet has)."""
    figures = list(figures)
    out: dict[str, float] = {}
    for name, pooled in (("relocked", "relock_share"), ("relocked_any", "relock_any_share"),
                         ("found_near", "found_near_share")):
        values = [f[name] for f in figures if name in f]
        if values:
            out[pooled] = float(np.mean(values))
            out[pooled.replace("_share", "_n")] = len(values)
    errors = [f["heading_err_last_deg"] for f in figures if "heading_err_last_deg" in f]
    if errors:
        out["heading_err_last_med_deg"] = float(np.median(errors))
    return out
