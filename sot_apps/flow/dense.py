"""Dense flow of one pair: raycast image k against all object meshes, move the hits, project into k+1.

1. Every object's mesh is placed at its state at camera k's time, in camera k's frame, and all go
   into ONE embree scene (geometry id = object index): the first hit per pixel gives the instance,
   its depth and inter-object occlusion. Only pixels inside the objects' projected bounding boxes
   are cast.
2. Pixels whose hit lies behind the frame's LiDAR occluders are dropped (the object is not the
   nearest surface there).
3. Each hit keeps its object-frame coordinates and moves with the object to camera k+1's time;
   it is projected through camera k+1 (ego/camera motion and lens distortion): flow = uv1 - uv0.
4. ``valid_noc`` additionally needs the moved point to be the nearest surface in image k+1: a ray
   from camera k+1 towards it must first hit the same object at the same depth (objects placed at
   k+1), no LiDAR occluder of k+1 may be in front, and it must land inside the image.
"""

from __future__ import annotations

import cv2
import numpy as np

from .camera import CameraModel, apply_transform, grid_pixels, pixel_rays, project
from .occlusion import depth_map, lookup_depth
from .raycast import MultiMeshScene
from .scene import FlowObject, ObjectPairStats, PairFlow, PairSetup, flow_magnitude, image_roi, project_vertices

__all__ = ["dense_flow", "RayCache"]


class RayCache:
    """Pixel rays of a camera, set up once per camera model: with lens distortion a map of the whole image
    (undistortion is the slow part); without, the x of each column and the y of each row (a pinhole ray is
    ``((u - cx) / fx, (v - cy) / fy, 1)`` when the skew ``K[0, 1]`` is 0: the same values as :func:`pixel_rays`)."""

    def __init__(self) -> None:
        self._maps: dict[tuple, tuple[np.ndarray, ...]] = {}

    def rays(self, model: CameraModel, pixels: np.ndarray) -> np.ndarray:
        """(M, 3) float64 rays ``(x, y, 1)`` through the integer pixels ``pixels`` (M, 2) (u, v)."""
        if not model.has_distortion and model.K[0, 1] != 0.0:
            return pixel_rays(pixels, model)
        key = (model.K.tobytes(), model.distortion.tobytes(), model.width, model.height)
        if key not in self._maps:
            if model.has_distortion:
                grid = grid_pixels(0, 0, model.width, model.height)
                self._maps[key] = (pixel_rays(grid, model)[:, :2].astype(np.float64).reshape(model.height, model.width, 2),)
            else:
                K = model.K
                self._maps[key] = ((np.arange(model.width, dtype=np.float64) - K[0, 2]) / K[0, 0],
                                   (np.arange(model.height, dtype=np.float64) - K[1, 2]) / K[1, 1])
        maps = self._maps[key]
        out = np.empty((len(pixels), 3))
        if len(maps) == 1:
            out[:, :2] = maps[0][pixels[:, 1], pixels[:, 0]]
        else:
            np.take(maps[0], pixels[:, 0], out=out[:, 0])
            np.take(maps[1], pixels[:, 1], out=out[:, 1])
        out[:, 2] = 1.0
        return out


_DEFAULT_CACHE = RayCache()


def _ray_pixels(footprints: list[tuple[tuple[int, int, int, int], np.ndarray | None]], model: CameraModel) -> np.ndarray:
    """Pixels to cast (unique, (M, 2) u, v): each object's projected silhouette (convex hull of its
    projected vertices, grown by 2 px) or, with lens distortion or vertices behind the camera, its
    bounding box. Work stays inside each object's box, never over the whole image."""
    flat_parts = []
    for (x0, y0, x1, y1), uv in footprints:
        if uv is None or model.has_distortion or np.isnan(uv).any():
            vs, us = np.mgrid[y0:y1, x0:x1]
        else:
            mask = np.zeros((y1 - y0, x1 - x0), dtype=np.uint8)
            hull = cv2.convexHull(np.round((uv - [x0, y0]) * 16).astype(np.int32))
            cv2.fillConvexPoly(mask, hull, 1, lineType=cv2.LINE_8, shift=4)
            mask = cv2.dilate(mask, np.ones((5, 5), np.uint8))
            vs, us = np.nonzero(mask)
            vs, us = vs + y0, us + x0
        flat_parts.append((vs.ravel().astype(np.int64) * model.width + us.ravel()))
    flat = flat_parts[0] if len(flat_parts) == 1 else np.unique(np.concatenate(flat_parts))
    return np.stack([flat % model.width, flat // model.width], axis=1)


def _in_image(uv: np.ndarray, model: CameraModel) -> np.ndarray:
    return ((uv[:, 0] > -0.5) & (uv[:, 0] < model.width - 0.5) & (uv[:, 1] > -0.5) & (uv[:, 1] < model.height - 0.5))


def visible_in_k1(setup: PairSetup, objects: list[FlowObject], obj: FlowObject, points_k1: np.ndarray,
                  uv1: np.ndarray, scene_k1: MultiMeshScene | None, order_k1: list[int]) -> np.ndarray:
    """Mask of points (camera k+1 frame) of ``obj`` that are the nearest surface in image k+1."""
    model, params = setup.model, setup.params
    z1 = points_k1[:, 2]
    # a NaN coordinate (behind the camera) compares False: not in the image
    shown = np.flatnonzero((z1 > 0.05) & _in_image(uv1, model))   # the points still visible, narrowed below
    if scene_k1 is not None and len(shown):
        points, z = (points_k1, z1) if len(shown) == len(z1) else (points_k1[shown], z1[shown])
        geom, t = scene_k1.first_hit(np.zeros(3), points / z[:, None])
        # Same object, and the hit is (within tolerance) the point itself, not a nearer part of it.
        same = (geom == order_k1.index(obj.index)) & (t >= z - params.margin(z))
        if not same.all():
            shown = shown[same]
    if setup.lidar_k1 is not None and len(shown):
        uv, z = uv1[shown], z1[shown]
        roi = image_roi(uv, model, margin=params.dilate_px)
        if roi is not None:
            bottom = obj.bottom_z(obj.world_from_object_k1) + params.ground_clearance
            dm = depth_map(setup.lidar_k1, roi, params.dilate_px, min_world_z=bottom)
            hidden = lookup_depth(dm, roi, uv) < z - params.margin(z)
            if hidden.any():
                shown = shown[~hidden]
    ok = np.zeros(len(z1), dtype=bool)
    ok[shown] = True
    return ok


def scene_at_k1(setup: PairSetup, objects: list[FlowObject]) -> tuple[MultiMeshScene | None, list[int]]:
    """Objects known at k+1, placed in camera k+1's frame; returns the scene and object index per geometry."""
    placed = [o for o in objects if o.world_from_object_k1 is not None]
    if not placed:
        return None, []
    cam = setup.camera_k1_from_world
    return MultiMeshScene([o.mesh.transformed(cam @ o.world_from_object_k1) for o in placed]), [o.index for o in placed]


def dense_flow(setup: PairSetup, objects: list[FlowObject], ray_cache: RayCache | None = None) -> PairFlow:
    """Flow, validity (occ/noc) and instance mask of one pair for ``objects`` (see module doc)."""
    model, params = setup.model, setup.params
    cache = ray_cache or _DEFAULT_CACHE
    out = PairFlow.empty(model.width, model.height)
    cam_k = setup.camera_k_from_world
    placed = [o.mesh.transformed(cam_k @ o.world_from_object_k) for o in objects]
    rois, footprints = {}, []
    for obj, mesh in zip(objects, placed, strict=True):
        uv = project_vertices(mesh, np.eye(4), model)
        roi = image_roi(uv, model)
        if roi is not None:
            rois[obj.index] = roi
            footprints.append((roi, uv))
    if not rois:
        return out
    pixels = _ray_pixels(footprints, model)
    rays = cache.rays(model, pixels)
    scene_k = MultiMeshScene(placed)
    geom, t = scene_k.first_hit(np.zeros(3), rays)
    scene_k1, order_k1 = scene_at_k1(setup, objects)
    hit = np.flatnonzero(geom >= 0)
    pixels, rays, geom, t = pixels[hit], rays[hit], geom[hit], t[hit]
    width = model.width
    for pos, obj in enumerate(objects):
        if len(objects) == 1:   # every hit is this object's: no selection (a copy of every array) needed
            pix, points_k = pixels, rays * t[:, None]
        else:
            sel = np.flatnonzero(geom == pos)
            pix, points_k = pixels[sel], rays[sel] * t[sel, None]
        z = points_k[:, 2]
        hidden = np.zeros(len(pix), dtype=bool)
        if setup.lidar_k is not None and len(pix):
            roi = rois[obj.index]
            bottom = obj.bottom_z(obj.world_from_object_k) + params.ground_clearance
            dm = depth_map(setup.lidar_k, roi, params.dilate_px, min_world_z=bottom)
            hidden = lookup_depth(dm, roi, pix) < z - params.margin(z)
        if hidden.any():
            shown = np.flatnonzero(~hidden)
            pix, points_k = pix[shown], points_k[shown]
        flat = pix[:, 1] * width + pix[:, 0]             # the pixels' flat indices into the (H, W) maps
        out.instance.reshape(-1)[flat] = obj.index + 1
        stats = ObjectPairStats.fields_before_flow(obj, len(pix), hidden.sum())
        if obj.world_from_object_k1 is not None and len(pix):
            motion = setup.motion(obj)
            points_k1 = apply_transform(motion, points_k)
            uv1, z1 = project(points_k1, model)
            flow = uv1 - pix
            good = np.isfinite(flow).all(axis=1)
            noc = visible_in_k1(setup, objects, obj, points_k1, uv1, scene_k1, order_k1) & good
            mag = flow_magnitude(flow)    # per pixel: the same values as the norm of any selection
            mean_flow_noc = float(mag[noc].mean()) if noc.any() else 0.0
            if not good.all():
                keep = np.flatnonzero(good)
                flow, mag, flat_good = flow[keep], mag[keep], flat[keep]
            else:
                flat_good = flat
            out.flow.reshape(-1, 2)[flat_good] = flow
            out.valid_occ.reshape(-1)[flat_good] = True
            out.valid_noc.reshape(-1)[flat[noc]] = True
            stats.update(pixels_noc=int(np.count_nonzero(noc)), has_flow=True,
                         mean_flow=float(mag.mean()) if len(mag) else 0.0, mean_flow_noc=mean_flow_noc)
        out.objects.append(ObjectPairStats(**stats))
    return out
