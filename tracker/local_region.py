"""A frame's non-ground world points near a box: the region the tracker's search can reach.

A cheap BEV radius test in the EGO frame first (x and y only, the sweep's precision), so only those points are
moved to the world (de-skewed when asked); the ground is removed on the box scaled ``scale`` + 0.5 grown by the
ground margin, then the points are kept to what a search box can contain (the box scaled ``scale`` + 1 m slack).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from .deskew import deskew_points
from .frames import LidarFrame
from .geometry import Box, invert_transform, transform_points
from .strategies.ground import GroundRemover, RoadPoints

__all__ = ["LocalCrop", "LocalRegion", "local_region", "road_within"]


@dataclass(frozen=True)
class LocalCrop:
    """The ground-removed world points the last step searched: every finite, non-ground point of sweep
    ``frame`` whose BEV position lies in the rectangle centred on ``box`` (its heading) with half extents
    ``half_length`` x ``half_width`` (no height limit), in the sweep's order. The fixed-lag window takes its
    region from it when the region fits inside (:func:`tracker.offline.frame_region_points`)."""

    frame: int
    points: np.ndarray = field(repr=False)
    box: Box
    half_length: float
    half_width: float
    ground: str  # "none" (nothing removed) or "sweep" (the cached whole-sweep mask); else not reusable
    time_offsets_ns: np.ndarray | None = field(default=None, repr=False)  # each point's capture time, if known

    def contains(self, box: Box, scale: float, tolerance: float = 1e-3) -> bool:
        """Whether ``box`` scaled ``scale`` (BEV) lies inside the rectangle, ``tolerance`` inside its edges."""
        c, s = np.cos(box.heading), np.sin(box.heading)
        hl, hw = 0.5 * box.length * scale, 0.5 * box.width * scale
        corners = np.array([[hl, hw], [hl, -hw], [-hl, hw], [-hl, -hw]]) @ np.array([[c, s], [-s, c]])
        d = corners + (box.center[:2] - self.box.center[:2])
        cc, ss = np.cos(self.box.heading), np.sin(self.box.heading)
        u = np.abs(d @ np.array([cc, ss]))
        v = np.abs(d @ np.array([-ss, cc]))
        return bool(np.all(u <= self.half_length - tolerance) and np.all(v <= self.half_width - tolerance))


@dataclass(frozen=True)
class LocalRegion:
    """``points``: the non-ground world points; ``road``: the road points near the box (for the height);
    ``crop``: the same points as a :class:`LocalCrop`; ``flags``: e.g. "nan_points"."""

    points: np.ndarray
    road: np.ndarray
    crop: LocalCrop | None
    flags: tuple[str, ...]


def local_region(frame: LidarFrame, box: Box, scale: float, ground: GroundRemover, road: RoadPoints,
                 margin: float, deskew: bool, previous_pose: tuple[int, np.ndarray] | None) -> LocalRegion:
    """Non-ground world points near ``box`` (BEV radius of the box scaled by ``scale`` plus a margin)."""
    empty = np.zeros((0, 3))
    flags: list[str] = []
    pts = np.asarray(frame.points_ego)
    if pts.ndim != 2 or pts.shape[1] != 3 or len(pts) == 0:
        return LocalRegion(empty, empty, None, ())
    ego_from_world = invert_transform(np.asarray(frame.world_from_ego, dtype=np.float64))
    centre_ego = transform_points(ego_from_world, box.center[None])[0]
    radius = 0.5 * float(np.hypot(box.length, box.width)) * (scale + 0.5) + margin
    deskew = (deskew and frame.point_time_offset_ns is not None and previous_pose is not None
              and len(frame.point_time_offset_ns) == len(pts))
    if deskew:
        assert previous_pose is not None
        radius += float(np.linalg.norm(frame.world_from_ego[:3, 3] - previous_pose[1][:3, 3])) + 0.5
    # cheap BEV radius test in the ego frame on the whole sweep (x and y only, the sweep's precision)
    dx = pts[:, 0] - pts.dtype.type(centre_ego[0])
    dy = pts[:, 1] - pts.dtype.type(centre_ego[1])
    dx *= dx
    dy *= dy
    dx += dy
    near = dx <= radius * radius
    if not np.isfinite(pts).all():
        flags.append("nan_points")
        near &= np.isfinite(pts).all(axis=1)
    idx = np.flatnonzero(near)
    local = pts[idx].astype(np.float64)
    offsets = frame.point_time_offset_ns
    times = np.asarray(offsets)[idx] if offsets is not None and len(offsets) == len(pts) else None
    known = ground.candidates(pts, idx)
    if deskew:
        assert previous_pose is not None and frame.point_time_offset_ns is not None
        prev_t, prev_pose = previous_pose
        world = deskew_points(local, np.asarray(frame.point_time_offset_ns)[idx], frame.timestamp_ns,
                              frame.world_from_ego, prev_t, prev_pose)
    else:
        world = transform_points(frame.world_from_ego, local)
    # ground removal on the region the search can reach: the box scaled by ``scale``, grown by a margin
    ca, sa = np.cos(box.heading), np.sin(box.heading)
    d = world[:, :2] - box.center[:2]
    u = np.abs(d @ np.array([ca, sa]))
    v = np.abs(d @ np.array([-sa, ca]))
    gscale = scale + 0.5
    region = (u <= 0.5 * box.length * gscale + margin) & (v <= 0.5 * box.width * gscale + margin)
    world = world[region]
    times = None if times is None else times[region]
    is_ground = ground.mask(world, None if known is None else known[region])
    road_points = empty
    if is_ground is not None:
        road_points = world[road.road(world, is_ground)]
        world = world[~is_ground]
        times = None if times is None else times[~is_ground]
    # keep only what a search box can contain (the box moves a little during the outer loop)
    d = world[:, :2] - box.center[:2]
    u = np.abs(d @ np.array([ca, sa]))
    v = np.abs(d @ np.array([-sa, ca]))
    slack = 1.0
    half_length, half_width = 0.5 * box.length * scale + slack, 0.5 * box.width * scale + slack
    kept = (u <= half_length) & (v <= half_width)
    world = world[kept]
    crop = LocalCrop(frame.index, world, box, half_length, half_width, ground.label,
                     None if times is None else times[kept])
    return LocalRegion(world, road_points, crop, tuple(flags))


def road_within(road: np.ndarray, box: Box, frame: LidarFrame, max_range: float) -> np.ndarray:
    """``road`` (the region's road points), or none of them when ``max_range`` > 0 and ``box`` is farther than that
    from the sensor (horizontally): the road around a far box is seen too sparsely to hold its height."""
    if max_range > 0 and np.hypot(*(box.center[:2] - frame.world_from_ego[:2, 3])) > max_range:
        return road[:0]
    return road
