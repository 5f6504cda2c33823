"""Timed object states (``x, y, z, heading``, world frame) and camera poses at other timestamps.

One :class:`Trajectory` serves flow, the LiDAR simulator, the bank and the synthetic world. States are
interpolated linearly in position and in the UNWRAPPED heading (unwrapped once, at construction). Outside
the samples the ``end`` mode says what happens, explicitly:

- ``"hold"``: the end states are held (the simulator's sensor and objects, the bank's de-skew);
- ``"extrapolate"``: the end segment is continued linearly (flow: PandaSet's front camera fires about 50 ms
  before the LiDAR; never assume it -- the camera's own timestamps are used).

Optional ``tilts`` (N, 2) ``[roll, pitch]`` per sample (default: level) are interpolated the same way and
turn the object frame to Rz(heading) Ry(pitch) Rx(roll), as :class:`tracker.Box` does: a box that is not
level in the world (AV2, Waymo, nuScenes on a tilted ego) is placed as the source gave it.

``max_extrapolation_ns`` (None: unlimited) bounds :meth:`Trajectory.covers` / :meth:`Trajectory.state_at`.
Camera poses, when a camera only has ego poses, are interpolated on SE(3) by :func:`tracker.interpolate_pose`.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Literal

import numpy as np

from tracker import rotation_zyx

from ..io.object_track import ObjectTrack

__all__ = ["Trajectory", "EndMode", "CAMERA_EXTRAPOLATION_NS", "world_from_object", "wrap_heading"]

EndMode = Literal["hold", "extrapolate"]

# How far flow extrapolates a track to a camera timestamp beyond its LiDAR samples.
CAMERA_EXTRAPOLATION_NS = 150_000_000


def world_from_object(states: np.ndarray) -> np.ndarray:
    """(..., 4) states ``[x, y, z, heading]`` -> (..., 4, 4) ``world_from_object`` transforms."""
    states = np.asarray(states, dtype=np.float64)
    c, s = np.cos(states[..., 3]), np.sin(states[..., 3])
    out = np.zeros(states.shape[:-1] + (4, 4))
    out[..., 0, 0], out[..., 0, 1], out[..., 1, 0], out[..., 1, 1] = c, -s, s, c
    out[..., 2, 2] = 1.0
    out[..., 3, 3] = 1.0
    out[..., :3, 3] = states[..., :3]
    return out


def wrap_heading(heading: np.ndarray | float) -> np.ndarray:
    """Heading(s) wrapped to [-pi, pi)."""
    return (np.asarray(heading, dtype=np.float64) + np.pi) % (2 * np.pi) - np.pi


@dataclass(frozen=True)
class Trajectory:
    """States of one object: ``times_ns`` (N,) int64 strictly increasing, ``states`` (N, 4) with unwrapped heading.

    The constructor sorts the samples, drops repeated times and unwraps the heading, so
    ``Trajectory(times, states, end=...)`` and :meth:`from_samples` are the same thing.
    """

    times_ns: np.ndarray
    states: np.ndarray
    end: EndMode = "hold"
    max_extrapolation_ns: int | None = None
    tilts: np.ndarray | None = None   # (N, 2) [roll, pitch]; None: level

    def __post_init__(self) -> None:
        times = np.asarray(self.times_ns, dtype=np.int64).ravel()
        values = np.array(self.states, dtype=np.float64).reshape(-1, 4)
        if len(times) != len(values) or len(times) == 0:
            raise ValueError("need as many times as states, at least one")
        if self.end not in ("hold", "extrapolate"):
            raise ValueError(f"end must be 'hold' or 'extrapolate', not {self.end!r}")
        tilts = None if self.tilts is None else np.array(self.tilts, dtype=np.float64).reshape(-1, 2)
        if tilts is not None and len(tilts) != len(times):
            raise ValueError("need as many tilts as states")
        order = np.argsort(times, kind="stable")
        times, values = times[order], values[order]
        keep = np.concatenate([[True], np.diff(times) > 0])
        times, values = times[keep], values[keep]
        values[:, 3] = np.unwrap(values[:, 3])
        if tilts is not None:
            tilts = tilts[order][keep]
            tilts = None if not tilts.any() else tilts
        object.__setattr__(self, "times_ns", times)
        object.__setattr__(self, "states", values)
        object.__setattr__(self, "tilts", tilts)

    @classmethod
    def from_samples(cls, times_ns, states, end: EndMode = "hold", max_extrapolation_ns: int | None = None,
                     tilts=None) -> "Trajectory":
        return cls(times_ns, states, end, None if max_extrapolation_ns is None else int(max_extrapolation_ns), tilts)

    @classmethod
    def from_track(cls, track: ObjectTrack, end: EndMode = "hold", max_extrapolation_ns: int | None = None
                   ) -> "Trajectory":
        """The states (and tilts) of ``track`` at its ``timestamps_ns``: every row, valid or not."""
        if track.timestamps_ns is None:
            raise ValueError(f"{track.object_id}: a trajectory needs the track's timestamps_ns")
        return cls.from_samples(track.timestamps_ns, track.states, end, max_extrapolation_ns, track.tilts)

    @classmethod
    def static(cls, x: float, y: float, z: float, heading: float, roll: float = 0.0, pitch: float = 0.0
               ) -> "Trajectory":
        """A fixed pose (one sample, held at every time)."""
        return cls(np.zeros(1, dtype=np.int64), np.array([[x, y, z, heading]], dtype=np.float64),
                   tilts=np.array([[roll, pitch]], dtype=np.float64))

    @property
    def is_static(self) -> bool:
        return len(self.times_ns) == 1

    def covers(self, time_ns: int) -> bool:
        if self.max_extrapolation_ns is None:
            return True
        return bool(self.times_ns[0] - self.max_extrapolation_ns <= time_ns <= self.times_ns[-1] + self.max_extrapolation_ns)

    def _interpolated(self, values: np.ndarray, times_ns: np.ndarray | int) -> np.ndarray:
        shape, width = np.shape(times_ns), values.shape[1]
        times = np.asarray(times_ns, dtype=np.int64).ravel()
        t = self.times_ns
        if len(t) == 1:
            return np.repeat(values, len(times), axis=0).reshape(shape + (width,))
        if self.end == "hold":
            times = np.clip(times, t[0], t[-1])
        i = np.clip(np.searchsorted(t, times) - 1, 0, len(t) - 2)
        alpha = (times - t[i]).astype(np.float64) / (t[i + 1] - t[i]).astype(np.float64)
        return (values[i] + alpha[:, None] * (values[i + 1] - values[i])).reshape(shape + (width,))

    def states_at(self, times_ns: np.ndarray | int) -> np.ndarray:
        """(..., 4) states at the given times (any shape; heading unwrapped); the ``end`` mode outside the
        samples, no coverage check."""
        return self._interpolated(self.states, times_ns)

    def tilts_at(self, times_ns: np.ndarray | int) -> np.ndarray:
        """(..., 2) ``[roll, pitch]`` at the given times (zeros for a level trajectory)."""
        if self.tilts is None:
            return np.zeros(np.shape(times_ns) + (2,))
        return self._interpolated(self.tilts, times_ns)

    def state_at(self, time_ns: int) -> np.ndarray | None:
        """[x, y, z, heading] at ``time_ns`` (heading unwrapped), or None outside the covered span."""
        return self.states_at(int(time_ns)) if self.covers(time_ns) else None

    def poses_at(self, times_ns: np.ndarray | int) -> np.ndarray:
        """(..., 4, 4) ``world_from_object`` at the given times, with the tilts (the ``end`` mode outside the
        samples, no coverage check)."""
        states = self.states_at(times_ns)
        out = world_from_object(states)
        if self.tilts is not None:
            tilts = self.tilts_at(times_ns)
            out[..., :3, :3] = rotation_zyx(states[..., 3], tilts[..., 1], tilts[..., 0])
        return out

    def world_from_object_at(self, time_ns: int) -> np.ndarray | None:
        state = self.state_at(time_ns)
        if state is None:
            return None
        out = world_from_object(state)
        if self.tilts is not None:
            roll, pitch = self.tilts_at(int(time_ns))
            out[:3, :3] = rotation_zyx(float(state[3]), float(pitch), float(roll))
        return out

    def object_from_world_points(self, points_world: np.ndarray, times_ns: np.ndarray) -> np.ndarray:
        """Object-frame coordinates of world points captured at their own times (rolling-shutter LiDAR)."""
        times = np.asarray(times_ns).ravel()
        states = self.states_at(times)
        d = np.asarray(points_world, dtype=np.float64).reshape(-1, 3) - states[:, :3]
        c, s = np.cos(states[:, 3]), np.sin(states[:, 3])
        local = np.stack([c * d[:, 0] + s * d[:, 1], -s * d[:, 0] + c * d[:, 1], d[:, 2]], axis=1)
        if self.tilts is None:
            return local
        roll, pitch = self.tilts_at(times).T   # undo Ry(pitch) then Rx(roll): local = Rx^T Ry^T Rz^T d
        cp, sp, cr, sr = np.cos(pitch), np.sin(pitch), np.cos(roll), np.sin(roll)
        x = cp * local[:, 0] - sp * local[:, 2]
        z = sp * local[:, 0] + cp * local[:, 2]
        return np.stack([x, cr * local[:, 1] + sr * z, -sr * local[:, 1] + cr * z], axis=1)
