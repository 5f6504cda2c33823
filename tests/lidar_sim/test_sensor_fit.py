"""`sensor fit` recovers a preset's beam table, azimuth step, spin rate and direction from a simulated sweep."""

from __future__ import annotations

import json

import numpy as np
import pytest
import trimesh

from sot_apps.cli.main import main
from sot_apps.io.canonical import write_sequence
from sot_apps.io.sequence import FrameInfo, Sequence, Sweep
from sot_apps.objects.trajectory import Trajectory
from sot_apps.sensor.model import PRESETS
from sot_apps.sensor.noise import Realism
from sot_apps.sensor.scan import SimObject, simulate_scan


def _room_sweep(name: str, seed: int = 0):
    room = trimesh.creation.box(extents=[60.0, 50.0, 30.0])
    room.apply_translation([3.0, -2.0, 8.0])  # every beam hits a wall, floor or ceiling
    realism = Realism(range_noise=True, drop_random=0.1, drop_grazing=False, intensity=False, motion_distortion=False,
                      seed=seed)
    return simulate_scan(PRESETS[name], [SimObject(room.vertices, room.faces, Trajectory.static(0, 0, 0, 0))],
                         np.eye(4), realism=realism)


@pytest.mark.parametrize("name", ["pandar64", "hdl32e"])
def test_sensor_fit_cli_recovers_preset(tmp_path, name):
    scan = _room_sweep(name)
    seq = Sequence(id="room", root=tmp_path / "none", format="sim", ego_from_lidar=np.eye(4),
                   frames=[FrameInfo(0, 1_000_000_000, np.eye(4), tmp_path / "p.npz")],
                   load_sweep=lambda k: Sweep(scan.xyz, scan.intensity, scan.time_offset_ns))
    write_sequence(seq, tmp_path / "seq", progress=False)
    out = tmp_path / "fit.json"
    assert main(["sensor", "fit", str(tmp_path / "seq"), "--frames", "0", "--out", str(out)]) == 0
    doc = json.loads(out.read_text())
    preset = PRESETS[name]
    fitted = np.sort(doc["elevations_deg"])
    assert len(fitted) == preset.beams
    np.testing.assert_allclose(fitted, np.sort(preset.elevations_deg), atol=0.01)
    assert doc["columns"] == preset.columns
    assert doc["rotation_hz"] == pytest.approx(preset.rotation_hz, rel=0.01)
    assert doc["direction"] == preset.direction


def test_points_at_capture_pose_undoes_the_sensor_motion():
    """Points seen by a moving, turning sensor come back to the sensor frame of their own capture time."""
    from scipy.spatial.transform import Rotation, Slerp

    from sot_apps.sensor.fit import points_at_capture_pose

    rng = np.random.default_rng(0)
    t_prev, t_now = 1_000_000_000, 1_100_000_000
    rot = Rotation.from_euler("zyx", [[0.3, 0.01, -0.02], [0.38, 0.015, -0.01]])
    pos = np.array([[10.0, 5.0, 1.0], [11.2, 5.4, 1.05]])
    world_from = [np.eye(4), np.eye(4)]
    for i in range(2):
        world_from[i][:3, :3] = rot[i].as_matrix()
        world_from[i][:3, 3] = pos[i]
    offsets = -rng.integers(0, 100_000_000, 2000)                    # capture times in the last 0.1 s
    s = 1.0 + offsets / (t_now - t_prev)
    rot_at = Slerp([0.0, 1.0], rot)(s)                               # independent: scipy's SLERP
    pos_at = pos[0] + s[:, None] * (pos[1] - pos[0])
    sensor_vectors = rng.normal(size=(2000, 3)) * 20
    world = rot_at.apply(sensor_vectors) + pos_at
    in_frame = (world - pos[1]) @ rot[1].as_matrix()                 # what a reader returns (frame pose)
    back = points_at_capture_pose(in_frame, offsets, t_now, world_from[1], t_prev, world_from[0])
    np.testing.assert_allclose(back, sensor_vectors, atol=1e-9)
    # the next frame works as the other pose too (extrapolation backwards)
    back_next = points_at_capture_pose((world - pos[0]) @ rot[0].as_matrix(), offsets + (t_now - t_prev), t_prev,
                                       world_from[0], t_now, world_from[1])
    np.testing.assert_allclose(back_next, sensor_vectors, atol=1e-9)


def test_align_finds_an_offset_optical_centre():
    """Sweeps given in a frame whose origin is not the optical centre (as PandaSet's): the alignment finds the
    centre, and the fit then recovers the preset's beams."""
    from sot_apps.sensor.fit import align_sensor_frame, fit_sensor
    from tracker.geometry import transform_points

    room = trimesh.creation.box(extents=[60.0, 50.0, 30.0])
    room.apply_translation([3.0, -2.0, 8.0])
    centre = np.array([0.4, 1.2, 1.6])
    world_from_sensor = np.eye(4)
    world_from_sensor[:3, 3] = centre
    realism = Realism(range_noise=True, drop_random=0.1, drop_grazing=False, intensity=False, motion_distortion=False)
    scan = simulate_scan(PRESETS["pandar64"], [SimObject(room.vertices, room.faces, Trajectory.static(0, 0, 0, 0))],
                         world_from_sensor, realism=realism)
    in_frame = scan.xyz.astype(np.float64) + centre                   # the frame origin sits below and behind
    sensor_from_frame, info = align_sensor_frame([in_frame], horizontal_search_m=2.0, vertical_search_m=(0.0, 2.5))
    np.testing.assert_allclose(info["origin_m"], centre, atol=0.03)
    assert abs(info["roll_deg"]) < 0.05 and abs(info["pitch_deg"]) < 0.05
    assert info["sharpness_after"] > 2 * info["sharpness_before"]
    fitted = fit_sensor([transform_points(sensor_from_frame, in_frame)]).sensor
    assert fitted.beams == 64
    np.testing.assert_allclose(np.sort(fitted.elevations_deg), np.sort(PRESETS["pandar64"].elevations_deg), atol=0.03)
