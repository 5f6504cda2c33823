"""``sot-apps bench keyframes`` on the tiny sequence: its car drives straight at constant speed, so linear and CTRV
interpolation between keyframes are exact (Acc 100), and every row is printed and written."""

from __future__ import annotations

import json

from sot_apps.cli.main import main


def test_bench_keyframes_prints_every_row(tiny_dir, tmp_path, capsys):
    out = tmp_path / "kf.json"
    assert main(["bench", "keyframes", str(tiny_dir), "--tracks", "car-move", "--every", "10", "--quiet",
                 "--json", str(out)]) == 0
    text = capsys.readouterr().out
    for row in ("linear", "ctrv", "keyframes fwd", "keyframes fwd+bwd", "keyframes", "single box + offline"):
        assert any(line.startswith(row) for line in text.splitlines()), row
    doc = json.loads(out.read_text())
    table = doc["tables"][str(tiny_dir)]
    assert table["linear"]["10"][0] > 99.9 and table["ctrv"]["10"][0] > 99.9
    assert table["keyframes"]["10"][0] > 80.0
    (track,) = doc["tracks"]
    assert track["every"]["10"]["keys"] == [0, 10, 19]
