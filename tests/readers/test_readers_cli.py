"""``sot-apps info`` and ``sot-apps convert`` on every reader's fixture; the canonical copy keeps what was read."""

from __future__ import annotations

import json

import numpy as np
import pytest

from sot_apps.cli.main import main
from sot_apps.io import open_sequence

from .paths import AV2_LOG_B, KITTI_TRACKING, VOD


def _nuscenes_dataroot(tmp_path):
    from sot_apps.io.tiny import make_tiny_sequence

    from .test_nuscenes import _write_tiny_dataroot

    tiny = open_sequence(make_tiny_sequence(tmp_path / "tiny"))
    return f"{_write_tiny_dataroot(tiny, tmp_path / 'nuscenes')}#scene-0001"


@pytest.mark.parametrize("fixture, fmt", [
    ("av2", "av2"), ("nuscenes", "nuscenes"), ("kitti_tracking", "kitti_tracking"), ("vod", "kitti_object")])
def test_info_and_convert(readers_root, tmp_path, capsys, fixture, fmt):
    path = {"av2": lambda: str(AV2_LOG_B), "nuscenes": lambda: _nuscenes_dataroot(tmp_path),
            "kitti_tracking": lambda: str(KITTI_TRACKING / "label_02" / "0012.txt"), "vod": lambda: str(VOD)}[fixture]()
    assert main(["info", path, "--json"]) == 0, capsys.readouterr().err
    summary = json.loads(capsys.readouterr().out)
    seq = open_sequence(path)
    assert summary["format"] == fmt and summary["num_frames"] == len(seq)
    assert summary["missing_sweeps"] == seq.missing_sweeps() and len(summary["tracks"]) == len(seq.tracks())
    assert main(["info", path]) == 0
    text = capsys.readouterr().out
    assert f"({fmt}:" in text and "sweeps" in text
    out = tmp_path / "canonical"
    assert main(["convert", path, "--out", str(out)]) == 0, capsys.readouterr().err
    again = open_sequence(out)
    assert again.format == "sequence" and len(again) == len(seq) and again.missing_sweeps() == seq.missing_sweeps()
    assert sorted(again.tracks()) == sorted(seq.tracks()) and sorted(again.cameras) == sorted(seq.cameras)
    k = next(i for i, f in enumerate(seq.frames) if seq.annotations and seq.annotations[i])
    np.testing.assert_allclose(again.annotations[k][0].box.to_array(), seq.annotations[k][0].box.to_array())
    np.testing.assert_allclose(again.frames[k].world_from_ego, seq.frames[k].world_from_ego)
    swept = [f.index for f in seq.frames if f.has_sweep]
    if swept:
        np.testing.assert_array_equal(again.sweep(swept[0]).xyz, seq.sweep(swept[0]).xyz)
