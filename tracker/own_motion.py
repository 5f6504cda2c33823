"""The object's own motion during a sweep, taken out of its points (offline refinement).

A spinning LiDAR's sweep takes ~0.1 s, and sweeps compensated for the ego's motion (PandaSet's, the synthetic
world's) still hold every object where it was when each ray hit it. An object seen within a few degrees of azimuth
is hit within a few milliseconds, so this does not matter, except at the sweep's seam. There the returns of one
object come from its start and its end, 0.1 s apart, and a car at 8 m/s shows its two parts 0.8 m apart along its
travel: a sheared face, which a registration takes for a turned one (docs/tracker-decisions.md, "The object's own
motion during the sweep").

:func:`own_motion_compensated` moves each point by the object's velocity times the gap between its capture time and
the median capture time of the object's returns, so the points show the object at one time: the time the ground
truth of PandaSet and of the synthetic world describes. It does so only when the object's returns span more than a
given time; otherwise it returns the points as they are. :func:`compensate_track` does it for every frame of a
track, with the velocity of the track's own boxes (central differences).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Sequence

import numpy as np

from .geometry import Box, points_in_box

__all__ = ["RegionTimes", "compensate_track", "own_motion_compensated", "track_velocities"]


@dataclass(frozen=True)
class RegionTimes:
    """When a frame's region points were captured: the frame's timestamp and each point's offset from it (ns)."""

    frame_ns: int
    offsets_ns: np.ndarray = field(repr=False)


def track_velocities(boxes: Sequence[Box], timestamps_ns: Sequence[int]) -> np.ndarray:
    """(n, 2) BEV velocities (m/s, world) of a track's boxes: central differences over the frames' timestamps,
    one-sided at the ends; zeros for a single box or where two frames share a timestamp."""
    n = len(boxes)
    if n < 2:
        return np.zeros((n, 2))
    xy = np.array([b.center[:2] for b in boxes], dtype=np.float64)
    t = np.asarray(timestamps_ns, dtype=np.float64) * 1e-9
    lo = np.r_[0, np.arange(n - 1)]
    hi = np.r_[np.arange(1, n), n - 1]
    dt = t[hi] - t[lo]
    v = np.zeros((n, 2))
    ok = dt > 0
    v[ok] = (xy[hi] - xy[lo])[ok] / dt[ok, None]
    return v


def own_motion_compensated(points: np.ndarray, offsets_ns: np.ndarray, box: Box, velocity: np.ndarray,
                           min_spread_s: float) -> np.ndarray:
    """``points`` (N, 3, world) moved in x, y by ``velocity`` (m/s) x (the median capture time of the points inside
    ``box`` - each point's capture time), when those points' capture times span more than ``min_spread_s``;
    else ``points`` itself. ``offsets_ns`` (N,): each point's capture time relative to any fixed time."""
    if len(points) == 0 or min_spread_s <= 0 or len(offsets_ns) != len(points):
        return points
    times = np.asarray(offsets_ns, dtype=np.float64) * 1e-9
    if float(times.max() - times.min()) <= min_spread_s:   # no subset spans more: most cars, no box test
        return points
    inside = points_in_box(points, box, 1.0)
    if not inside.any():
        return points
    own = times[inside]
    if float(own.max() - own.min()) <= min_spread_s:
        return points
    moved = np.array(points, dtype=np.float64, copy=True)
    moved[:, :2] += (float(np.median(own)) - times)[:, None] * np.asarray(velocity, dtype=np.float64)[None, :2]
    return moved


def compensate_track(points: list[np.ndarray], times: Sequence[RegionTimes | None], boxes: Sequence[Box],
                     min_spread_s: float) -> list[np.ndarray]:
    """Each frame's region ``points`` with the object's own motion taken out (:func:`own_motion_compensated`), the
    velocity from the track's ``boxes``; a frame without ``times`` keeps its points."""
    known = np.array([i for i, t in enumerate(times) if t is not None])
    if min_spread_s <= 0 or len(known) == 0:
        return points
    at = np.array([float(t.frame_ns) for t in times if t is not None])
    # frames without times: their timestamps inter- or extrapolated from the others' (for the velocities only)
    step = (at[-1] - at[0]) / (known[-1] - known[0]) if len(known) > 1 else 0.0
    index = np.arange(len(times))
    stamps = np.where(index < known[0], at[0] + (index - known[0]) * step,
                      np.where(index > known[-1], at[-1] + (index - known[-1]) * step, np.interp(index, known, at)))
    velocity = track_velocities(boxes, stamps.astype(np.int64))
    return [p if t is None else own_motion_compensated(p, t.offsets_ns, b, v, min_spread_s)
            for p, t, b, v in zip(points, times, boxes, velocity, strict=True)]
