"""Searching for a track's object again: the empty start's slide along the heading (``first_frame.reacquire``)
and the candidates of the lost-track search (``reacquire.mode="clusters"``, tracker/strategies/reacquire.py).

The empty start's search (``first_frame.reacquire``): where along its heading a held start box finds points.

The start box had too few points to follow. A region along its heading that grows with the time since the start
is searched: ``max_speed`` x elapsed ahead, a third of that behind, the box's width + 0.5 m each side across.
Once one box length of it holds ``min_points`` non-ground points, the box slides along its heading to where it
holds the most of them (among equals, where its face toward the sensor meets the points: that face is the
visible one).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .geometry import Box, points_in_box
from .shape import to_object_frame

__all__ = ["Candidate", "EarlierSweep", "box_holds_against", "cluster_candidates", "filled_start", "search_region",
           "start_shift"]


class EarlierSweep:
    """The non-ground points (world) of an earlier sweep, indexed once in BEV: which of a later sweep's points
    have one of them within a radius."""

    def __init__(self, points: np.ndarray) -> None:
        from scipy.spatial import cKDTree  # here, not at import: only a search compared with an earlier sweep

        self.size = len(points)
        self._tree = cKDTree(np.asarray(points, dtype=np.float64).reshape(-1, 3)[:, :2])

    def near(self, points: np.ndarray, radius: float) -> np.ndarray:
        """Boolean mask of ``points`` (N x 2 or 3, world) with an earlier point within ``radius`` m in BEV."""
        if self.size == 0 or len(points) == 0:
            return np.zeros(len(points), dtype=bool)
        return np.isfinite(self._tree.query(np.asarray(points)[:, :2], distance_upper_bound=radius)[0])


def search_region(box: Box, ahead: float, behind: float, across: float = 0.5, rise: float = 0.0) -> Box:
    """The box stretched ``ahead`` along its heading and ``behind`` against it, ``across`` wider each side and
    ``rise`` taller each way (a road that climbs or falls)."""
    return Box(box.x + 0.5 * (ahead - behind) * np.cos(box.heading),
               box.y + 0.5 * (ahead - behind) * np.sin(box.heading), box.z, box.heading,
               box.length + ahead + behind, box.width + 2.0 * across, box.height + 2.0 * rise)


def start_shift(local: np.ndarray, box: Box, ahead: float, behind: float, min_points: int,
                sensor: np.ndarray) -> float | None:
    """The shift along ``box``'s heading where it holds the most of ``local``'s points (at least ``min_points``),
    or None; ``sensor``: the sensor's world position."""
    reach = search_region(box, ahead, behind)
    obj = to_object_frame(local[points_in_box(local, reach, 1.0)], reach)
    u = np.sort(obj[:, 0] + 0.5 * (ahead - behind))      # along the heading, from the start box's centre
    shifts = np.arange(-behind, ahead + 0.05, 0.1)
    half = 0.5 * box.length                              # points within a box length of each shift
    counts = np.searchsorted(u, shifts + half, side="right") - np.searchsorted(u, shifts - half, side="left")
    if counts.max(initial=0) < min_points:
        return None
    best = shifts[counts == counts.max()]
    sensor_u = float(np.dot(sensor[:2] - box.center[:2], [np.cos(box.heading), np.sin(box.heading)]))
    return float(best.min() if sensor_u > best.mean() else best.max())  # the visible face meets the points


def filled_start(points: np.ndarray, box: Box, min_points: int, sensor: np.ndarray) -> np.ndarray:
    """Where a held start ``box`` that holds its object's points again starts (``reacquire.start_fill_frames``): its
    centre (xy, world) slid along its heading, by at most half its length, to where it holds the most of ``points``
    (world; at least ``min_points``; in place if nowhere); ``sensor``: the sensor's world position."""
    half = 0.5 * box.length
    shift = start_shift(points, box, half, half, min_points, sensor) or 0.0
    return box.center[:2] + shift * np.array([np.cos(box.heading), np.sin(box.heading)])


@dataclass(frozen=True)
class Candidate:
    """A non-ground cluster of the right size: the box placed on it (``centre``, xy, world), its extent along
    and across the searched box's heading (m), its number of points, the time it was seen (s), how many of
    its points the searched box (scaled by ``hold_scale``) holds, whether the cluster reaches the searched
    region's side (``cut``: its extent and centre are those of the part inside), and ``anchor`` (xy, world): per
    axis of the box, the cluster's end that the region does not cut where only one end is cut, else the middle of
    its extent (the part of a cut cluster that moves with the object, not with the region), and ``before``: the
    share of its points that have a point of the earlier sweep it is compared with within a radius (1 at rest
    where something already was; 0 when not compared)."""

    centre: np.ndarray
    extent: np.ndarray
    count: int
    time_s: float
    held: int = 0
    cut: bool = False
    anchor: np.ndarray | None = None
    before: float = 0.0


def _anchor(low: np.ndarray, high: np.ndarray, cut_low: np.ndarray, cut_high: np.ndarray) -> np.ndarray:
    """Per cluster and axis (box frame) the point of its extent that is the object's own: the end the region
    does not cut where only one end is cut (the other is the region's side, which moves with the region), else
    the middle."""
    return np.where(cut_low & ~cut_high, high, np.where(cut_high & ~cut_low, low, 0.5 * (low + high)))


def cluster_candidates(points: np.ndarray, box: Box, sensor: np.ndarray, cell: float, min_points: int,
                       size_margin: float, time_s: float, centred: bool = False,
                       hold_scale: float = 1.0, region: Box | None = None,
                       earlier: EarlierSweep | None = None, radius: float = 0.5) -> list[Candidate]:
    """The clusters of ``points`` (non-ground, world) on a BEV grid of ``cell`` metres (8-connected cells) that
    hold at least ``min_points`` points and fit ``box``'s length and width + ``size_margin``, each with ``box``
    placed on it: along an axis where the cluster is shorter than the box and the line of sight from ``sensor``
    is within 60 degrees of the axis, the box's face toward the sensor meets the points (the visible face, as in
    :func:`start_shift`); else, or with ``centred``, the box is centred on the cluster's extent (which end of the
    object a short cluster shows is ambiguous for a track that was lost: the near end seen, the near end hidden by
    an occluder, the roof of a far car; centred, the box is off by at most half the unseen length). ``held``: the
    cluster's points inside ``box`` scaled by ``hold_scale`` (whether the box already holds that object).
    ``region``: the searched region (a box with ``box``'s heading); a cluster with points within ``cell`` of its
    sides is ``cut``. ``earlier``: the non-ground points of an earlier sweep; each candidate's ``before`` is the
    share of its points with one of them within ``radius`` m in BEV."""
    if len(points) < min_points:
        return []
    c, s = np.cos(box.heading), np.sin(box.heading)
    d = points[:, :2] - box.center[:2]
    uv = np.column_stack([d @ np.array([c, s]), d @ np.array([-s, c])])
    ij = np.floor((uv - uv.min(axis=0)) / cell).astype(np.int64)
    grid = np.zeros(tuple(ij.max(axis=0) + 1), dtype=bool)
    grid[ij[:, 0], ij[:, 1]] = True
    from scipy import ndimage  # here, not at import: only a re-acquisition search labels clusters

    labels, count = ndimage.label(grid, structure=np.ones((3, 3), dtype=bool))
    if count == 0:
        return []
    label = labels[ij[:, 0], ij[:, 1]] - 1
    sizes = np.bincount(label, minlength=count)
    low = np.full((count, 2), np.inf)
    high = np.full((count, 2), -np.inf)
    np.minimum.at(low, label, uv)
    np.maximum.at(high, label, uv)
    extent = high - low
    limit = np.array([box.length, box.width]) + size_margin
    keep = np.flatnonzero((sizes >= min_points) & np.all(extent <= limit, axis=1))
    if len(keep) == 0:
        return []
    sensor_uv = np.array([(sensor[:2] - box.center[:2]) @ np.array([c, s]),
                          (sensor[:2] - box.center[:2]) @ np.array([-s, c])])
    half = 0.5 * np.array([box.length, box.width])
    mid = 0.5 * (low[keep] + high[keep])
    toward = sensor_uv < mid                               # the sensor is on the low side: that face is seen
    placed = np.where(toward, low[keep] + half, high[keep] - half)
    sight = sensor_uv - mid
    faced = np.abs(sight) > 0.5 * np.linalg.norm(sight, axis=1, keepdims=True)  # that face is seen, not edge-on
    placed = np.where(faced & (extent[keep] < 2.0 * half) & (not centred), placed, mid)
    world = box.center[:2] + placed[:, :1] * np.array([c, s]) + placed[:, 1:] * np.array([-s, c])
    held = np.bincount(label[points_in_box(points, box, hold_scale)], minlength=count)
    cut_low = cut_high = np.zeros((count, 2), dtype=bool)
    if region is not None:
        r = region.center[:2] - box.center[:2]
        centre = np.array([r @ np.array([c, s]), r @ np.array([-s, c])])
        inner = 0.5 * np.array([region.length, region.width]) - cell
        cut_low, cut_high = low < centre - inner, high > centre + inner
    cut = np.any(cut_low | cut_high, axis=1)
    own = _anchor(low[keep], high[keep], cut_low[keep], cut_high[keep])
    anchor = box.center[:2] + own[:, :1] * np.array([c, s]) + own[:, 1:] * np.array([-s, c])
    before = np.zeros(count)
    if earlier is not None:   # only the candidates' points are looked up
        mine = np.isin(label, keep)
        near = np.bincount(label[mine], weights=earlier.near(points[mine], radius).astype(np.float64),
                           minlength=count)
        before = near / np.maximum(sizes, 1)
    return [Candidate(world[i], extent[k], int(sizes[k]), time_s, int(held[k]), bool(cut[k]), anchor[i],
                      float(before[k])) for i, k in enumerate(keep)]


def box_holds_against(box: Box, centre: np.ndarray, points: np.ndarray, hold_ties: bool, crop_scale: float) -> bool:
    """Whether a lost track's ``box`` stays where it is against a confirmed candidate at ``centre`` (xy; the search
    goes on): the box placed there would hold fewer of the region's non-ground ``points`` than the box does (the
    frame's points support the track where it is better; a candidate may be only a part of the object, e.g. the
    top of one that re-appears from behind an occluder). On a tie (a far car's few points fit in both boxes) the
    candidate wins: it is centred on them. With ``hold_ties`` (``reacquire.supported_holds_ties`` while the frame's
    estimate has support: ``min_points`` object points, not continued on the prior) the box also stays when the
    candidate would hold no more points than it, both counted in the box scaled by ``crop_scale`` (the points on
    its faces count, which a box that fits them exactly splits by their noise): the normal step already holds the
    object again, and a candidate centred on the same partial view of it is no better (which end of the object
    the points show is ambiguous for the candidate, not for the registration against the track's shape)."""
    moved = Box(float(centre[0]), float(centre[1]), box.z, box.heading, box.length, box.width, box.height)
    if points_in_box(points, moved, 1.0).sum() < points_in_box(points, box, 1.0).sum():
        return True
    if not hold_ties:
        return False
    return bool(points_in_box(points, moved, crop_scale).sum() <= points_in_box(points, box, crop_scale).sum())
