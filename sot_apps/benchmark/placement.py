"""Where inserted vehicles go: a motion profile placed on free ground of the background, clear of every real
object, of the ego and of the other inserted vehicles, at every frame.

A candidate is a drawn motion (:mod:`sot_apps.objects.motion_profiles`) started on a free-ground cell about
``r0`` metres from the sensor (``r0`` log-uniform in ``range_m``), heading along the ego's direction of travel, against it,
or across it. It is accepted when, at every frame time of the tracklet,

- its footprint (box enlarged by ``margin`` m, sampled every 0.5 m) has no blocked cell of the
  :class:`~.background.GroundMap` (no real point standing in it over all the frames) and 90 % of it
  lies on observed free ground;
- its enlarged box overlaps no annotated real box of that frame, the ego's box, or another inserted
  vehicle's enlarged box (exact bird's-eye-view polygon intersection);
- it stays at least 4 m from the sensor.

An ``occluded`` tracklet gets a second, unlisted inserted vehicle (the occluder) that is on the line of
sight from the sensor to the target at the middle frame (35-70 % of the way), crossing it along or across
the road. Ground height: the median ground of the footprint at each frame (running median over 5 frames).
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass, replace

import numpy as np

from tracker import iou_3d_batch

from ..objects.motion_profiles import MotionSpec, integrate_motion, place_path, place_states, sample_motion
from .background import GroundMap
from .deps import Trajectory

__all__ = ["InsertedVehicle", "PlacementContext", "place_vehicle", "place_occluder", "EGO_SIZE", "STEP_S"]

EGO_SIZE = (5.0, 2.2)
MIN_GROUND_FRACTION = 0.9
STEP_S = 0.01


@dataclass(frozen=True)
class InsertedVehicle:
    """One inserted vehicle: its bank mesh, its motion and its world trajectory (x, y, z, heading)."""

    id: str
    bank_id: str
    label: str
    size: tuple[float, float, float]
    motion: MotionSpec
    times_ns: np.ndarray
    states: np.ndarray
    listed: bool = True
    occluder_of: str | None = None
    span: tuple[int, int] | None = None   # listed frames (indices into the copy's frames); None: all
    replaces: str | None = None           # a real track this vehicle stands in for (its points are cut)

    def states_at(self, t_ns: np.ndarray | int) -> np.ndarray:
        """(..., 4) x, y, z, heading at the given times (linear between samples, held outside)."""
        return Trajectory(self.times_ns, self.states).states_at(t_ns)


@dataclass
class PlacementContext:
    """The background's facts for placement (world frame) and what has been placed so far."""

    ground: GroundMap
    frame_times_ns: np.ndarray           # (F,) frame timestamps of the tracklet frames
    sensor_xyh: np.ndarray               # (F, 3) sensor x, y, heading at the frames
    real_boxes: list[np.ndarray]         # per frame (R, 7) annotated boxes
    range_m: tuple[float, float] = (5.0, 80.0)
    margin: float = 0.5
    min_sensor_distance: float = 4.0

    def __post_init__(self) -> None:
        self.placed: list[np.ndarray] = []  # (F, 7) boxes of the placed vehicles
        ego = np.zeros((len(self.frame_times_ns), 7))
        ego[:, 0], ego[:, 1], ego[:, 3] = self.sensor_xyh[:, 0], self.sensor_xyh[:, 1], self.sensor_xyh[:, 2]
        ego[:, 4], ego[:, 5], ego[:, 6] = EGO_SIZE[0], EGO_SIZE[1], 2.0
        self._ego = ego
        self._real_frame = np.concatenate([np.full(len(r), f) for f, r in enumerate(self.real_boxes)] + [np.zeros(0, int)])
        self._real = np.vstack([r.reshape(-1, 7) for r in self.real_boxes] + [np.zeros((0, 7))])
        rows, cols = np.nonzero(self.ground.ground)
        self.free_xy = self.ground.origin + (np.column_stack([cols, rows]) + 0.5) * self.ground.cell
        self.free_range = np.hypot(*(self.free_xy - self.sensor_xyh[0, :2]).T)
        order = np.argsort(self.free_range)
        self.free_xy, self.free_range = self.free_xy[order], self.free_range[order]

    def path_start_ns(self) -> int:
        return int(self.frame_times_ns[0]) - 200_000_000

    def duration_s(self) -> float:
        return (int(self.frame_times_ns[-1]) - self.path_start_ns()) * 1e-9 + 0.1


@functools.lru_cache(maxsize=64)
def _footprint_offsets(length: float, width: float) -> np.ndarray:
    """(P, 2) object-frame points every <= 0.5 m over a length x width rectangle."""
    u = np.linspace(-length / 2, length / 2, max(2, int(math.ceil(length / 0.5)) + 1))
    v = np.linspace(-width / 2, width / 2, max(2, int(math.ceil(width / 0.5)) + 1))
    return np.stack([a.ravel() for a in np.meshgrid(u, v)], axis=1)


def _footprint_points(xyh: np.ndarray, size: tuple[float, float, float], margin: float) -> np.ndarray:
    """(F, P, 2) points every <= 0.5 m over the enlarged footprint at each frame."""
    offsets = _footprint_offsets(round(size[0] + 2 * margin, 4), round(size[1] + 2 * margin, 4))
    c, s = np.cos(xyh[:, 2])[:, None], np.sin(xyh[:, 2])[:, None]
    uu, vv = offsets[:, 0], offsets[:, 1]
    return np.stack([xyh[:, 0:1] + c * uu - s * vv, xyh[:, 1:2] + s * uu + c * vv], axis=-1)


def _overlaps(boxes: np.ndarray, others: np.ndarray) -> bool:
    """Any (F, 7) box overlapping the (F, 7) other box of the same frame (bird's-eye view)?"""
    reach = np.hypot(boxes[:, 4], boxes[:, 5]) / 2 + np.hypot(others[:, 4], others[:, 5]) / 2
    close = np.flatnonzero(np.hypot(boxes[:, 0] - others[:, 0], boxes[:, 1] - others[:, 1]) < reach)
    if close.size == 0:
        return False
    flat_a, flat_b = boxes[close].copy(), others[close].copy()  # same z and height: 3D IoU = bird's-eye IoU
    flat_a[:, 2] = flat_b[:, 2] = 0.0
    flat_a[:, 6] = flat_b[:, 6] = 1.0
    return bool((iou_3d_batch(flat_a, flat_b) > 1e-9).any())


def _clear(ctx: PlacementContext, xyh: np.ndarray, size: tuple[float, float, float]) -> np.ndarray | None:
    """(F, 7) enlarged boxes when the frame-time poses ``xyh`` are a valid placement, else None."""
    d = np.hypot(xyh[:, 0] - ctx.sensor_xyh[:, 0], xyh[:, 1] - ctx.sensor_xyh[:, 1])
    if d.min() < ctx.min_sensor_distance:
        return None
    coarse = xyh[:: max(1, len(xyh) // 4)]  # a few frames first: most candidates fail there, cheaply
    if ctx.ground.blocked_at(_footprint_points(coarse, size, ctx.margin).reshape(-1, 2)).any():
        return None
    foot = _footprint_points(xyh, size, ctx.margin).reshape(-1, 2)
    if ctx.ground.blocked_at(foot).any() or ctx.ground.free(foot).mean() < MIN_GROUND_FRACTION:
        return None
    boxes = np.zeros((len(xyh), 7))
    boxes[:, 0], boxes[:, 1], boxes[:, 3] = xyh[:, 0], xyh[:, 1], xyh[:, 2]
    boxes[:, 4], boxes[:, 5], boxes[:, 6] = size[0] + 2 * ctx.margin, size[1] + 2 * ctx.margin, size[2]
    if _overlaps(boxes, ctx._ego):
        return None
    for other in ctx.placed:
        if _overlaps(boxes, other):
            return None
    if len(ctx._real) and _overlaps(boxes[ctx._real_frame], ctx._real):
        return None
    return boxes


def _finish(ctx: PlacementContext, vid: str, bank_id: str, label: str, size, spec: MotionSpec, world: np.ndarray,
            times_ns: np.ndarray, boxes: np.ndarray, listed: bool, occluder_of: str | None,
            span: tuple[int, int] | None = None) -> InsertedVehicle:
    at_frames = np.stack([np.interp(ctx.frame_times_ns.astype(np.float64), times_ns.astype(np.float64), world[:, i])
                          for i in range(2)], axis=1)
    foot = _footprint_points(np.column_stack([at_frames, np.interp(ctx.frame_times_ns.astype(np.float64),
                                                                   times_ns.astype(np.float64),
                                                                   np.unwrap(world[:, 2]))]), size, 0.0)
    ground = np.median(ctx.ground.z(foot.reshape(-1, 2)).reshape(foot.shape[:2]), axis=1)
    padded = np.pad(ground, 2, mode="edge")
    ground = np.median(np.lib.stride_tricks.sliding_window_view(padded, 5), axis=1)
    z = np.interp(times_ns.astype(np.float64), ctx.frame_times_ns.astype(np.float64), ground) + size[2] / 2
    states = np.column_stack([world[:, 0], world[:, 1], z, world[:, 2]])
    ctx.placed.append(boxes)
    return InsertedVehicle(vid, bank_id, label, tuple(float(s) for s in size), spec, times_ns, states, listed,
                           occluder_of, span)


def _path(ctx: PlacementContext, spec: MotionSpec):
    path = integrate_motion(spec, ctx.duration_s(), STEP_S)
    times_ns = ctx.path_start_ns() + np.round(path.times_s * 1e9).astype(np.int64)
    frame_idx = np.clip(np.round((ctx.frame_times_ns - times_ns[0]) / (STEP_S * 1e9)).astype(int), 0, len(times_ns) - 1)
    return path, times_ns, frame_idx


def place_vehicle(ctx: PlacementContext, rng: np.random.Generator, vid: str, bank_id: str, label: str,
                  size: tuple[float, float, float], profile: str, attempts: int = 1000) -> InsertedVehicle | None:
    """Place one listed vehicle with a motion of ``profile``; None if no place.

    The motion is redrawn every 50 attempts with its initial speed scaled down by 5 % more each time
    (down to 30 %): the realised speeds are reported per tracklet (``motion.speed0``)."""
    lo, hi = math.log(ctx.range_m[0]), math.log(ctx.range_m[1])
    sh = ctx.sensor_xyh[0, 2]
    for attempt in range(attempts):
        if attempt % 50 == 0:  # a new draw, slower each time (fast paths need long stretches of free road)
            spec = sample_motion(profile, rng, ctx.duration_s())
            spec = replace(spec, speed0=spec.speed0 * max(0.3, 1.0 - 0.05 * (attempt // 50)))
            path, times_ns, frame_idx = _path(ctx, spec)
            at_frames = path.states()[frame_idx]
        r0 = math.exp(rng.uniform(lo, hi))  # a free cell at about r0 from the sensor
        a, b = np.searchsorted(ctx.free_range, [r0 - max(1.0, 0.05 * r0), r0 + max(1.0, 0.05 * r0)])
        if b <= a:
            continue
        x0, y0 = ctx.free_xy[int(rng.integers(a, b))]
        for turn in rng.permutation([0.0, math.pi, math.pi / 2, -math.pi / 2]):
            heading = sh + turn + rng.normal(0.0, 0.01)
            boxes = _clear(ctx, place_states(at_frames, x0, y0, heading), size)
            if boxes is not None:
                world = place_path(path, x0, y0, heading)
                return _finish(ctx, vid, bank_id, label, size, spec, world, times_ns, boxes, True, None)
    return None


def place_occluder(ctx: PlacementContext, rng: np.random.Generator, target: InsertedVehicle, vid: str, bank_id: str,
                   label: str, size: tuple[float, float, float], attempts: int = 200) -> InsertedVehicle | None:
    """An unlisted vehicle on the sensor-target line of sight at the middle frame, moving at constant speed."""
    mid = len(ctx.frame_times_ns) // 2
    t_mid = int(ctx.frame_times_ns[mid])
    p = target.states_at(t_mid)[:2]
    s = ctx.sensor_xyh[mid, :2]
    sight = math.atan2(p[1] - s[1], p[0] - s[0])
    road = ctx.sensor_xyh[mid, 2]
    for _ in range(attempts):
        q = s + rng.uniform(0.35, 0.7) * (p - s)
        heading = float(rng.choice([road, road + math.pi, sight + math.pi / 2, sight - math.pi / 2]))
        spec = MotionSpec("constant_speed", float(rng.uniform(1.5, 7.0)))
        path, times_ns, frame_idx = _path(ctx, spec)
        back = spec.speed0 * (t_mid - times_ns[0]) * 1e-9  # where to start so that it is at q at t_mid
        x0, y0 = q[0] - back * math.cos(heading), q[1] - back * math.sin(heading)
        world = place_path(path, x0, y0, heading)
        boxes = _clear(ctx, world[frame_idx], size)
        if boxes is not None:
            return _finish(ctx, vid, bank_id, label, size, spec, world, times_ns, boxes, False, target.id)
    return None

