"""Dense flow against analytic truth: a planar object with known rigid motion (homography)."""

from __future__ import annotations

import cv2
import numpy as np
from scipy.spatial.transform import Rotation

from sot_apps.flow.camera import CameraModel
from sot_apps.flow.dense import RayCache, dense_flow
from sot_apps.flow.scene import FlowObject, PairSetup
from sot_apps.objects.meshes import Mesh
from sot_apps.objects.trajectory import world_from_object
from tracker.geometry import invert_transform, make_transform, rotation_z

# Camera looking along world +x from 1.5 m height (OpenCV axes: x right, y down, z forward).
CAM_ROT = np.array([[0.0, 0.0, 1.0], [-1.0, 0.0, 0.0], [0.0, -1.0, 0.0]])
K = np.array([[900.0, 0.0, 322.5], [0.0, 905.0, 241.0], [0.0, 0.0, 1.0]])


def plate_mesh() -> Mesh:
    """A 2 x 1.4 m plate in the object's y-z plane at x = +0.5 (two triangles)."""
    v = np.array([[0.5, -1.0, -0.7], [0.5, 1.0, -0.7], [0.5, 1.0, 0.7], [0.5, -1.0, 0.7]])
    return Mesh(v, np.array([[0, 1, 2], [0, 2, 3]], dtype=np.int32))


def scenario(distortion):
    model = CameraModel(K, np.asarray(distortion, float), 640, 480)
    world_from_cam_k = make_transform(CAM_ROT, np.array([0.0, 0.0, 1.5]))
    wiggle = Rotation.from_euler("xyz", [0.01, -0.02, 0.015]).as_matrix()
    world_from_cam_k1 = make_transform(rotation_z(0.02) @ CAM_ROT @ wiggle, np.array([0.6, 0.05, 1.52]))
    obj = FlowObject(0, "plate", plate_mesh(), world_from_object([10.0, 0.4, 1.3, np.pi + 0.25]),
                     world_from_object([9.3, 0.7, 1.33, np.pi + 0.31]))
    return model, PairSetup(model, world_from_cam_k, world_from_cam_k1), obj


def plane_in_camera_k(setup, obj):
    cam_from_obj = invert_transform(setup.world_from_camera_k) @ obj.world_from_object_k
    normal = cam_from_obj[:3, :3] @ np.array([1.0, 0.0, 0.0])
    point = cam_from_obj[:3, :3] @ np.array([0.5, 0.0, 0.0]) + cam_from_obj[:3, 3]
    return normal, float(normal @ point)


def test_planar_flow_matches_homography_without_distortion():
    model, setup, obj = scenario(np.zeros(5))
    result = dense_flow(setup, [obj], RayCache())
    valid = result.valid_occ
    assert valid.sum() > 5000
    normal, d = plane_in_camera_k(setup, obj)
    motion = setup.motion(obj)
    H = K @ (motion[:3, :3] + np.outer(motion[:3, 3], normal) / d) @ np.linalg.inv(K)
    vs, us = np.nonzero(valid)
    p = H @ np.stack([us, vs, np.ones_like(us)]).astype(float)
    expected = (p[:2] / p[2]).T - np.stack([us, vs], axis=1)
    error = np.abs(result.flow[vs, us] - expected).max()
    assert error < 0.05, error
    # The mask is the plate's projected quadrilateral: same pixel count as a direct polygon fill.
    cam_from_obj = invert_transform(setup.world_from_camera_k) @ obj.world_from_object_k
    corners = plate_mesh().vertices @ cam_from_obj[:3, :3].T + cam_from_obj[:3, 3]
    uv = (corners @ K.T)[:, :2] / corners[:, 2:]
    poly = np.zeros((480, 640), np.uint8)
    cv2.fillPoly(poly, [np.round(uv * 256).astype(np.int32)], 1, shift=8)
    assert abs(int(poly.sum()) - int(valid.sum())) < 0.02 * valid.sum()


def test_planar_flow_with_lens_distortion_matches_ray_plane_intersection():
    dist = [-0.28, 0.09, 0.0008, -0.0011, -0.015]
    model, setup, obj = scenario(dist)
    result = dense_flow(setup, [obj], RayCache())
    vs, us = np.nonzero(result.valid_occ)
    assert len(us) > 5000
    normal, d = plane_in_camera_k(setup, obj)
    xy = cv2.undistortPoints(np.stack([us, vs], 1).astype(np.float64).reshape(-1, 1, 2), K, np.array(dist),
                             None, None, None, (cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, 100, 1e-14)).reshape(-1, 2)
    rays = np.concatenate([xy, np.ones((len(xy), 1))], axis=1)
    points = rays * (d / (rays @ normal))[:, None]
    motion = setup.motion(obj)
    uv1, _ = cv2.projectPoints(points, cv2.Rodrigues(motion[:3, :3])[0], motion[:3, 3], K, np.array(dist))
    expected = uv1.reshape(-1, 2) - np.stack([us, vs], 1)
    error = np.abs(result.flow[vs, us] - expected).max()
    assert error < 0.05, error
    # Everything visible in k stays visible in k+1 here (no occluder, stays in the image).
    assert result.valid_noc.sum() > 0.95 * result.valid_occ.sum()
