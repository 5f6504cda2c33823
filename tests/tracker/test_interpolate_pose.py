"""SE(3) interpolation has one home (tracker.interpolate_pose): camera poses of the flow app and the readers'
ego poses (sot_apps.io.convert_util.pose_at) both use it."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from sot_apps.errors import InputError
from sot_apps.io.convert_util import pose_at
from tracker import interpolate_pose, make_transform, rotation_z, rotation_zyx


def _poses():
    times = np.array([0, 100, 300], dtype=np.int64)
    poses = np.stack([make_transform(rotation_z(0.0), [0.0, 0.0, 0.0]),
                      make_transform(rotation_z(np.pi / 2), [2.0, 0.0, 1.0]),
                      make_transform(rotation_zyx(np.pi / 2, 0.4, 0.0), [2.0, 4.0, 1.0])])
    return times, poses


def test_halfway_is_half_the_rotation_and_the_mean_translation():
    times, poses = _poses()
    mid = interpolate_pose(times, poses, 50)
    np.testing.assert_allclose(mid[:3, :3], rotation_z(np.pi / 4), atol=1e-12)
    np.testing.assert_allclose(mid[:3, 3], [1.0, 0.0, 0.5])
    quarter = interpolate_pose(times, poses, 150)     # second segment, a quarter of the pitch
    np.testing.assert_allclose(quarter[:3, :3], rotation_zyx(np.pi / 2, 0.1, 0.0), atol=1e-12)
    np.testing.assert_allclose(quarter[:3, 3], [2.0, 1.0, 1.0])
    np.testing.assert_allclose(mid[3], [0, 0, 0, 1])


def test_sample_times_give_the_samples_and_the_ends_are_clamped():
    times, poses = _poses()
    for t, pose in zip(times, poses, strict=True):
        np.testing.assert_allclose(interpolate_pose(times, poses, int(t)), pose, atol=1e-12)
    np.testing.assert_allclose(interpolate_pose(times, poses, -50), poses[0], atol=1e-12)
    np.testing.assert_allclose(interpolate_pose(times, poses, 10_000), poses[-1], atol=1e-12)
    np.testing.assert_array_equal(interpolate_pose(times[:1], poses[:1], 77), poses[0])


def test_reader_poses_interpolate_inside_and_refuse_outside_or_across_gaps():
    times, poses = _poses()
    np.testing.assert_array_equal(pose_at(times, poses, 100, Path("p")), poses[1])
    np.testing.assert_array_equal(pose_at(times, poses, 50, Path("p")), interpolate_pose(times, poses, 50))
    with pytest.raises(InputError, match="no ego pose around time 400"):
        pose_at(times, poses, 400, Path("p"))
    with pytest.raises(InputError, match="within"):
        pose_at(times, poses, 200, Path("p"), max_gap_ns=150)
