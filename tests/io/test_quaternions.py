"""The readers' quaternion -> rotation matrix (numpy, no scipy.spatial import) against scipy's Rotation (a
third-party truth, bit for bit) and an analytic case."""

from __future__ import annotations

import math

import numpy as np
from scipy.spatial.transform import Rotation

from sot_apps.io.convert_util import quaternion_wxyz_to_matrix, rotation_matrices_xyzw


def test_bit_identical_to_scipy_rotation():
    rng = np.random.default_rng(7)
    quats = rng.normal(size=(5000, 4))
    quats *= rng.uniform(0.6, 1.9, size=(5000, 1)) / np.linalg.norm(quats, axis=1, keepdims=True)   # any norm
    assert np.array_equal(rotation_matrices_xyzw(quats), Rotation.from_quat(quats).as_matrix())
    for q in quats[:50]:   # one at a time, as the PandaSet reader converts each pose
        assert np.array_equal(rotation_matrices_xyzw(q)[0], Rotation.from_quat(q).as_matrix())


def test_quarter_turn_about_z():
    half = math.pi / 4
    matrix = quaternion_wxyz_to_matrix(math.cos(half), 0.0, 0.0, math.sin(half), None, "test")
    np.testing.assert_allclose(matrix, [[0, -1, 0], [1, 0, 0], [0, 0, 1]], atol=1e-15)
