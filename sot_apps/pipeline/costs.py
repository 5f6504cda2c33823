"""The tracking stage's cost of each object, estimated before it is tracked, so the chunks of a sequence that is
split over several workers carry equal work (:func:`sot_apps.pipeline.plan.track_chunks`).

An object's CPU time is its frames times a cost per frame that grows with the LiDAR points on it: the tracker's
registration and the offline refinement work on the object's points. On the 9 moving dev vehicles of
pandaset_002 (offline mode, preset ``full``) the CPU per object-frame went from 13 ms (18 points in the box) to
61 ms (1,600 points); ``FIXED_MS + PER_SQRT_POINT_MS * sqrt(points)`` fits them within 2.6 ms rms (a straight
line in the points: 4.4 ms; the distance to the ego: 8-11 ms). The points are counted in the object's boxes at a
few frames spread over the sequence (``SAMPLE_FRAMES``, shared by all its objects so each sampled sweep is read
once, through the sweep cache). Only the ratios between objects matter.
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np

from tracker import Box, LidarFrame, points_in_box, transform_points

from .plan import ObjectPlan, open_cached

__all__ = ["estimate_costs", "frame_cost", "FIXED_MS", "PER_SQRT_POINT_MS", "SAMPLE_FRAMES"]

FIXED_MS = 9.0            # CPU per object-frame without points (prediction, bookkeeping, refinement set-up)
PER_SQRT_POINT_MS = 1.3   # ... plus this much per square root of the points in the object's box
SAMPLE_FRAMES = 5         # sweeps read per sequence to count the points


def frame_cost(points: float) -> float:
    """Estimated CPU milliseconds of one object-frame with ``points`` LiDAR points in the object's box."""
    return FIXED_MS + PER_SQRT_POINT_MS * math.sqrt(max(0.0, points))


def _box_near(plan: ObjectPlan, k: int) -> Box:
    """The object's annotated box nearest to frame ``k`` (its initial box when it has no annotations)."""
    if not plan.annotated:
        return plan.init_box
    return min(plan.annotated, key=lambda kb: abs(kb[0] - k))[1]


class _Sweep:
    """A sampled sweep: its points' ego x and y as contiguous columns (the pre-selection reads only those)."""

    def __init__(self, frame: LidarFrame) -> None:
        self.frame = frame
        self.x = np.ascontiguousarray(frame.points_ego[:, 0])
        self.y = np.ascontiguousarray(frame.points_ego[:, 1])
        self.ego_from_world = np.linalg.inv(frame.world_from_ego)

    def points_in(self, box: Box) -> int:
        """How many points lie in ``box`` (world frame): those within the box's radius of its centre in x and y (ego
        frame, float32, a cheap pre-selection), then the exact test on them."""
        centre = self.ego_from_world @ np.array([box.x, box.y, box.z, 1.0])
        radius = 0.5 * math.sqrt(box.length**2 + box.width**2 + box.height**2)
        near = np.flatnonzero((np.abs(self.x - centre[0]) <= radius) & (np.abs(self.y - centre[1]) <= radius))
        points = transform_points(self.frame.world_from_ego, self.frame.points_ego[near])
        return int(points_in_box(points, box).sum())


def estimate_costs(objects: list[ObjectPlan]) -> list[ObjectPlan]:
    """``objects`` (of ONE sequence) with ``cost`` set: frames tracked x :func:`frame_cost` of the mean point count
    in the object's boxes at the sampled frames inside its range (objects without annotations: at their start
    frame, the only box known). A sampled sweep that is missing or unreadable is left out; an object with no
    sampled sweep left costs :data:`FIXED_MS` per frame."""
    if not objects:
        return []
    first = min(o.start for o in objects)
    last = max(o.end for o in objects)
    grid = sorted({int(round(k)) for k in np.linspace(first, last, SAMPLE_FRAMES)})
    samples = {o.key: ([k for k in grid if o.start <= k <= o.end] if o.annotated else []) or [o.start]
               for o in objects}
    seq = open_cached(objects[0].sequence_path, objects[0].format)
    frames: dict[int, _Sweep | None] = {}
    for k in sorted({k for ks in samples.values() for k in ks}):
        try:
            frame = seq.lidar_frame(k)
            frames[k] = _Sweep(frame) if frame.has_sweep else None
        except Exception:  # noqa: BLE001 - an estimate only: the task reports a sweep it cannot read
            frames[k] = None
    out = []
    for o in objects:
        counts = [sweep.points_in(_box_near(o, k)) for k in samples[o.key] if (sweep := frames[k]) is not None]
        per_frame = float(np.mean([frame_cost(n) for n in counts])) if counts else FIXED_MS
        out.append(dataclasses.replace(o, cost=round(max(1, o.end - o.start) * per_frame, 1)))
    return out
