"""LiDAR-SOT evaluation metrics: exact 3D IoU, Acc, Rob, Shape (Chamfer), Success, Precision.

Definitions (``../shared/docs/paper-notes.md``, "Metrics"; all evaluated over frames 1..n-1 of a
tracklet, i.e. the start frame, whose box is given, is never scored):

- **IoU** ``= I / (V_a + V_b − I)`` with ``I`` the exact intersection volume. Of two level boxes (roll =
  pitch = 0): ``I = A_bev(a ∩ b) · max(0, min(top_a, top_b) − max(bottom_a, bottom_b))``, where ``A_bev``
  is the area of the intersection of the two rotated rectangles in the x–y plane (convex polygon
  intersection, computed exactly) and ``top = z + h/2``, ``bottom = z − h/2``. (The upstream
  implementation's height overlap is wrong when the heights differ; this one is not.) When either box has
  a roll or pitch (boxes given as :class:`Box` or as (N, 9) arrays): ``I`` is the volume of the convex
  hull of the intersection polytope's vertices — the corners of each box inside the other and the
  crossings of each box's edges with the other's faces (every vertex of the intersection of two convex
  polytopes is one of these). The bird's-eye-view IoU uses the heading footprint (roll, pitch ignored).
- **Acc** = Σ_k Σ_j IoU_kj / Σ_k n_k: the mean IoU pooled over all scored frames of all tracklets.
- **Rob**: for t in ``ROB_THRESHOLDS`` = {0, 0.05, …, 1}, ``l_k(t)`` = the number of scored frames
  *before* the first scored frame of tracklet k whose IoU < t (``n_k`` if there is none);
  ``Rob(t) = Σ_k l_k(t) / Σ_k n_k``; ``Rob = trapz(Rob(t), t)`` (trapezoid rule on the 21 thresholds,
  so Rob ∈ [0, 1]). Note: upstream's ``track_len_ratio`` counts the failing frame itself
  (``l = i + 1``); the notes (authoritative here) do not.
- **Shape** (Chamfer distance, metres): both shapes are voxelised at 5 cm (one point per occupied voxel,
  at the voxel centre, grid anchored at the object-frame origin), then
  ``CD = (Σ_{a∈M} min_b ‖a−b‖ + Σ_{b∈M̃} min_a ‖a−b‖) / (|M| + |M̃|)`` (Euclidean, not squared; this is
  the notes' and upstream's ``compute_cd_loss``; the paper's Eq. 3 instead averages each direction
  separately — available as ``symmetric_mean=True``). Shape = mean CD over tracklets.
- **Success** (3D-SOT literature) = ``100 · trapz(S(t), t) / 1`` with ``S(t)`` = fraction of pooled
  scored frames with IoU **>** t, t in ``SUCCESS_THRESHOLDS`` = linspace(0, 1, 21).
- **Precision** = ``100 · trapz(P(d), d) / 2`` with ``P(d)`` = fraction of pooled scored frames whose
  centre error (3D Euclidean distance between box centres, metres) is **<** d, d in
  ``PRECISION_THRESHOLDS`` = linspace(0, 2, 21). Both are in [0, 100].
- **Difficulty**: mean number of sweep points inside the ground-truth box over the tracklet's first 10
  frames (start frame included, points not ground-removed): ``hard`` if < 38.2, ``medium`` if
  38.2 ≤ m < 808.3, ``easy`` if ≥ 808.3 (the paper: more points = easier; thresholds split LiDAR-SOT's
  Waymo test set into equal-count thirds).

Everything here is vectorised numpy; nearest neighbours for the Chamfer distance use scipy's cKDTree.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass, field
from typing import Iterable, Sequence

import numpy as np
from scipy.spatial import ConvexHull, QhullError, cKDTree

from .geometry import Box, rotation_zyx
from .rows import finite3

__all__ = [
    "unique_sorted",
    "ROB_THRESHOLDS",
    "SUCCESS_THRESHOLDS",
    "PRECISION_THRESHOLDS",
    "DIFFICULTY_THRESHOLDS",
    "DIFFICULTIES",
    "bev_corners_batch",
    "bev_intersection_area_batch",
    "iou_3d_batch",
    "iou_3d",
    "iou_bev_batch",
    "centre_errors_batch",
    "accuracy",
    "robustness_curve",
    "robustness",
    "success_curve",
    "success",
    "precision_curve",
    "precision",
    "voxel_downsample_centres",
    "voxel_downsample_means",
    "chamfer_distance",
    "difficulty",
    "TrackletScores",
    "TrackletMetrics",
    "PooledMetrics",
    "score_tracklet",
    "tracklet_metrics",
    "pool_metrics",
]

ROB_THRESHOLDS: np.ndarray = np.linspace(0.0, 1.0, 21)
SUCCESS_THRESHOLDS: np.ndarray = np.linspace(0.0, 1.0, 21)
PRECISION_THRESHOLDS: np.ndarray = np.linspace(0.0, 2.0, 21)
DIFFICULTY_THRESHOLDS: tuple[float, float] = (38.2, 808.3)
DIFFICULTIES: tuple[str, str, str] = ("easy", "medium", "hard")

_EPS = 1e-9


def _trapz(y: np.ndarray, x: np.ndarray) -> float:
    """Trapezoid rule along the last axis (numpy 1.x/2.x compatible)."""
    y = np.asarray(y, dtype=np.float64)
    x = np.asarray(x, dtype=np.float64)
    return float(np.sum((y[..., 1:] + y[..., :-1]) * np.diff(x) / 2.0, axis=-1))


# ---------------------------------------------------------------------------------------------------
# IoU
# ---------------------------------------------------------------------------------------------------

def _box_row(box: Box) -> np.ndarray:
    return np.array([box.x, box.y, box.z, box.heading, box.length, box.width, box.height, box.roll, box.pitch],
                    dtype=np.float64)


def _as_boxes(boxes: np.ndarray | Sequence[Box] | Box) -> np.ndarray:
    """(N, 9) [x, y, z, heading, length, width, height, roll, pitch] of Boxes or of (N, 7) / (N, 9) arrays
    (7 columns: level boxes)."""
    if isinstance(boxes, Box):
        return _box_row(boxes)[None]
    if isinstance(boxes, np.ndarray):
        arr = boxes.astype(np.float64, copy=False)
    else:
        items = list(boxes)
        arr = (np.array([_box_row(b) for b in items], dtype=np.float64) if items and isinstance(items[0], Box)
               else np.asarray(items, dtype=np.float64))
    columns = arr.shape[-1] if arr.ndim > 1 else arr.size
    if arr.size == 0:
        return np.zeros((0, 9))
    if columns not in (7, 9):
        raise ValueError(f"boxes need 7 or 9 values each, not {columns}")
    arr = arr.reshape(-1, columns)
    return arr if columns == 9 else np.concatenate([arr, np.zeros((len(arr), 2))], axis=1)


def bev_corners_batch(boxes: np.ndarray) -> np.ndarray:
    """(N, 4, 2) bird's-eye-view corners of (N, 7) boxes [x, y, z, heading, l, w, h], counter-clockwise."""
    boxes = _as_boxes(boxes)
    c, s = np.cos(boxes[:, 3]), np.sin(boxes[:, 3])
    hl, hw = boxes[:, 4] / 2.0, boxes[:, 5] / 2.0
    local = np.stack([np.stack([hl, hw], -1), np.stack([-hl, hw], -1),
                      np.stack([-hl, -hw], -1), np.stack([hl, -hw], -1)], axis=1)  # (N, 4, 2)
    rot = np.stack([np.stack([c, -s], -1), np.stack([s, c], -1)], axis=1)  # (N, 2, 2)
    return np.einsum("nij,nkj->nki", rot, local) + boxes[:, None, :2]


def _inside_convex(points: np.ndarray, poly: np.ndarray) -> np.ndarray:
    """(N, P) mask: points (N, P, 2) inside (or on) the CCW convex polygons (N, V, 2)."""
    edge_start = poly
    edge_vec = np.roll(poly, -1, axis=1) - poly  # (N, V, 2)
    rel = points[:, :, None, :] - edge_start[:, None, :, :]  # (N, P, V, 2)
    cross = edge_vec[:, None, :, 0] * rel[..., 1] - edge_vec[:, None, :, 1] * rel[..., 0]
    scale = np.max(np.abs(edge_vec), axis=(1, 2))[:, None, None] + 1.0
    return np.all(cross >= -_EPS * scale * scale, axis=2)


def _edge_intersections(poly_a: np.ndarray, poly_b: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """All edge–edge intersection points of two quadrilaterals: (N, 16, 2) points and (N, 16) validity."""
    a0 = poly_a[:, :, None, :]
    da = (np.roll(poly_a, -1, axis=1) - poly_a)[:, :, None, :]
    b0 = poly_b[:, None, :, :]
    db = (np.roll(poly_b, -1, axis=1) - poly_b)[:, None, :, :]
    denom = da[..., 0] * db[..., 1] - da[..., 1] * db[..., 0]  # (N, 4, 4)
    diff = b0 - a0
    parallel = np.abs(denom) < 1e-12
    safe = np.where(parallel, 1.0, denom)
    ta = (diff[..., 0] * db[..., 1] - diff[..., 1] * db[..., 0]) / safe
    tb = (diff[..., 0] * da[..., 1] - diff[..., 1] * da[..., 0]) / safe
    valid = ~parallel & (ta >= -_EPS) & (ta <= 1 + _EPS) & (tb >= -_EPS) & (tb <= 1 + _EPS)
    points = a0 + ta[..., None] * da  # (N, 4, 4, 2)
    n = poly_a.shape[0]
    return points.reshape(n, 16, 2), valid.reshape(n, 16)


def bev_intersection_area_batch(corners_a: np.ndarray, corners_b: np.ndarray) -> np.ndarray:
    """Exact intersection areas of pairs of convex CCW quadrilaterals (N, 4, 2) -> (N,).

    The intersection of two convex polygons is the convex polygon whose vertices are among: vertices of
    A inside B, vertices of B inside A, and edge–edge crossings. Those candidates all lie on the
    intersection's boundary, so sorting the valid ones by angle about their mean and applying the
    shoelace formula gives the area. Invalid candidates are replaced by the first sorted valid point,
    which adds only zero-area (degenerate) shoelace terms; duplicates likewise add nothing.
    """
    corners_a = np.asarray(corners_a, dtype=np.float64)
    corners_b = np.asarray(corners_b, dtype=np.float64)
    n = corners_a.shape[0]
    if n == 0:
        return np.zeros(0)
    cross_pts, cross_ok = _edge_intersections(corners_a, corners_b)
    a_in_b = _inside_convex(corners_a, corners_b)
    b_in_a = _inside_convex(corners_b, corners_a)
    pts = np.concatenate([corners_a, corners_b, cross_pts], axis=1)  # (N, 24, 2)
    ok = np.concatenate([a_in_b, b_in_a, cross_ok], axis=1)  # (N, 24)
    count = ok.sum(axis=1)
    centre = np.where(count[:, None] > 0,
                      (pts * ok[..., None]).sum(axis=1) / np.maximum(count, 1)[:, None], 0.0)
    rel = pts - centre[:, None, :]
    angle = np.where(ok, np.arctan2(rel[..., 1], rel[..., 0]), np.inf)
    order = np.argsort(angle, axis=1, kind="stable")
    rel_sorted = np.take_along_axis(rel, order[..., None], axis=1)
    ok_sorted = np.take_along_axis(ok, order, axis=1)
    rel_sorted = np.where(ok_sorted[..., None], rel_sorted, rel_sorted[:, :1, :])
    nxt = np.roll(rel_sorted, -1, axis=1)
    area = 0.5 * np.sum(rel_sorted[..., 0] * nxt[..., 1] - rel_sorted[..., 1] * nxt[..., 0], axis=1)
    return np.where(count >= 3, np.abs(area), 0.0)


def iou_bev_batch(boxes_a: np.ndarray, boxes_b: np.ndarray) -> np.ndarray:
    """Bird's-eye-view IoU of paired (N, 7) boxes -> (N,)."""
    a, b = _as_boxes(boxes_a), _as_boxes(boxes_b)
    inter = bev_intersection_area_batch(bev_corners_batch(a), bev_corners_batch(b))
    union = a[:, 4] * a[:, 5] + b[:, 4] * b[:, 5] - inter
    return np.where(union > 0, inter / np.where(union > 0, union, 1.0), 0.0)


_CORNER_SIGNS = np.array([[sx, sy, sz] for sx in (1, -1) for sy in (1, -1) for sz in (1, -1)], dtype=np.float64)
_EDGES = np.array([(i, j) for i in range(8) for j in range(i + 1, 8)   # corner pairs differing in one sign
                   if np.sum(_CORNER_SIGNS[i] != _CORNER_SIGNS[j]) == 1])


def _inside_boxes(points: np.ndarray, centres: np.ndarray, rotations: np.ndarray, halves: np.ndarray,
                  tolerance: np.ndarray) -> np.ndarray:
    """(N, K) mask: points (N, K, 3) inside box n (within ``tolerance[n]``)."""
    local = np.einsum("nkj,nji->nki", points - centres[:, None], rotations)   # R^T d
    return np.all(np.abs(local) <= halves[:, None] + tolerance[:, None, None], axis=2)


def _edge_face_crossings(corners: np.ndarray, centres: np.ndarray, rotations: np.ndarray, halves: np.ndarray
                         ) -> tuple[np.ndarray, np.ndarray]:
    """Crossings of the 12 edges of boxes (``corners`` (N, 8, 3)) with the 6 face planes of the other boxes:
    (N, 72, 3) points and (N, 72) mask of the crossings within their edge."""
    p0, p1 = corners[:, _EDGES[:, 0]], corners[:, _EDGES[:, 1]]                   # (N, 12, 3)
    normals = np.concatenate([rotations, -rotations], axis=2).transpose(0, 2, 1)  # (N, 6, 3): the +-axes
    offsets = np.einsum("nfj,nj->nf", normals, centres) + np.concatenate([halves, halves], axis=1)
    start = np.einsum("nej,nfj->nef", p0, normals)                                # (N, 12, 6)
    rate = np.einsum("nej,nfj->nef", p1 - p0, normals)
    parallel = np.abs(rate) < 1e-12
    t = (offsets[:, None, :] - start) / np.where(parallel, 1.0, rate)
    ok = ~parallel & (t >= -_EPS) & (t <= 1.0 + _EPS)
    points = p0[:, :, None] + np.clip(t, 0.0, 1.0)[..., None] * (p1 - p0)[:, :, None]
    return points.reshape(len(corners), 72, 3), ok.reshape(len(corners), 72)


def _polytope_intersection_volume(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Exact intersection volumes of paired (N, 9) boxes of any orientation: the convex hull of the
    intersection's vertex candidates (corners inside the other box, edge-face crossings inside both)."""
    n = len(a)
    rot_a, rot_b = rotation_zyx(a[:, 3], a[:, 8], a[:, 7]), rotation_zyx(b[:, 3], b[:, 8], b[:, 7])
    half_a, half_b = a[:, 4:7] / 2.0, b[:, 4:7] / 2.0
    corners_a = a[:, None, :3] + np.einsum("nij,nkj->nki", rot_a, _CORNER_SIGNS[None] * half_a[:, None])
    corners_b = b[:, None, :3] + np.einsum("nij,nkj->nki", rot_b, _CORNER_SIGNS[None] * half_b[:, None])
    ab, ab_ok = _edge_face_crossings(corners_a, b[:, :3], rot_b, half_b)
    ba, ba_ok = _edge_face_crossings(corners_b, a[:, :3], rot_a, half_a)
    points = np.concatenate([corners_a, corners_b, ab, ba], axis=1)               # (N, 160, 3)
    tolerance = 1e-9 * (1.0 + np.maximum(np.abs(a[:, :7]).max(axis=1), np.abs(b[:, :7]).max(axis=1)))
    ok = (np.concatenate([np.ones((n, 16), dtype=bool), ab_ok, ba_ok], axis=1)
          & _inside_boxes(points, a[:, :3], rot_a, half_a, tolerance)
          & _inside_boxes(points, b[:, :3], rot_b, half_b, tolerance))
    volumes = np.zeros(n)
    for i in np.flatnonzero(ok.sum(axis=1) >= 4):   # one small hull per overlapping pair
        try:
            volumes[i] = ConvexHull(points[i, ok[i]]).volume
        except QhullError:   # the candidates are flat (boxes touching): no volume
            volumes[i] = 0.0
    return volumes


def iou_3d_batch(boxes_a: np.ndarray | Sequence[Box], boxes_b: np.ndarray | Sequence[Box]) -> np.ndarray:
    """Exact 3D IoU of paired boxes -> (N,) in [0, 1]: :class:`Box` sequences, or arrays (N, 7)
    [x, y, z, heading, l, w, h] (level) or (N, 9) [..., roll, pitch].

    Level pairs: ``IoU = A_bev(a ∩ b) · max(0, min(top) − max(bottom)) / (V_a + V_b − that)`` (true
    vertical overlap, so boxes of unequal heights are handled correctly). Pairs with a tilted box: the
    intersection polytope's volume (see the module docstring).
    """
    a, b = _as_boxes(boxes_a), _as_boxes(boxes_b)
    if a.shape != b.shape:
        raise ValueError(f"iou_3d_batch: shapes differ: {a.shape} vs {b.shape}")
    if a.shape[0] == 0:
        return np.zeros(0)
    tilted = np.any(a[:, 7:9] != 0.0, axis=1) | np.any(b[:, 7:9] != 0.0, axis=1)
    # Pairs whose circumscribed circles (spheres, when tilted) do not meet cannot overlap: no polygon work.
    reach = np.hypot(a[:, 4], a[:, 5]) / 2.0 + np.hypot(b[:, 4], b[:, 5]) / 2.0
    near = np.hypot(a[:, 0] - b[:, 0], a[:, 1] - b[:, 1]) <= reach + 1e-9
    overlap_h = np.clip(np.minimum(a[:, 2] + a[:, 6] / 2, b[:, 2] + b[:, 6] / 2)
                        - np.maximum(a[:, 2] - a[:, 6] / 2, b[:, 2] - b[:, 6] / 2), 0.0, None)
    todo = near & (overlap_h > 0) & ~tilted
    inter = np.zeros(a.shape[0])
    if np.any(todo):
        area = bev_intersection_area_batch(bev_corners_batch(a[todo]), bev_corners_batch(b[todo]))
        inter[todo] = area * overlap_h[todo]
    sphere = np.linalg.norm(a[:, 4:7], axis=1) / 2.0 + np.linalg.norm(b[:, 4:7], axis=1) / 2.0
    todo = tilted & (np.linalg.norm(a[:, :3] - b[:, :3], axis=1) <= sphere + 1e-9)
    if np.any(todo):
        inter[todo] = _polytope_intersection_volume(a[todo], b[todo])
    union = np.prod(a[:, 4:7], axis=1) + np.prod(b[:, 4:7], axis=1) - inter
    iou = np.where(union > 0, inter / np.where(union > 0, union, 1.0), 0.0)
    return np.clip(iou, 0.0, 1.0)


def iou_3d(box_a: Box, box_b: Box) -> float:
    """Exact 3D IoU of two boxes, with their roll and pitch (see :func:`iou_3d_batch`)."""
    return float(iou_3d_batch([box_a], [box_b])[0])


def centre_errors_batch(boxes_a: np.ndarray | Sequence[Box], boxes_b: np.ndarray | Sequence[Box]) -> np.ndarray:
    """3D Euclidean distance between the centres of paired boxes (metres), (N,)."""
    a, b = _as_boxes(boxes_a), _as_boxes(boxes_b)
    return np.linalg.norm(a[:, :3] - b[:, :3], axis=1)


# ---------------------------------------------------------------------------------------------------
# State metrics
# ---------------------------------------------------------------------------------------------------

def _concat(per_track: Iterable[np.ndarray]) -> np.ndarray:
    arrays = [np.asarray(v, dtype=np.float64).reshape(-1) for v in per_track]
    return np.concatenate(arrays) if arrays else np.zeros(0)


def accuracy(ious_per_track: Iterable[np.ndarray]) -> float:
    """Acc = mean IoU pooled over all scored frames of all tracklets (NaN if there are none)."""
    pooled = _concat(ious_per_track)
    return float(pooled.mean()) if pooled.size else float("nan")


def _tracking_lengths(ious: np.ndarray, thresholds: np.ndarray) -> np.ndarray:
    """l(t) for one tracklet: frames before the first frame with IoU < t (all if none), (T,)."""
    ious = np.asarray(ious, dtype=np.float64).reshape(-1)
    fails = ious[None, :] < thresholds[:, None]  # (T, n)
    first = np.argmax(fails, axis=1)
    return np.where(fails.any(axis=1), first, ious.size)


def robustness_curve(ious_per_track: Iterable[np.ndarray],
                     thresholds: np.ndarray = ROB_THRESHOLDS) -> np.ndarray:
    """Rob(t) = Σ_k l_k(t) / Σ_k n_k for each threshold t (see module docstring)."""
    thresholds = np.asarray(thresholds, dtype=np.float64)
    tracks = [np.asarray(v, dtype=np.float64).reshape(-1) for v in ious_per_track]
    total = sum(t.size for t in tracks)
    if total == 0:
        return np.full(thresholds.shape, np.nan)
    lengths = sum(_tracking_lengths(t, thresholds) for t in tracks)
    return np.asarray(lengths, dtype=np.float64) / total


def robustness(ious_per_track: Iterable[np.ndarray], thresholds: np.ndarray = ROB_THRESHOLDS) -> float:
    """Rob = trapezoid area under Rob(t) over the thresholds (0, 0.05, …, 1), in [0, 1]."""
    thresholds = np.asarray(thresholds, dtype=np.float64)
    return _trapz(robustness_curve(ious_per_track, thresholds), thresholds)


def success_curve(ious: np.ndarray, thresholds: np.ndarray = SUCCESS_THRESHOLDS) -> np.ndarray:
    """S(t) = fraction of frames with IoU > t (strict), per threshold."""
    ious = np.asarray(ious, dtype=np.float64).reshape(-1)
    if ious.size == 0:
        return np.full(np.shape(thresholds), np.nan)
    return np.mean(ious[None, :] > np.asarray(thresholds)[:, None], axis=1)


def success(ious: np.ndarray, thresholds: np.ndarray = SUCCESS_THRESHOLDS) -> float:
    """Success = 100 · trapz(S(t), t) / (t_max − t_min) with t = linspace(0, 1, 21): in [0, 100]."""
    thresholds = np.asarray(thresholds, dtype=np.float64)
    return 100.0 * _trapz(success_curve(ious, thresholds), thresholds) / float(thresholds[-1] - thresholds[0])


def precision_curve(centre_errors: np.ndarray, thresholds: np.ndarray = PRECISION_THRESHOLDS) -> np.ndarray:
    """P(d) = fraction of frames with centre error < d (strict, metres), per threshold."""
    errors = np.asarray(centre_errors, dtype=np.float64).reshape(-1)
    if errors.size == 0:
        return np.full(np.shape(thresholds), np.nan)
    return np.mean(errors[None, :] < np.asarray(thresholds)[:, None], axis=1)


def precision(centre_errors: np.ndarray, thresholds: np.ndarray = PRECISION_THRESHOLDS) -> float:
    """Precision = 100 · trapz(P(d), d) / (d_max − d_min) with d = linspace(0, 2, 21) m: in [0, 100]."""
    thresholds = np.asarray(thresholds, dtype=np.float64)
    return 100.0 * _trapz(precision_curve(centre_errors, thresholds), thresholds) / float(thresholds[-1] - thresholds[0])


# ---------------------------------------------------------------------------------------------------
# Shape
# ---------------------------------------------------------------------------------------------------

def unique_sorted(values: np.ndarray) -> np.ndarray:
    """The distinct values of a 1-D integer array in ascending order: what ``np.unique(values)`` returns, by a sort
    and a comparison of neighbours (numpy 2's hash-based ``unique`` is several times slower on int64 codes)."""
    values = np.sort(values)
    if len(values) < 2:
        return values
    keep = np.empty(len(values), dtype=bool)
    keep[0] = True
    np.not_equal(values[1:], values[:-1], out=keep[1:])
    return values[keep]


def voxel_downsample_centres(points: np.ndarray, voxel: float = 0.05) -> np.ndarray:
    """One point per occupied voxel, at the voxel's centre (grid anchored at the origin), sorted."""
    points = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    points = points[finite3(points)]
    if points.shape[0] == 0:
        return np.zeros((0, 3))
    keys = np.floor(points / voxel).astype(np.int64)
    coded = _voxel_codes(keys)
    if coded is not None:
        codes, low, span = coded
        codes = unique_sorted(codes)
        keys = np.stack([codes // (span[1] * span[2]), (codes // span[2]) % span[1], codes % span[2]], axis=1) + low
    else:
        keys = np.unique(keys, axis=0)
    return (keys.astype(np.float64) + 0.5) * voxel


def _voxel_codes(keys: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray] | None:
    """One int64 code per row of integer voxel keys (x-major, so sorting the codes sorts the rows
    lexicographically: a 1D unique is fast), with the keys' minimum and span; None when the span overflows."""
    low = keys.min(axis=0)
    span = keys.max(axis=0) - low + 1
    if np.prod(span.astype(np.float64)) >= 2.0**62:
        return None
    rel = keys - low
    return (rel[:, 0] * span[1] + rel[:, 1]) * span[2] + rel[:, 2], low, span


def voxel_downsample_means(points: np.ndarray, voxel: float) -> np.ndarray:
    """One point per occupied voxel of size ``voxel`` (the mean of the points in it), in a deterministic order
    (voxels sorted); ``voxel`` <= 0: the points as given."""
    points = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    if len(points) == 0 or voxel <= 0:
        return points
    keys = np.floor(points / voxel).astype(np.int64)
    coded = _voxel_codes(keys)
    if coded is None:
        _, inverse, counts = np.unique(keys, axis=0, return_inverse=True, return_counts=True)
    else:  # the same voxel order; per-column bincount sums in the points' order, as np.add.at does
        _, inverse, counts = np.unique(coded[0], return_inverse=True, return_counts=True)
    inverse = inverse.reshape(-1)
    sums = np.stack([np.bincount(inverse, weights=points[:, c], minlength=len(counts)) for c in range(3)], axis=1)
    return sums / counts[:, None]


def chamfer_distance(shape: np.ndarray, reference: np.ndarray, voxel: float | None = 0.05,
                     symmetric_mean: bool = False) -> float:
    """Chamfer distance (metres) between two object-frame point sets.

    Both are first voxelised at ``voxel`` (voxel centres; ``None`` = use the points as given). Default:
    ``(Σ_{a∈M} min_b ‖a−b‖ + Σ_{b∈M̃} min_a ‖a−b‖) / (|M| + |M̃|)``; with ``symmetric_mean`` the paper's
    Eq. 3, ``mean_a min_b ‖a−b‖ + mean_b min_a ‖a−b‖``. NaN if either set is empty.
    """
    a = voxel_downsample_centres(shape, voxel) if voxel else np.asarray(shape, dtype=np.float64).reshape(-1, 3)
    b = voxel_downsample_centres(reference, voxel) if voxel else np.asarray(reference, dtype=np.float64).reshape(-1, 3)
    if a.shape[0] == 0 or b.shape[0] == 0:
        return float("nan")
    d_ab, _ = cKDTree(b).query(a, k=1)
    d_ba, _ = cKDTree(a).query(b, k=1)
    if symmetric_mean:
        return float(d_ab.mean() + d_ba.mean())
    return float((d_ab.sum() + d_ba.sum()) / (a.shape[0] + b.shape[0]))


def difficulty(mean_points_first10: float, thresholds: tuple[float, float] = DIFFICULTY_THRESHOLDS) -> str:
    """'hard' if m < 38.2, 'medium' if 38.2 ≤ m < 808.3, else 'easy' (mean GT-box points, first 10 frames)."""
    low, high = thresholds
    if mean_points_first10 < low:
        return "hard"
    if mean_points_first10 < high:
        return "medium"
    return "easy"


# ---------------------------------------------------------------------------------------------------
# Records
# ---------------------------------------------------------------------------------------------------

@dataclass(frozen=True)
class TrackletScores:
    """Per-frame scores of one tracklet over its scored frames (1..n-1).

    ``ious`` and ``centre_errors`` are (n-1,) arrays; ``shape_cd`` the Chamfer distance of its final
    shape (NaN if not evaluated); ``mean_points_first10`` drives the difficulty.
    """

    track_id: str
    ious: np.ndarray
    centre_errors: np.ndarray
    shape_cd: float = float("nan")
    mean_points_first10: float = float("nan")

    @property
    def n_frames(self) -> int:
        return int(np.asarray(self.ious).size)

    @property
    def difficulty(self) -> str:
        return difficulty(self.mean_points_first10) if np.isfinite(self.mean_points_first10) else "unknown"


def _nan_to_none(value: float) -> float | None:
    return None if value is None or not np.isfinite(value) else float(value)


@dataclass(frozen=True)
class TrackletMetrics:
    """Metrics of one tracklet (Acc, Rob in [0, 1]; Success, Precision in [0, 100]; metres)."""

    track_id: str
    difficulty: str
    n_frames: int
    acc: float
    rob: float
    shape: float
    success: float
    precision: float
    centre_error: float
    mean_points_first10: float

    def to_dict(self) -> dict:
        return {k: (_nan_to_none(v) if isinstance(v, float) else v) for k, v in asdict(self).items()}


@dataclass(frozen=True)
class PooledMetrics:
    """Metrics pooled over tracklets: Acc, Rob, Success, Precision and centre error pool frames
    (length-weighted); Shape is the mean CD over tracklets with a finite CD."""

    n_tracklets: int
    n_frames: int
    acc: float
    rob: float
    shape: float
    success: float
    precision: float
    centre_error: float
    track_ids: tuple[str, ...] = field(default_factory=tuple)

    def to_dict(self) -> dict:
        out = {k: (_nan_to_none(v) if isinstance(v, float) else v) for k, v in asdict(self).items()}
        out["track_ids"] = list(self.track_ids)
        return out


def score_tracklet(track_id: str, predicted: np.ndarray | Sequence[Box], ground_truth: np.ndarray | Sequence[Box],
                   shape: np.ndarray | None = None, reference_shape: np.ndarray | None = None,
                   mean_points_first10: float = float("nan"), skip_first: bool = True) -> TrackletScores:
    """Per-frame IoUs and centre errors of a tracklet; frame 0 (the given start box) is dropped when
    ``skip_first``. The Chamfer distance is computed when both shapes are given."""
    pred, gt = _as_boxes(predicted), _as_boxes(ground_truth)
    if pred.shape != gt.shape:
        raise ValueError(f"{track_id}: {pred.shape[0]} predicted boxes but {gt.shape[0]} ground-truth boxes")
    if skip_first:
        pred, gt = pred[1:], gt[1:]
    cd = chamfer_distance(shape, reference_shape) if shape is not None and reference_shape is not None else float("nan")
    return TrackletScores(track_id, iou_3d_batch(pred, gt), centre_errors_batch(pred, gt), cd,
                          float(mean_points_first10))


def tracklet_metrics(scores: TrackletScores) -> TrackletMetrics:
    """All metrics of one tracklet."""
    pooled = pool_metrics([scores])
    return TrackletMetrics(scores.track_id, scores.difficulty, scores.n_frames, pooled.acc, pooled.rob,
                           float(scores.shape_cd), pooled.success, pooled.precision, pooled.centre_error,
                           float(scores.mean_points_first10))


def pool_metrics(tracklets: Sequence[TrackletScores]) -> PooledMetrics:
    """Pooled metrics over tracklets (see :class:`PooledMetrics`); NaN fields when there are no frames."""
    ious = [t.ious for t in tracklets]
    errors = _concat(t.centre_errors for t in tracklets)
    all_ious = _concat(ious)
    cds = np.array([t.shape_cd for t in tracklets], dtype=np.float64)
    cds = cds[np.isfinite(cds)]
    return PooledMetrics(
        n_tracklets=len(tracklets),
        n_frames=int(all_ious.size),
        acc=accuracy(ious),
        rob=robustness(ious) if all_ious.size else float("nan"),
        shape=float(cds.mean()) if cds.size else float("nan"),
        success=success(all_ious) if all_ious.size else float("nan"),
        precision=precision(errors) if errors.size else float("nan"),
        centre_error=float(errors.mean()) if errors.size else float("nan"),
        track_ids=tuple(t.track_id for t in tracklets),
    )
