"""`sensor fit` recovers a preset's beam table, azimuth step, spin rate and direction from a simulated sweep."""

from __future__ import annotations

import json

import numpy as np
import pytest
import trimesh

from sot_apps.cli.main import main
from sot_apps.io.canonical import write_sequence
from sot_apps.io.sequence import FrameInfo, Sequence, Sweep
from sot_apps.lidar_sim.noise import Realism
from sot_apps.lidar_sim.scan import SimObject, Trajectory, simulate_scan
from sot_apps.lidar_sim.sensors import PRESETS


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
