"""The scan writers keep every value: the npz (deflate level 1) and the KITTI .bin read back equal to the scan."""

from __future__ import annotations

import zipfile

import numpy as np

from sot_apps.lidar_sim.export import write_bin, write_scan_npz
from sot_apps.objects.trajectory import Trajectory
from sot_apps.sensor.model import load_sensor
from sot_apps.sensor.noise import Realism
from sot_apps.sensor.scan import SimObject, range_image, simulate_scan


def test_scan_npz_and_bin_read_back_equal(tmp_path):
    ground = SimObject(np.array([[-50, -50, -1.8], [50, -50, -1.8], [50, 50, -1.8], [-50, 50, -1.8]], float),
                       np.array([[0, 1, 2], [0, 2, 3]]), Trajectory.static(0, 0, 0, 0), -1, 0.2)
    scan = simulate_scan(load_sensor("vlp16"), [ground], np.eye(4), realism=Realism(seed=1))
    assert len(scan) > 1000
    write_scan_npz(tmp_path / "s.npz", scan)
    with np.load(tmp_path / "s.npz") as data:
        for key, value in (("xyz", scan.xyz), ("instance", scan.instance), ("intensity", scan.intensity),
                           ("time_offset_ns", scan.time_offset_ns), ("beam", scan.beam), ("column", scan.column),
                           ("range", scan.distance), ("range_image", range_image(scan))):
            np.testing.assert_array_equal(data[key], value, err_msg=key)
    with zipfile.ZipFile(tmp_path / "s.npz") as archive:
        assert {i.compress_type for i in archive.infolist()} == {zipfile.ZIP_DEFLATED}
    write_bin(tmp_path / "s.bin", scan)
    table = np.fromfile(tmp_path / "s.bin", dtype="<f4").reshape(-1, 4)
    np.testing.assert_array_equal(table[:, :3], scan.xyz)
    np.testing.assert_array_equal(table[:, 3], scan.intensity)
