"""Does a track look lost? A rule on what the tracker itself recorded, for users who have no ground truth.

Evidence per track (``track.json``), over the frames after the start:

- ``measured``: frames whose state was measured, i.e. not flagged ``no_points`` / ``prior_only`` /
  ``lost`` (:func:`sot_apps.io.tracks.frame_is_valid`); the other states are the motion prior's
  extrapolation;
- ``mean_quality``: the tracker's per-frame quality (shape-fit inlier share, 0..1);
- ``longest_prior_run`` and ``lost_from``: the longest run of unmeasured frames, and the first frame
  of the final such run (None when the last frame was measured).

Rule (``status``): **lost** when fewer than 20 % of the frames after the start were measured (the
track is mostly an extrapolation, wherever the object really went); **weak** when fewer than 80 %
were (the object was not seen for a while: the states over those frames are predictions); **ok**
otherwise. On the real-data demo (PandaSet 002, ``sot-apps demo --sequence ../shared/data/pandaset_002``)
the three tracks this rule calls lost are exactly the three with a mean 3D IoU below 0.2 against the
annotations; the thresholds were checked on that run only (a tuning set, not a benchmark).
"""

from __future__ import annotations

from dataclasses import asdict, dataclass

import numpy as np

from ..io.object_track import ObjectTrack
from ..io.tracks import frame_is_valid

__all__ = ["TrackHealth", "track_health", "LOST_BELOW", "WEAK_BELOW"]

LOST_BELOW = 0.2     # measured share of the frames after the start below which a track looks lost
WEAK_BELOW = 0.8     # ... below which it is weak


@dataclass(frozen=True)
class TrackHealth:
    object_id: str
    frames: int                  # frames after the start
    measured: int
    measured_share: float
    mean_quality: float
    longest_prior_run: int
    lost_from: int | None
    status: str                  # "ok" | "weak" | "lost"

    def to_json(self) -> dict:
        out = asdict(self)
        out["object"] = out.pop("object_id")
        return out

    def describe(self) -> str:
        text = (f"{self.object_id}: measured {self.measured}/{self.frames} frames, mean quality "
                f"{self.mean_quality:.2f}")
        return text + (f", on the motion prior from frame {self.lost_from}" if self.lost_from is not None else "")


def track_health(track: ObjectTrack) -> TrackHealth:
    """The tracker's own evidence on ``track`` (a track file's rows: their ``flags`` and ``scores``, the tracker's
    quality) and the rule's verdict (module doc)."""
    valid = np.array([frame_is_valid(f) for f in track.flags[1:]], dtype=bool)
    n = len(valid)
    measured = int(valid.sum())
    share = measured / n if n else 1.0
    longest = run = 0
    for v in valid:
        run = 0 if v else run + 1
        longest = max(longest, run)
    lost_from = None
    if n and not valid[-1]:
        last_measured = np.flatnonzero(valid)
        lost_from = int(track.frames[1 + (int(last_measured[-1]) + 1 if len(last_measured) else 0)])
    status = "lost" if share < LOST_BELOW else ("weak" if share < WEAK_BELOW else "ok")
    quality = float(np.mean(track.scores[1:])) if n and track.scores is not None else 1.0
    return TrackHealth(track.object_id, n, measured, round(share, 3), round(quality, 3), longest, lost_from, status)
