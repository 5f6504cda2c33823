"""Issue 16, defect 1: every command that takes track directories refuses a track of another sequence."""

from __future__ import annotations

import numpy as np
import pytest

from sot_apps.cli.main import main
from sot_apps.errors import InputError
from sot_apps.io.object_track import ObjectTrack
from sot_apps.io.tracks import TrackHeader, read_track, write_track
from tracker.geometry import Box


def _track_of(directory, sequence_id: str, timestamps: list[int]):
    n = len(timestamps)
    track = ObjectTrack.from_states("car", "", (4.0, 2.0, 1.5), range(n), timestamps, [[10.0, 0.0, 1.0, 0.0]] * n,
                                    None, [["init"]] + [[]] * (n - 1), scores=[0.9] * n, num_points=[50] * n,
                                    shape_points=np.random.default_rng(0).uniform(-1, 1, (50, 3)))
    box = Box(10.0, 0.0, 1.0, 0.0, 4.0, 2.0, 1.5)
    write_track(directory, TrackHeader(sequence_id, 0, n - 1, box, {"preset": "test"}), track)
    return directory


@pytest.mark.parametrize("name, shift_ns", [("some_other_sequence", 0), ("pandaset_002", 1_000)])
def test_flow_refuses_a_track_of_another_sequence(tmp_path, pandaset_root, pandaset, capsys, name, shift_ns):
    times = [int(pandaset.frames[k].timestamp_ns) + shift_ns for k in range(3)]
    track = _track_of(tmp_path / "t", name, times)
    code = main(["flow", str(pandaset_root), "--tracks", str(track), "--camera", "front_camera", "--pairs", "0:1",
                 "--out", str(tmp_path / "F"), "--quiet", "--no-vis"])
    err = capsys.readouterr().err
    assert code == 2 and len(err.strip().splitlines()) == 1
    assert "track.json" in err
    assert not (tmp_path / "F").exists()


def test_check_track_belongs_names_the_mismatch(tmp_path, pandaset):
    from sot_apps.io.tracks import check_track_belongs

    n = len(pandaset.frames)
    ok = _track_of(tmp_path / "ok", pandaset.id, [int(pandaset.frames[k].timestamp_ns) for k in range(3)])
    check_track_belongs(*read_track(ok), pandaset, ok / "track.json")
    beyond = _track_of(tmp_path / "beyond", pandaset.id, [int(pandaset.frames[0].timestamp_ns) + k for k in range(n + 1)])
    with pytest.raises(InputError, match="outside the sequence"):
        check_track_belongs(*read_track(beyond), pandaset, beyond / "track.json")
    other = _track_of(tmp_path / "other", "world_7", [int(pandaset.frames[k].timestamp_ns) for k in range(3)])
    with pytest.raises(InputError, match="world_7"):
        check_track_belongs(*read_track(other), pandaset, other / "track.json")
