"""Track files (track.json + shape.ply) as flow input: states, timestamps and shape are used as written."""

from __future__ import annotations

from pathlib import Path

import numpy as np
from test_occlusion_timing import _sequence

from sot_apps.flow.annotate import FlowOptions, build_pair, compute_pair
from sot_apps.flow.objects import objects_from_tracks
from sot_apps.io.object_track import ObjectTrack
from sot_apps.io.sequence import FrameInfo, Sequence, Sweep
from sot_apps.io.tracks import TrackHeader, write_track
from tracker.geometry import Box


def test_track_directory_drives_the_flow(tmp_path):
    # A 4 x 2 x 1.5 m box-shaped point cloud driving along +y at 5 m/s, 20 m ahead of the camera.
    g = np.linspace(-0.5, 0.5, 9)
    shape = np.stack(np.meshgrid(g * 4.0, g * 2.0, g * 1.5, indexing="ij"), -1).reshape(-1, 3)
    times = [1_000_000_000 + k * 100_000_000 for k in range(3)]
    track = ObjectTrack.from_states("car_1", "Car", (4.0, 2.0, 1.5), range(3), times,
                                    [[20.0, -1.0 + 0.5 * k, 1.5, np.pi / 2] for k in range(3)], None,
                                    scores=[0.9] * 3, num_points=[100] * 3, shape_points=shape)
    box = Box(20.0, -1.0, 1.5, np.pi / 2, 4.0, 2.0, 1.5)
    write_track(tmp_path / "car_1", TrackHeader("synthetic", 0, 2, box, {"preset": "test"}), track)
    [obj] = objects_from_tracks([tmp_path / "car_1"])
    assert obj.object_id == "car_1" and obj.label == "Car"
    np.testing.assert_array_equal(obj.trajectory.times_ns, times)
    np.testing.assert_allclose(obj.trajectory.state_at(times[0] + 50_000_000), [20.0, -0.75, 1.5, np.pi / 2])
    np.testing.assert_allclose(np.ptp(obj.mesh.vertices, axis=0), [4.0, 2.0, 1.5], atol=1e-9)
    seq = _sequence([times[0] + 20_000_000, times[1] + 20_000_000])
    setup, objects = build_pair(seq, seq.cameras["front"], 0, [obj], FlowOptions(use_lidar=False))
    result = compute_pair(setup, objects, "dense")
    assert result.valid_occ.sum() > 3000
    # 0.5 m sideways (world +y = image left) at 20 m depth with f = 700: about -17.5 px of u, no v.
    flow = result.flow[result.valid_occ]
    assert np.all(flow[:, 0] < -15) and np.all(flow[:, 0] > -20)
    assert np.abs(flow[:, 1]).max() < 1.5


def test_track_states_are_restamped_with_the_capture_time_of_their_points(tmp_path):
    times = [1_000_000_000 + k * 100_000_000 for k in range(2)]
    track = ObjectTrack.from_states("car", "", (4.0, 2.0, 1.5), range(2), times,
                                    [[10.0 + k, 0.0, 1.0, 0.0] for k in range(2)], None, scores=[0.9] * 2,
                                    num_points=[50] * 2, shape_points=np.random.default_rng(0).uniform(-1, 1, (50, 3)))
    box = Box(10.0, 0.0, 1.0, 0.0, 4.0, 2.0, 1.5)
    write_track(tmp_path / "car", TrackHeader("s", 0, 1, box, {"preset": "test"}), track)
    # Sweeps (ego = world): 30 points on the car captured 40 ms (frame 0) / 70 ms (frame 1) before the frame
    # time, 30 points elsewhere captured 5 ms before it.
    def sweep(k):
        car = np.column_stack([np.full(30, 10.0 + k), np.linspace(-0.8, 0.8, 30), np.full(30, 1.0)])
        other = car + [0.0, 20.0, 0.0]
        offsets = np.r_[np.full(30, -40_000_000 - 30_000_000 * k), np.full(30, -5_000_000)].astype(np.int64)
        return Sweep(np.concatenate([car, other]).astype(np.float32), None, offsets)

    frames = [FrameInfo(k, t, np.eye(4), Path("none")) for k, t in enumerate(times)]
    seq = Sequence("s", Path("."), "test", frames, sweep)
    [given] = objects_from_tracks([tmp_path / "car"], box_time="frame", seq=seq)
    [stamped] = objects_from_tracks([tmp_path / "car"], box_time="points", seq=seq)
    np.testing.assert_array_equal(given.trajectory.times_ns, times)
    np.testing.assert_array_equal(stamped.trajectory.times_ns, [times[0] - 40_000_000, times[1] - 70_000_000])
