"""Object states and camera poses at camera timestamps.

Object states are SE(2) + z (``x, y, z, heading``, world frame) sampled at known times. They are
interpolated linearly in position and in the UNWRAPPED heading, and extrapolated linearly from the
nearest segment for at most ``max_extrapolation_ns`` (PandaSet's front camera fires about 50 ms
before the LiDAR; never assume it — the camera's own timestamps are used).
Camera poses, when a camera only has ego poses, are interpolated on SE(3) (linear translation,
slerp rotation).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.spatial.transform import Rotation, Slerp

from tracker import make_transform, rotation_z

__all__ = ["ObjectTrajectory", "interpolate_pose", "world_from_object"]


def world_from_object(state: np.ndarray) -> np.ndarray:
    """4x4 transform of a state ``[x, y, z, heading]``."""
    x, y, z, heading = (float(v) for v in np.asarray(state, dtype=np.float64).reshape(4))
    return make_transform(rotation_z(heading), np.array([x, y, z]))


@dataclass(frozen=True)
class ObjectTrajectory:
    """States of one object: ``times_ns`` (N,) int64 increasing, ``states`` (N, 4) with unwrapped heading."""

    times_ns: np.ndarray
    states: np.ndarray
    max_extrapolation_ns: int = 150_000_000

    @classmethod
    def from_samples(cls, times_ns, states, max_extrapolation_ns: int = 150_000_000) -> "ObjectTrajectory":
        times = np.asarray(times_ns, dtype=np.int64).ravel()
        values = np.asarray(states, dtype=np.float64).reshape(-1, 4).copy()
        if len(times) != len(values) or len(times) == 0:
            raise ValueError("need as many times as states, at least one")
        order = np.argsort(times, kind="stable")
        times, values = times[order], values[order]
        keep = np.concatenate([[True], np.diff(times) > 0])
        times, values = times[keep], values[keep]
        values[:, 3] = np.unwrap(values[:, 3])
        return cls(times, values, int(max_extrapolation_ns))

    def covers(self, time_ns: int) -> bool:
        return bool(self.times_ns[0] - self.max_extrapolation_ns <= time_ns <= self.times_ns[-1] + self.max_extrapolation_ns)

    def state_at(self, time_ns: int) -> np.ndarray | None:
        """[x, y, z, heading] at ``time_ns`` (heading unwrapped), or None outside the covered span."""
        if not self.covers(time_ns):
            return None
        t = self.times_ns
        if len(t) == 1:
            return self.states[0].copy()
        i = int(np.clip(np.searchsorted(t, time_ns) - 1, 0, len(t) - 2))
        # Linear inside [t_i, t_i+1]; beyond the ends the same formula extrapolates the end segment.
        alpha = (time_ns - int(t[i])) / float(int(t[i + 1]) - int(t[i]))
        return self.states[i] + alpha * (self.states[i + 1] - self.states[i])

    def states_at(self, times_ns: np.ndarray, hold: bool = False) -> np.ndarray:
        """(N, 4) states at many times (linear, extrapolating the end segments; no coverage check). ``hold``:
        outside the samples the end states are held instead."""
        times = np.asarray(times_ns, dtype=np.int64).ravel()
        t = self.times_ns
        if hold:
            times = np.clip(times, t[0], t[-1])
        if len(t) == 1:
            return np.repeat(self.states, len(times), axis=0)
        i = np.clip(np.searchsorted(t, times) - 1, 0, len(t) - 2)
        alpha = (times - t[i]).astype(np.float64) / (t[i + 1] - t[i]).astype(np.float64)
        return self.states[i] + alpha[:, None] * (self.states[i + 1] - self.states[i])

    def object_from_world_points(self, points_world: np.ndarray, times_ns: np.ndarray, hold: bool = False
                                 ) -> np.ndarray:
        """Object-frame coordinates of world points captured at their own times (rolling-shutter LiDAR);
        ``hold`` as in :meth:`states_at`."""
        states = self.states_at(times_ns, hold)
        d = np.asarray(points_world, dtype=np.float64).reshape(-1, 3) - states[:, :3]
        c, s = np.cos(states[:, 3]), np.sin(states[:, 3])
        return np.stack([c * d[:, 0] + s * d[:, 1], -s * d[:, 0] + c * d[:, 1], d[:, 2]], axis=1)

    def world_from_object_at(self, time_ns: int) -> np.ndarray | None:
        state = self.state_at(time_ns)
        return None if state is None else world_from_object(state)

    def velocity_at(self, time_ns: int) -> np.ndarray:
        """d[x, y, z, heading]/dt in units per second, of the segment used at ``time_ns``."""
        t = self.times_ns
        if len(t) == 1:
            return np.zeros(4)
        i = int(np.clip(np.searchsorted(t, time_ns) - 1, 0, len(t) - 2))
        return (self.states[i + 1] - self.states[i]) / ((int(t[i + 1]) - int(t[i])) * 1e-9)


def interpolate_pose(times_ns: np.ndarray, target_from_source: np.ndarray, time_ns: int) -> np.ndarray:
    """SE(3) pose at ``time_ns`` from (N, 4, 4) poses at increasing ``times_ns`` (clamped at the ends)."""
    times = np.asarray(times_ns, dtype=np.int64)
    poses = np.asarray(target_from_source, dtype=np.float64)
    if len(times) == 1:
        return poses[0].copy()
    i = int(np.clip(np.searchsorted(times, time_ns) - 1, 0, len(times) - 2))
    t0, t1 = int(times[i]), int(times[i + 1])
    alpha = float(np.clip((time_ns - t0) / float(t1 - t0), 0.0, 1.0))
    slerp = Slerp([0.0, 1.0], Rotation.from_matrix(poses[i:i + 2, :3, :3]))
    rotation = slerp([alpha]).as_matrix()[0]
    translation = (1.0 - alpha) * poses[i, :3, 3] + alpha * poses[i + 1, :3, 3]
    return make_transform(rotation, translation)
