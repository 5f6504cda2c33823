"""Sparse mode: projected shape points with a z-buffer."""

from __future__ import annotations

import cv2
import numpy as np
from test_dense_analytic import K, plane_in_camera_k, scenario

from sot_apps.flow.scene import FlowObject
from sot_apps.flow.sparse import sparse_flow
from sot_apps.objects.meshes import box_mesh


def test_sparse_flow_of_visible_face_matches_homography_and_hides_far_face():
    model, setup, plate = scenario(np.zeros(5))
    # Points on the plate's plane x = +0.5 (visible) and a parallel face at x = -1.5 (behind it).
    g = np.linspace(-1.0, 1.0, 120)
    ys, zs = np.meshgrid(g, g * 0.7)
    near = np.column_stack([np.full(ys.size, 0.5), ys.ravel(), zs.ravel()])
    far = near - [2.0, 0.0, 0.0]
    near_only = sparse_flow(setup, [FlowObject(0, "plate", box_mesh(2.0, 2.0, 1.4), plate.world_from_object_k,
                                               plate.world_from_object_k1, points=near)])
    both = sparse_flow(setup, [FlowObject(0, "plate", box_mesh(2.0, 2.0, 1.4), plate.world_from_object_k,
                                          plate.world_from_object_k1, points=np.concatenate([near, far]))])
    normal, d = plane_in_camera_k(setup, plate)
    motion = setup.motion(plate)
    H = K @ (motion[:3, :3] + np.outer(motion[:3, 3], normal) / d) @ np.linalg.inv(K)
    vs, us = np.nonzero(near_only.valid_occ)
    assert len(us) > 3000
    p = H @ np.stack([us, vs, np.ones_like(us)]).astype(float)
    expected = (p[:2] / p[2]).T - np.stack([us, vs], axis=1)
    # The flow belongs to the point, stored at its rounded pixel: within the flow gradient over half a pixel.
    assert np.abs(near_only.flow[vs, us] - expected).max() < 0.1
    # With the far face added, no far point leaks through the near face (dilated z-buffer): the near
    # face's pixels keep the near face's flow. (Far points beside the near face are truly visible.)
    region = cv2.morphologyEx(near_only.valid_occ.astype(np.uint8), cv2.MORPH_CLOSE, np.ones((5, 5), np.uint8))
    region = cv2.erode(region, np.ones((5, 5), np.uint8)) > 0
    vi, ui = np.nonzero(region & both.valid_occ)
    assert len(ui) > 3000
    q = H @ np.stack([ui, vi, np.ones_like(ui)]).astype(float)
    near_expected = (q[:2] / q[2]).T - np.stack([ui, vi], axis=1)
    assert np.abs(both.flow[vi, ui] - near_expected).max() < 0.1
    far_normal_d = d + 2.0  # the far face is 2 m further along the same normal: a different homography
    H_far = K @ (motion[:3, :3] + np.outer(motion[:3, 3], normal) / far_normal_d) @ np.linalg.inv(K)
    q = H_far @ np.stack([ui, vi, np.ones_like(ui)]).astype(float)
    far_expected = (q[:2] / q[2]).T - np.stack([ui, vi], axis=1)
    assert np.abs(far_expected - near_expected).max(axis=1).min() > 0.3  # so a leak would be caught
    assert both.objects[0].pixels == int(both.valid_occ.sum())
