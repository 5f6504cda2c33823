"""Sparse flow of one pair: project the objects' shape points with a z-buffer.

All objects' points placed at camera k's time go into one z-buffer (nearest depth per pixel),
densified by a min filter so that points on an object's far side, seen through the gaps between
near-side points, are rejected. A point survives when it is within the depth margin of that
densified buffer and not behind the LiDAR occluders; its flow (exact projection at k+1 minus its
exact projection at k) is stored at its rounded pixel. ``valid_noc`` repeats the test at k+1.
"""

from __future__ import annotations

import cv2
import numpy as np

from .camera import CameraModel, apply_transform, project
from .occlusion import NO_DEPTH, ProjectedPoints, depth_map, lookup_depth
from .scene import FlowObject, ObjectPairStats, PairFlow, PairSetup

__all__ = ["sparse_flow"]


def _zbuffer_visible(uv: np.ndarray, z: np.ndarray, model: CameraModel, dilate_px: int, margin: np.ndarray) -> np.ndarray:
    """Points within ``margin`` of the densified nearest depth at their pixel (and inside the image)."""
    pix = np.rint(np.nan_to_num(uv, nan=-1e6)).astype(np.int64)
    inside = ((pix[:, 0] >= 0) & (pix[:, 0] < model.width) & (pix[:, 1] >= 0) & (pix[:, 1] < model.height) & (z > 0.05))
    visible = np.zeros(len(z), dtype=bool)
    if not inside.any():
        return visible
    idx = np.flatnonzero(inside)
    x0, y0 = pix[idx, 0].min(), pix[idx, 1].min()
    x1, y1 = pix[idx, 0].max() + 1, pix[idx, 1].max() + 1
    buf = np.full((y1 - y0, x1 - x0), NO_DEPTH, dtype=np.float32)
    np.minimum.at(buf.reshape(-1), (pix[idx, 1] - y0) * (x1 - x0) + (pix[idx, 0] - x0), z[idx].astype(np.float32))
    if dilate_px > 1:
        buf = cv2.erode(buf, np.ones((dilate_px, dilate_px), np.uint8), borderType=cv2.BORDER_CONSTANT,
                        borderValue=float(NO_DEPTH))
    nearest = buf[pix[idx, 1] - y0, pix[idx, 0] - x0]
    visible[idx] = z[idx] <= nearest + margin[idx]
    return visible


def _lidar_hidden(lidar: ProjectedPoints | None, uv: np.ndarray, z: np.ndarray, bottom: float, setup: PairSetup) -> np.ndarray:
    params = setup.params
    if lidar is None or len(z) == 0:
        return np.zeros(len(z), dtype=bool)
    finite = np.isfinite(uv).all(axis=1)
    if not finite.any():
        return np.zeros(len(z), dtype=bool)
    lo = np.floor(uv[finite].min(axis=0)).astype(int) - params.dilate_px
    hi = np.ceil(uv[finite].max(axis=0)).astype(int) + params.dilate_px + 1
    roi = (max(lo[0], 0), max(lo[1], 0), min(hi[0], setup.model.width), min(hi[1], setup.model.height))
    dm = depth_map(lidar, roi, params.dilate_px, min_world_z=bottom + params.ground_clearance)
    return lookup_depth(dm, roi, uv) < z - params.margin(z)


def sparse_flow(setup: PairSetup, objects: list[FlowObject]) -> PairFlow:
    """Flow at the pixels of visible shape points (``FlowObject.points``, object frame)."""
    model, params = setup.model, setup.params
    out = PairFlow.empty(model.width, model.height)
    usable = [o for o in objects if o.points is not None and len(o.points)]
    if not usable:
        out.objects = [ObjectPairStats(**ObjectPairStats.fields_before_flow(o)) for o in objects]
        return out

    def place(camera_from_world: np.ndarray, attr: str):
        parts, owners = [], []
        for pos, o in enumerate(usable):
            pose = getattr(o, attr)
            if pose is None:
                continue
            m = camera_from_world @ pose
            parts.append(apply_transform(m, o.points))
            owners.append(np.full(len(o.points), pos))
        if not parts:
            return np.zeros((0, 3)), np.zeros(0, int)
        return np.concatenate(parts), np.concatenate(owners)

    pts_k, owner_k = place(setup.camera_k_from_world, "world_from_object_k")
    uv_k, z_k = project(pts_k, model)
    vis_k = _zbuffer_visible(uv_k, z_k, model, params.dilate_px, params.margin(z_k))
    pts_k1_all, owner_k1 = place(setup.camera_k1_from_world, "world_from_object_k1")
    uv_k1_all, z_k1_all = project(pts_k1_all, model)
    vis_k1_all = _zbuffer_visible(uv_k1_all, z_k1_all, model, params.dilate_px, params.margin(z_k1_all))
    stats_by_index = {}
    for pos, obj in enumerate(usable):
        sel = np.flatnonzero((owner_k == pos) & vis_k)
        uv0, z0, p0 = uv_k[sel], z_k[sel], pts_k[sel]
        hidden = _lidar_hidden(setup.lidar_k, uv0, z0, obj.bottom_z(obj.world_from_object_k), setup)
        uv0, z0, p0 = uv0[~hidden], z0[~hidden], p0[~hidden]
        # Nearest point per pixel wins.
        pix = np.rint(uv0).astype(np.int64)
        order = np.lexsort((z0, pix[:, 0], pix[:, 1]))
        first = np.ones(len(order), bool)
        first[1:] = (np.diff(pix[order, 1]) != 0) | (np.diff(pix[order, 0]) != 0)
        keep = order[first]
        uv0, z0, p0, pix = uv0[keep], z0[keep], p0[keep], pix[keep]
        out.instance[pix[:, 1], pix[:, 0]] = obj.index + 1
        stats = ObjectPairStats.fields_before_flow(obj, len(pix), hidden.sum())
        if obj.world_from_object_k1 is not None and len(pix):
            motion = setup.motion(obj)
            p1 = apply_transform(motion, p0)
            uv1, z1 = project(p1, model)
            flow = uv1 - uv0
            good = np.isfinite(flow).all(axis=1)
            # Visible at k+1: its own moved point passes the k+1 z-buffer of all objects and the LiDAR test.
            own = np.flatnonzero(owner_k1 == pos)
            # The object's points are in the same order at k and k+1: map kept points to their k+1 entries.
            local = sel[~hidden][keep] - np.flatnonzero(owner_k == pos)[0]
            noc = good & vis_k1_all[own[local]]
            noc &= ~_lidar_hidden(setup.lidar_k1, uv1, z1, obj.bottom_z(obj.world_from_object_k1), setup)
            noc &= ((uv1[:, 0] > -0.5) & (uv1[:, 0] < model.width - 0.5) & (uv1[:, 1] > -0.5)
                    & (uv1[:, 1] < model.height - 0.5))
            out.flow[pix[good, 1], pix[good, 0]] = flow[good]
            out.valid_occ[pix[good, 1], pix[good, 0]] = True
            out.valid_noc[pix[noc, 1], pix[noc, 0]] = True
            stats.update(pixels_noc=int(noc.sum()), has_flow=True,
                         mean_flow=float(np.linalg.norm(flow[good], axis=1).mean()) if good.any() else 0.0,
                         mean_flow_noc=float(np.linalg.norm(flow[noc], axis=1).mean()) if noc.any() else 0.0)
        stats_by_index[obj.index] = ObjectPairStats(**stats)
    out.objects = [stats_by_index.get(o.index, ObjectPairStats(**ObjectPairStats.fields_before_flow(o)))
                   for o in objects]
    return out
