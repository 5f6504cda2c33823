"""Track files (track.json + shape.ply) as flow input: states, timestamps and shape are used as written."""

from __future__ import annotations

import numpy as np

from tracker.geometry import Box, State
from sot_apps.flow.annotate import FlowOptions, build_pair, compute_pair
from sot_apps.flow.objects import objects_from_tracks
from sot_apps.io.tracks import FrameRecord, Size, TrackFile, write_track

from test_occlusion_timing import CAMERA_POSE, K, _sequence


def test_track_directory_drives_the_flow(tmp_path):
    # A 4 x 2 x 1.5 m box-shaped point cloud driving along +y at 5 m/s, 20 m ahead of the camera.
    g = np.linspace(-0.5, 0.5, 9)
    shape = np.stack(np.meshgrid(g * 4.0, g * 2.0, g * 1.5, indexing="ij"), -1).reshape(-1, 3)
    times = [1_000_000_000 + k * 100_000_000 for k in range(3)]
    records = [FrameRecord(k, t, State(20.0, -1.0 + 0.5 * k, 1.5, np.pi / 2), 100, 0.9, [])
               for k, t in enumerate(times)]
    box = Box(20.0, -1.0, 1.5, np.pi / 2, 4.0, 2.0, 1.5)
    track = TrackFile("synthetic", "car_1", Size(4.0, 2.0, 1.5), 0, 2, box, {"preset": "test"}, records, label="Car")
    write_track(tmp_path / "car_1", track, shape)
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
