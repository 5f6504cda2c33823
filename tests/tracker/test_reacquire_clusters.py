"""Re-acquisition (``reacquire.mode="clusters"``) and heading from travel (``motion.travel_weight``) on synthetic
scenes with known boxes: a car hidden for some frames, a far sparse car that approaches, a straight drive seen
obliquely."""

from __future__ import annotations

import numpy as np
import pytest

from tracker import get_preset, track
from tracker.frames import LidarFrame
from tracker.geometry import Box, invert_transform, make_transform, rotation_z, transform_points
from tracker.metrics import iou_3d_batch

from tracker_synthetic import BOX_SIZE, SyntheticSequence, car_points, ground_points

REACQUIRE = {"reacquire.mode": "clusters"}
_EGO = make_transform(rotation_z(0.0), np.array([0.0, 0.0, 1.0]))   # a parked ego, sensor 1 m up


def _scene(boxes: list[Box], seed: int, hidden: range = range(0), density=lambda r: 80.0,
           ground_centre=(20.0, 4.0), ground_half=16.0) -> SyntheticSequence:
    """The car at ``boxes`` seen from the parked ego (``density(range)`` points per m^2 of a face toward the
    sensor), no car points in ``hidden`` frames, a road around ``ground_centre``."""
    rng = np.random.default_rng(seed)
    frames = []
    sensor = _EGO[:3, 3]
    for k, box in enumerate(boxes):
        road = ground_points(rng, np.array(ground_centre), ground_half, per_m2=2.0)
        rng_m = float(np.linalg.norm(box.center[:2] - sensor[:2]))
        pts = road if k in hidden else np.vstack([road, car_points(rng, box, sensor, density(rng_m))])
        pts = pts + rng.normal(0.0, 0.01, pts.shape)
        ego = transform_points(invert_transform(_EGO), pts).astype(np.float32)
        frames.append(LidarFrame(index=k, timestamp_ns=1_000_000_000 + k * 100_000_000, points_ego=ego,
                                 world_from_ego=_EGO))
    return SyntheticSequence(frames, boxes)


def _straight(n: int, start: tuple[float, float], heading: float, step: float, side_shift: tuple[int, float] = (0, 0.0)
              ) -> list[Box]:
    """A straight drive of ``step`` m per frame; from frame ``side_shift[0]`` on (if > 0) the path is moved
    ``side_shift[1]`` m to the left (a lane change)."""
    u = np.array([np.cos(heading), np.sin(heading)])
    left = np.array([-u[1], u[0]])
    out = []
    for k in range(n):
        xy = np.array(start) + k * step * u
        if side_shift[0] > 0 and k >= side_shift[0]:
            xy = xy + side_shift[1] * left
        out.append(Box(float(xy[0]), float(xy[1]), 0.0, heading, *BOX_SIZE))
    return out


def _iou(result, truth: list[Box]) -> np.ndarray:
    est = np.array([e.box.to_array() for e in result.estimates])
    return iou_3d_batch(est, np.array([b.to_array() for b in truth]))


def _track(seq: SyntheticSequence, **changes):
    return track(seq, seq.boxes[0], 0, len(seq) - 1, get_preset("full", seed=0, **changes))
