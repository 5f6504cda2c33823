"""Occlusion (other objects, LiDAR points) and camera-timestamp handling of the dense flow."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from sot_apps.flow.annotate import FlowOptions, build_pair, compute_pair
from sot_apps.flow.camera import CameraModel, project
from sot_apps.flow.dense import RayCache, dense_flow
from sot_apps.flow.objects import MeshedObject
from sot_apps.flow.occlusion import project_lidar
from sot_apps.flow.scene import FlowObject, OcclusionParams, PairSetup
from sot_apps.io.sequence import Camera, CameraFrame, FrameInfo, Sequence, Sweep
from sot_apps.objects.meshes import Mesh
from sot_apps.objects.trajectory import Trajectory, world_from_object
from tracker.geometry import invert_transform, make_transform

CAM_ROT = np.array([[0.0, 0.0, 1.0], [-1.0, 0.0, 0.0], [0.0, -1.0, 0.0]])
K = np.array([[700.0, 0.0, 320.0], [0.0, 700.0, 240.0], [0.0, 0.0, 1.0]])
MODEL = CameraModel(K, np.zeros(5), 640, 480)
CAMERA_POSE = make_transform(CAM_ROT, np.array([0.0, 0.0, 1.5]))


def plate(half_y: float, half_z: float) -> Mesh:
    """A plate in the object's y-z plane facing -x (towards a camera looking along +x)."""
    v = np.array([[0.0, -half_y, -half_z], [0.0, half_y, -half_z], [0.0, half_y, half_z], [0.0, -half_y, half_z]])
    return Mesh(v, np.array([[0, 1, 2], [0, 2, 3]], dtype=np.int32))


def quad_uv(obj_pose: np.ndarray, mesh: Mesh, camera_pose: np.ndarray) -> np.ndarray:
    m = invert_transform(camera_pose) @ obj_pose
    uv, _ = project(mesh.vertices @ m[:3, :3].T + m[:3, 3], MODEL)
    return uv


def inside_quad(points: np.ndarray, quad: np.ndarray, margin: float) -> np.ndarray:
    """Points inside a convex quad by at least ``margin`` px (negative margin: grown quad)."""
    inside = np.ones(len(points), bool)
    centre = quad.mean(axis=0)
    for i in range(4):
        a, b = quad[i], quad[(i + 1) % 4]
        edge = b - a
        normal = np.array([-edge[1], edge[0]]) / np.linalg.norm(edge)
        if normal @ (centre - a) < 0:
            normal = -normal
        inside &= (points - a) @ normal >= margin
    return inside


def test_object_behind_another_object_is_masked_and_invalid_when_covered_in_next_frame():
    back_mesh, front_mesh = plate(1.5, 1.0), plate(0.6, 0.6)
    back = FlowObject(0, "back", back_mesh, world_from_object([20.0, 0.0, 1.5, 0.0]),
                      world_from_object([20.0, 0.0, 1.5, 0.0]))
    # The front plate slides sideways over the back plate between the two images.
    front = FlowObject(1, "front", front_mesh, world_from_object([10.0, 0.6, 1.5, 0.0]),
                       world_from_object([10.0, 0.1, 1.5, 0.0]))
    setup = PairSetup(MODEL, CAMERA_POSE, CAMERA_POSE)
    result = dense_flow(setup, [back, front], RayCache())
    vs, us = np.nonzero(result.instance == 1)
    pix = np.stack([us, vs], 1).astype(float)
    front_k = quad_uv(front.world_from_object_k, front_mesh, CAMERA_POSE)
    front_k1 = quad_uv(front.world_from_object_k1, front_mesh, CAMERA_POSE)
    # In image k the back plate never owns a pixel well inside the front plate.
    assert not inside_quad(pix, front_k, 1.0).any()
    assert (result.instance == 2).sum() > 1000
    # Back pixels landing under the front plate at k+1 are occluded (flow_occ valid, flow_noc not).
    covered = inside_quad(pix, front_k1, 1.0)
    clear = ~inside_quad(pix, front_k1, -1.0)
    assert covered.sum() > 1000 and clear.sum() > 1000
    assert result.valid_occ[vs[covered], us[covered]].all()
    assert not result.valid_noc[vs[covered], us[covered]].any()
    assert result.valid_noc[vs[clear], us[clear]].all()
    stats = {s.object_id: s for s in result.objects}
    assert 0.0 < stats["back"].occluded_share < 1.0


def wall_points(x: float, y0: float, y1: float, z0: float, z1: float, step: float = 0.05) -> np.ndarray:
    ys, zs = np.meshgrid(np.arange(y0, y1 + 1e-9, step), np.arange(z0, z1 + 1e-9, step))
    return np.stack([np.full(ys.size, x), ys.ravel(), zs.ravel()], 1)


def test_pixels_behind_lidar_points_are_invalid():
    mesh = plate(1.5, 1.0)
    obj = FlowObject(0, "car", mesh, world_from_object([20.0, 0.0, 1.5, 0.0]), world_from_object([19.0, 0.0, 1.5, 0.0]))
    # A post (LiDAR returns) 8 m ahead covers the plate's left part in image k; another one appears only in k+1.
    post_k = wall_points(8.0, 0.3, 0.8, 0.0, 3.0)
    post_k1 = wall_points(8.0, -0.8, -0.3, 0.0, 3.0)
    cam_from_world = invert_transform(CAMERA_POSE)
    setup = PairSetup(MODEL, CAMERA_POSE, CAMERA_POSE, project_lidar(post_k, cam_from_world, MODEL),
                      project_lidar(post_k1, cam_from_world, MODEL), OcclusionParams(dilate_px=7))
    result = dense_flow(setup, [obj], RayCache())
    silhouette = dense_flow(PairSetup(MODEL, CAMERA_POSE, CAMERA_POSE), [obj], RayCache())
    post_k_uv = quad_uv(make_transform(np.eye(3), np.zeros(3)),
                        Mesh(np.array([[8.0, 0.3, 0.0], [8.0, 0.8, 0.0], [8.0, 0.8, 3.0], [8.0, 0.3, 3.0]]), np.zeros((0, 3), int)),
                        CAMERA_POSE)
    vs, us = np.nonzero(silhouette.instance == 1)
    pix = np.stack([us, vs], 1).astype(float)
    behind = inside_quad(pix, post_k_uv, 4.0)
    away = ~inside_quad(pix, post_k_uv, -6.0)
    assert behind.sum() > 500
    assert not result.valid_occ[vs[behind], us[behind]].any()
    assert (result.instance[vs[behind], us[behind]] == 0).all()
    assert result.instance[vs[away], us[away]].all()
    # k+1: pixels whose moved point falls behind the new post lose flow_noc but keep flow_occ.
    post_k1_uv = quad_uv(np.eye(4), Mesh(np.array([[8.0, -0.8, 0.0], [8.0, -0.3, 0.0], [8.0, -0.3, 3.0],
                                                    [8.0, -0.8, 3.0]]), np.zeros((0, 3), int)), CAMERA_POSE)
    vs, us = np.nonzero(result.valid_occ)
    target = np.stack([us, vs], 1) + result.flow[vs, us]
    hidden_next = inside_quad(target, post_k1_uv, 4.0)
    visible_next = ~inside_quad(target, post_k1_uv, -6.0)
    assert hidden_next.sum() > 500
    assert not result.valid_noc[vs[hidden_next], us[hidden_next]].any()
    assert result.valid_noc[vs[visible_next], us[visible_next]].all()


def _sequence(camera_times: list[int]) -> Sequence:
    frames = [FrameInfo(k, 1_000_000_000 + k * 100_000_000, np.eye(4), Path("none")) for k in range(2)]
    cam_frames = [CameraFrame(t, Path("none.png"), CAMERA_POSE) for t in camera_times]
    camera = Camera("front", K, np.zeros(5), 640, 480, cam_frames)
    return Sequence("synthetic", Path("."), "test", frames, lambda k: Sweep(np.zeros((0, 3), np.float32)),
                    cameras={"front": camera})


def test_shifted_camera_timestamp_changes_flow_by_projected_velocity():
    velocity = np.array([-8.0, 2.0, 0.0])  # m/s, towards the camera and sideways
    t0 = 1_000_000_000
    trajectory = Trajectory.from_samples([t0 - 200_000_000, t0 + 400_000_000],
                                         [[25.0 + velocity[0] * -0.2, -1.0 + velocity[1] * -0.2, 1.5, 0.0],
                                          [25.0 + velocity[0] * 0.4, -1.0 + velocity[1] * 0.4, 1.5, 0.0]],
                                         "extrapolate", 150_000_000)
    mesh = plate(1.0, 0.8)
    obj = MeshedObject.from_trajectory("car", "Car", trajectory, mesh.vertices, mesh, np.array([0.1, 2.0, 1.6]), "test")
    options = FlowOptions(use_lidar=False)
    camera_k_time = t0 - 50_000_000
    shift = 30_000_000  # image k+1 taken 30 ms later than nominal
    flows = []
    for t1 in (camera_k_time + 100_000_000, camera_k_time + 100_000_000 + shift):
        seq = _sequence([camera_k_time, t1])
        setup, objects = build_pair(seq, seq.cameras["front"], 0, [obj], options)
        flows.append(compute_pair(setup, objects, "dense"))
    base, shifted = flows
    assert (base.valid_occ == shifted.valid_occ).all() and base.valid_occ.sum() > 2000
    vs, us = np.nonzero(base.valid_occ)
    # Predicted: each point seen at k+1 moves a further v * dt before the shifted image.
    cam_from_world = invert_transform(CAMERA_POSE)
    target = np.stack([us, vs], 1) + base.flow[vs, us]
    rays = np.concatenate([(target - K[:2, 2]) / np.diag(K)[:2], np.ones((len(target), 1))], 1)
    # Depth of the plate at k+1 along each target ray (plate plane x_world = const at k+1).
    x_plane = trajectory.state_at(camera_k_time + 100_000_000)[0]
    world_rays = rays @ CAMERA_POSE[:3, :3].T
    t = (x_plane - CAMERA_POSE[0, 3]) / world_rays[:, 0]
    points_world = CAMERA_POSE[:3, 3] + world_rays * t[:, None]
    moved = points_world + velocity * shift * 1e-9
    expected, _ = project(moved @ cam_from_world[:3, :3].T + cam_from_world[:3, 3], MODEL)
    change = shifted.flow[vs, us] - base.flow[vs, us]
    np.testing.assert_allclose(change, expected - target, atol=0.02)
    assert np.abs(change).max() > 1.0  # the shift matters: over a pixel
