"""The paper's "Det" row: a detector's boxes associated over time with a constant-velocity Kalman filter.

No point registration: the state [x, y, z, heading, vx, vy, vz] (velocities in metres per frame) is
predicted with constant velocity, the frame's detection with the largest BEV IoU with the predicted box
(score >= ``det_min_score``, IoU >= ``det_min_iou``, the same rule as the Detection term) updates it, and
a frame without a qualifying detection keeps the prediction. The box size stays the first box's
(as in the paper's Det row). The noise levels are :class:`KalmanNoise` (documented in docs/detection.md).
"""

from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np

from .config import TrackerConfig
from .detection import Detections, align_heading, associate_detection
from .frames import FrameSource
from .geometry import Box, points_in_box, wrap_angle
from .sotracker import FrameEstimate, TrackResult

__all__ = ["KalmanNoise", "ConstantVelocityFilter", "track_detections"]


@dataclass(frozen=True)
class KalmanNoise:
    """Standard deviations, per frame (10 Hz): the measurement noise of a detection (a learned detector's
    typical centre / heading error), the process noise (velocity change per frame, ~5 m/s^2 at 10 Hz), and
    the initial velocity uncertainty (unknown: a vehicle may drive at 30 m/s = 3 m/frame)."""

    position: float = 0.2
    heading: float = 0.1
    position_process: float = 0.02
    heading_process: float = 0.05
    velocity_process: float = 0.05
    initial_velocity: float = 3.0


class ConstantVelocityFilter:
    """Kalman filter on [x, y, z, heading, vx, vy, vz]; ``predict()`` then optionally ``update(box)``."""

    def __init__(self, box: Box, noise: KalmanNoise = KalmanNoise()) -> None:
        self.x = np.zeros(7)
        self.x[:4] = box.to_array()[:4]
        self.P = np.diag([noise.position ** 2] * 3 + [noise.heading ** 2] + [noise.initial_velocity ** 2] * 3)
        self.F = np.eye(7)
        self.F[0, 4] = self.F[1, 5] = self.F[2, 6] = 1.0
        self.Q = np.diag([noise.position_process ** 2] * 3 + [noise.heading_process ** 2]
                         + [noise.velocity_process ** 2] * 3)
        self.H = np.eye(4, 7)
        self.R = np.diag([noise.position ** 2] * 3 + [noise.heading ** 2])

    def predict(self) -> np.ndarray:
        self.x = self.F @ self.x
        self.P = self.F @ self.P @ self.F.T + self.Q
        return self.x[:4].copy()

    def update(self, measurement: np.ndarray) -> None:
        """Update with a box state [x, y, z, heading] (heading taken modulo pi closest to the state's)."""
        z = np.asarray(measurement, dtype=np.float64)[:4].copy()
        z[3] = align_heading(z[3], self.x[3])
        innovation = z - self.H @ self.x
        S = self.H @ self.P @ self.H.T + self.R
        K = np.linalg.solve(S, self.H @ self.P).T
        self.x = self.x + K @ innovation
        self.x[3] = wrap_angle(self.x[3])
        self.P = (np.eye(7) - K @ self.H) @ self.P


def track_detections(source: FrameSource, init_box: Box, start: int, end: int, config: TrackerConfig,
                     detections: Detections, progress=None, noise: KalmanNoise = KalmanNoise()) -> TrackResult:
    """The Det baseline from ``init_box`` at ``start`` through ``end``; estimates carry the associated
    detection's score as quality and the flag "det" (or "prior_only" without a detection)."""
    size = init_box.size
    kf = ConstantVelocityFilter(init_box, noise)

    def estimate(k: int, box: Box, quality: float, flags: tuple[str, ...], t0: float) -> FrameEstimate:
        points = source.lidar_frame(k).points_world()
        obj = points[points_in_box(points, box)]
        return FrameEstimate(k, box.state, box, len(obj), quality, flags, (time.perf_counter() - t0) * 1e3, obj)

    estimates = [estimate(start, init_box, 1.0, ("init",), time.perf_counter())]
    frames = range(start + 1, end + 1)
    for k in (progress(frames) if progress else frames):
        t0 = time.perf_counter()
        predicted = Box(*kf.predict(), *size)
        frame_dets = detections.get(k)
        d = config.detection
        det = associate_detection(predicted, frame_dets, d.min_score, d.min_iou, d.max_distance)
        if det is None or frame_dets is None:   # no detection is associated without detections
            quality, flags = 0.0, ("prior_only",)
        else:
            kf.update(det)
            best = np.flatnonzero(np.all(frame_dets.boxes == det, axis=1))[0]
            quality, flags = float(frame_dets.scores[best]), ("det",)
        estimates.append(estimate(k, Box(*kf.x[:4], *size), quality, flags, t0))
    return TrackResult(estimates, size, np.zeros((0, 3)), config)
