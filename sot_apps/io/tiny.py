"""A tiny synthetic canonical sequence (deterministic): the built-in default for first runs and tests.

20 frames at 10 Hz. The ego drives along world +x at 5 m/s over a flat ground (z = 0). Two annotated
cars: ``car-move`` (4.5 x 1.8 x 1.5 m) drives along +x at 8 m/s in the next lane; ``car-park``
(4.2 x 1.8 x 1.6 m, heading 0.3 rad) stands still. Points are in the EGO frame with intensity and
per-point time offsets (-100..0 ms by azimuth); one forward camera ``front_camera`` (64 x 48 PNG,
fires 50 ms before the lidar timestamp) is rigidly mounted (``ego_from_camera``).
"""

from __future__ import annotations

import os
import tempfile
from pathlib import Path

import numpy as np

from tracker.geometry import Box, invert_transform, make_transform, rotation_z, transform_points

from ..errors import InputError
from .atomic import write_bytes
from .canonical import write_sequence
from .sequence import BoxAnnotation, Camera, CameraFrame, FrameInfo, Sequence, Sweep

__all__ = ["make_tiny_sequence", "tiny_sequence_dir", "TINY_NUM_FRAMES", "TINY_TRACKS"]

TINY_NUM_FRAMES = 20
TINY_VERSION = 2
_T0_NS = 1_000_000_000_000
_DT_NS = 100_000_000
_EGO_SPEED = 5.0
TINY_TRACKS = {
    "car-move": (Box(8.0, 3.5, 0.75, 0.0, 4.5, 1.8, 1.5), np.array([8.0, 0.0])),
    "car-park": (Box(20.0, -4.5, 0.8, 0.3, 4.2, 1.8, 1.6), np.array([0.0, 0.0])),
}
_EGO_FROM_CAMERA = make_transform(np.array([[0.0, 0.0, 1.0], [-1.0, 0.0, 0.0], [0.0, -1.0, 0.0]]), np.array([1.5, 0.0, 1.5]))
_K = np.array([[40.0, 0.0, 32.0], [0.0, 40.0, 24.0], [0.0, 0.0, 1.0]])


def _box_at(track: str, k: int) -> Box:
    box, velocity = TINY_TRACKS[track]
    t = k * _DT_NS * 1e-9
    return Box(box.x + velocity[0] * t, box.y + velocity[1] * t, box.z, box.heading, box.length, box.width, box.height)


def _world_from_ego(k: float) -> np.ndarray:
    """Ego pose at time ``k`` frames after the first frame (fractional ``k`` allowed)."""
    return make_transform(rotation_z(0.0), np.array([_EGO_SPEED * k * _DT_NS * 1e-9, 0.0, 0.0]))


def _box_surface(box: Box, n: int, rng: np.random.Generator) -> np.ndarray:
    """``n`` points on the sides and top of ``box`` shrunk by 2 cm (inside it for sure; world frame)."""
    l, w, h = box.length - 0.02, box.width - 0.02, box.height - 0.02
    areas = np.array([w * h, w * h, l * h, l * h, l * w])
    face = rng.choice(5, size=n, p=areas / areas.sum())
    u, v = rng.uniform(-0.5, 0.5, size=n), rng.uniform(-0.5, 0.5, size=n)
    pts = np.zeros((n, 3))
    sign = np.where(face % 2 == 0, 0.5, -0.5)
    front_back = face < 2
    sides = (face >= 2) & (face < 4)
    top = face == 4
    pts[front_back] = np.stack([sign[front_back] * l, u[front_back] * w, v[front_back] * h], axis=1)
    pts[sides] = np.stack([u[sides] * l, sign[sides] * w, v[sides] * h], axis=1)
    pts[top] = np.stack([u[top] * l, v[top] * w, np.full(top.sum(), 0.5 * h)], axis=1)
    return transform_points(box.world_from_object(), pts)


def _sweep(k: int) -> Sweep:
    rng = np.random.default_rng(1000 + k)
    world_from_ego = _world_from_ego(k)
    grid = np.arange(-25.0, 25.0 + 1e-9, 0.5)
    gx, gy = np.meshgrid(grid, grid, indexing="ij")
    ground_ego = np.stack([gx.ravel(), gy.ravel(), np.zeros(gx.size)], axis=1)
    ground_ego[:, :2] += rng.uniform(-0.05, 0.05, size=(gx.size, 2))
    cars_world = np.concatenate([_box_surface(_box_at("car-move", k), 600, rng),
                                 _box_surface(_box_at("car-park", k), 400, rng)])
    cars_ego = transform_points(invert_transform(world_from_ego), cars_world)
    xyz = np.concatenate([ground_ego, cars_ego]).astype(np.float32)
    intensity = np.concatenate([np.full(len(ground_ego), 10.0), np.full(len(cars_ego), 80.0)]).astype(np.float32)
    azimuth = np.arctan2(xyz[:, 1].astype(np.float64), xyz[:, 0].astype(np.float64))
    offsets = np.round(-(np.pi - azimuth) / (2 * np.pi) * _DT_NS).astype(np.int64)
    return Sweep(xyz=xyz, intensity=intensity, time_offset_ns=offsets)


def _image_png(k: int) -> bytes:
    import cv2

    image = np.full((48, 64, 3), 90, dtype=np.uint8)
    image[30:, :, :] = 60  # road
    cv2.putText(image, f"{k:02d}", (4, 16), cv2.FONT_HERSHEY_PLAIN, 1.0, (255, 255, 255), 1)
    ok, data = cv2.imencode(".png", image)
    if not ok:
        raise RuntimeError("cv2.imencode failed")
    return data.tobytes()


def make_tiny_sequence(out_dir: str | Path, progress: bool = False) -> Path:
    """Write the tiny sequence in the canonical format to ``out_dir``; returns ``out_dir``."""
    out_dir = Path(out_dir)
    frames = [FrameInfo(index=k, timestamp_ns=_T0_NS + k * _DT_NS, world_from_ego=_world_from_ego(k),
                        points_path=Path(f"points/{k:06d}.npz")) for k in range(TINY_NUM_FRAMES)]
    images = []
    for k in range(TINY_NUM_FRAMES):
        path = out_dir / "cameras" / "front_camera" / f"{k:06d}.png"
        data = _image_png(k)
        if not (path.is_file() and path.read_bytes() == data):
            write_bytes(path, data)
        images.append(path)
    camera = Camera(name="front_camera", K=_K, distortion=np.zeros(5), width=64, height=48,
                    frames=[CameraFrame(timestamp_ns=f.timestamp_ns - 50_000_000, image_path=images[f.index],
                                        world_from_camera=_world_from_ego(f.index - 0.5) @ _EGO_FROM_CAMERA) for f in frames],
                    ego_from_camera=_EGO_FROM_CAMERA)
    annotations = [[BoxAnnotation(track_id=name, label="Car", box=_box_at(name, k), stationary=name == "car-park")
                    for name in TINY_TRACKS] for k in range(TINY_NUM_FRAMES)]
    seq = Sequence(id="tiny", root=Path("<generated>"), format="tiny", frames=frames, load_sweep=_sweep,
                   ego_from_lidar=np.eye(4), cameras={"front_camera": camera}, annotations=annotations)
    write_sequence(seq, out_dir, progress=progress)
    return out_dir


def tiny_sequence_dir(progress: bool = False) -> Path:
    """The tiny sequence in the user cache (``$XDG_CACHE_HOME/sot-apps/tiny-vN``), generated if needed."""
    base = Path(os.environ.get("XDG_CACHE_HOME") or Path.home() / ".cache") / "sot-apps"
    target = base / f"tiny-v{TINY_VERSION}"
    try:
        if (target / "sequence.json").is_file():
            from .canonical import read_sequence

            try:
                read_sequence(target)
                return target
            except InputError:
                pass
        return make_tiny_sequence(target, progress=progress)
    except OSError:
        return make_tiny_sequence(Path(tempfile.mkdtemp(prefix="sot-apps-tiny-")), progress=progress)
