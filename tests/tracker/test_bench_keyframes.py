"""``sot-apps bench keyframes`` on the tiny sequence: its car drives straight at constant speed, so linear and CTRV
interpolation between keyframes are exact (Acc 100), and every row is printed and written."""

from __future__ import annotations

import json

import numpy as np
import pytest

from sot_apps.cli.main import main


def test_bench_keyframes_prints_every_row_over_seeds(tiny_dir, tmp_path, capsys):
    """Every row (with the ablations) for two tracker seeds: one run per seed, the figures their mean,
    interpolation the same in both (std 0)."""
    out = tmp_path / "kf.json"
    assert main(["bench", "keyframes", str(tiny_dir), "--tracks", "car-move", "--every", "10", "--quiet",
                 "--ablations", "--seeds", "2", "--json", str(out)]) == 0
    text = capsys.readouterr().out
    for row in ("linear", "ctrv", "keyframes fwd", "keyframes fwd+bwd", "keyframes no-ctrv", "keyframes no-solve",
                "keyframes", "single box + offline"):
        assert any(line.startswith(row) for line in text.splitlines()), row
    assert "seeds 0..1" in text and "mean over 2 seeds" in text
    doc = json.loads(out.read_text())
    assert doc["seeds"] == [0, 1] and [t["seed"] for t in doc["tracks"]] == [0, 1]
    table = doc["tables"][str(tiny_dir)]
    assert table["linear"]["10"][0] > 99.9 and table["ctrv"]["10"][0] > 99.9 and table["linear"]["10"][1] == 0.0
    assert table["keyframes"]["10"][0] > 80.0
    per_seed = [100 * np.mean(t["every"]["10"]["ious"]["keyframes"]) for t in doc["tracks"]]
    assert table["keyframes"]["10"][0] == pytest.approx(np.mean(per_seed))
    assert table["keyframes"]["10"][1] == pytest.approx(np.std(per_seed))
    assert doc["tracks"][0]["every"]["10"]["keys"] == [0, 10, 19]


def test_bench_keyframes_leaves_the_ablations_out_by_default(tiny_dir, capsys):
    assert main(["bench", "keyframes", str(tiny_dir), "--tracks", "car-move", "--every", "19", "--quiet"]) == 0
    rows = [line.split("  ")[0] for line in capsys.readouterr().out.splitlines()]
    assert "keyframes no-solve" in rows and "keyframes" in rows and "keyframes fwd" not in rows
