"""Synthetic inputs with known answers for the motion-export tests (no files, no real data)."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from sot_apps.io.object_track import ObjectTrack
from sot_apps.io.sequence import FrameInfo, Sequence, Sweep
from tracker.geometry import make_transform, rotation_z, wrap_angle

T0_NS = 1_557_539_956_500_000_000


def frame_times_ns(n: int, seed: int = 0, jitter_s: float = 0.01) -> np.ndarray:
    """Irregular frame times around 10 Hz (steps 0.1 s +- jitter), integer ns."""
    rng = np.random.default_rng(seed)
    steps = 0.1 + rng.uniform(-jitter_s, jitter_s, n - 1)
    return T0_NS + np.round(np.concatenate([[0.0], np.cumsum(steps)]) * 1e9).astype(np.int64)


def constant_turn(t_s: np.ndarray, speed: float, yaw_rate: float, x0: float = 5.0, y0: float = -2.0,
                  heading0: float = 0.5, z0: float = 1.0) -> np.ndarray:
    """(N, 4) [x, y, z, heading] of a vehicle driving a circle at signed ``speed`` along its heading."""
    heading = heading0 + yaw_rate * t_s
    if abs(yaw_rate) < 1e-12:
        x = x0 + speed * t_s * np.cos(heading0)
        y = y0 + speed * t_s * np.sin(heading0)
    else:
        radius = speed / yaw_rate
        x = x0 + radius * (np.sin(heading) - np.sin(heading0))
        y = y0 - radius * (np.cos(heading) - np.cos(heading0))
    return np.stack([x, y, np.full_like(t_s, z0), wrap_angle(heading)], axis=1)


def make_track(object_id: str, times_ns: np.ndarray, states: np.ndarray, valid: np.ndarray | None = None,
               frames: np.ndarray | None = None, label: str = "Car", shape: bool = False) -> ObjectTrack:
    n = len(times_ns)
    valid = np.ones(n, dtype=bool) if valid is None else np.asarray(valid, dtype=bool)
    flags = [[] if v else ["no_points"] for v in valid]
    shape_points = None
    if shape:
        g = np.linspace(-1.0, 1.0, 5)
        shape_points = np.stack(np.meshgrid(2 * g, g, 0.7 * g), axis=-1).reshape(-1, 3)
    return ObjectTrack.from_states(object_id=object_id, label=label, size=(4.5, 1.9, 1.6),
                       frames=np.arange(n) if frames is None else frames, timestamps_ns=times_ns, states=states,
                       valid=valid, flags=flags, source="synthetic", shape_points=shape_points)


def make_sequence(times_ns: np.ndarray, points_per_frame: int = 200) -> Sequence:
    """An in-memory sequence: ego driving along +x at 5 m/s with a slow turn; random sweeps."""
    t = (times_ns - times_ns[0]) * 1e-9
    frames = [FrameInfo(index=k, timestamp_ns=int(times_ns[k]),
                        world_from_ego=make_transform(rotation_z(0.05 * t[k]), np.array([5.0 * t[k], 0.3 * t[k], 1.8])),
                        points_path=Path(f"/nonexistent/{k:02d}.npz")) for k in range(len(times_ns))]

    def load(k: int) -> Sweep:
        rng = np.random.default_rng(k)
        xyz = rng.uniform(-30, 30, (points_per_frame, 3)).astype(np.float32)
        return Sweep(xyz=xyz, intensity=rng.uniform(0, 255, points_per_frame).astype(np.float32),
                     time_offset_ns=np.zeros(points_per_frame, dtype=np.int64))

    return Sequence(id="synthetic", root=Path("/nonexistent/synthetic"), format="sequence", frames=frames,
                    load_sweep=load)
