"""De-skew: a sweep's points moved by the ego pose at each point's capture time."""

from __future__ import annotations

import numpy as np

__all__ = ["deskew_points"]


def _axis_angle(rotation: np.ndarray) -> tuple[np.ndarray, float]:
    """Unit axis and angle of a 3x3 rotation."""
    angle = float(np.arccos(np.clip((np.trace(rotation) - 1.0) / 2.0, -1.0, 1.0)))
    axis = np.array([rotation[2, 1] - rotation[1, 2], rotation[0, 2] - rotation[2, 0], rotation[1, 0] - rotation[0, 1]])
    norm = np.linalg.norm(axis)
    if norm < 1e-12:
        return np.array([0.0, 0.0, 1.0]), 0.0
    return axis / norm, angle


def deskew_points(points_ego: np.ndarray, offsets_ns: np.ndarray, timestamp_ns: int, world_from_ego: np.ndarray,
                  previous_timestamp_ns: int, previous_world_from_ego: np.ndarray) -> np.ndarray:
    """World points with each point moved by the ego pose at its capture time.

    The pose at time t is interpolated between the previous frame's pose and this frame's (SLERP of the
    rotation, linear translation); times outside the interval extrapolate.
    """
    dt = float(timestamp_ns - previous_timestamp_ns)
    s = 1.0 + np.asarray(offsets_ns, dtype=np.float64) / dt if dt != 0 else np.ones(len(points_ego))
    r0, r1 = previous_world_from_ego[:3, :3], world_from_ego[:3, :3]
    t0, t1 = previous_world_from_ego[:3, 3], world_from_ego[:3, 3]
    axis, angle = _axis_angle(r0.T @ r1)
    p = np.asarray(points_ego, dtype=np.float64)
    a = s * angle
    ca, sa = np.cos(a)[:, None], np.sin(a)[:, None]
    rotated = p * ca + np.cross(axis, p) * sa + np.outer(p @ axis, axis) * (1.0 - ca)  # Rodrigues
    return rotated @ r0.T + t0 + s[:, None] * (t1 - t0)
