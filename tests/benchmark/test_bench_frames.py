"""`sot-apps bench frames`: per-frame errors against analytic boxes; a confirming list is refused."""

from __future__ import annotations

import json

import numpy as np
import pytest

from sot_apps.bench.frames import frame_errors, parse_variant
from sot_apps.cli.main import main
from sot_apps.errors import InputError
from tracker.geometry import Box


def test_errors_are_in_the_true_box_frame_and_the_heading_wraps():
    truth = [Box(10.0, 5.0, 1.0, 0.5, 4.5, 1.8, 1.5), Box(0.0, 0.0, 0.0, np.pi - 0.05, 4.5, 1.8, 1.5)]
    forward, left = np.array([np.cos(0.5), np.sin(0.5)]), np.array([-np.sin(0.5), np.cos(0.5)])
    x, y = np.array([10.0, 5.0]) + 1.0 * forward + 0.2 * left
    boxes = [Box(x, y, 1.1, 0.5 + np.radians(10.0), 4.5, 1.8, 1.5),
             Box(0.0, 0.0, 0.0, -np.pi + 0.05, 4.5, 1.8, 1.5)]          # 0.1 rad across the +-pi seam
    e = frame_errors(boxes, truth)
    np.testing.assert_allclose(e.along, [1.0, 0.0], atol=1e-12)
    np.testing.assert_allclose(e.across, [0.2, 0.0], atol=1e-12)
    np.testing.assert_allclose(e.dz, [0.1, 0.0], atol=1e-12)
    np.testing.assert_allclose(e.heading_deg, [10.0, np.degrees(0.1)], atol=1e-9)
    assert e.iou[1] < 1.0 and 0.0 < e.iou[0] < 1.0
    assert frame_errors(truth, truth).iou == pytest.approx([1.0, 1.0])


def test_variants_parse_and_bad_ones_are_input_errors():
    assert parse_variant("ft:motion.first_turn_points=200,motion.alpha=0.5") == (
        "ft", {"motion.first_turn_points": 200, "motion.alpha": 0.5})
    assert parse_variant("same:") == ("same", {})
    for bad in ("noname", ":motion.alpha=1", "x:motion.nope=1"):
        with pytest.raises(InputError):
            parse_variant(bad)


def test_a_list_from_the_confirming_part_is_refused(tmp_path, capsys):
    entry = {"id": "ins_c00_00", "type": 1, "segment_name": "missing", "frame_range": [0, 3], "split": "confirm"}
    path = tmp_path / "benchmark.json"
    path.write_text(json.dumps([entry]))
    assert main(["bench", "frames", str(path)]) == 2
    assert "confirming part" in capsys.readouterr().err


def test_offline_rows_are_the_offline_refinement_that_eval_scores(small_benchmark, capsys, tmp_path):
    """``--offline``: each run's offline refinement, pooled as ``sot-apps eval --offline`` pools it (the eval's
    offline row over the same tracklets, seed 0; online likewise)."""
    listing = str(small_benchmark / "benchmark.json")
    pooled = {}
    for mode in ("online", "offline"):
        assert main(["bench", "frames", listing, "--preset", "full"] + (["--offline"] if mode == "offline" else [])) == 0
        pooled[mode] = float(capsys.readouterr().out.strip().splitlines()[-1].split()[-1])
    report = tmp_path / "report.json"
    assert main(["eval", "--benchmark", listing, "--preset", "full", "--offline", "--json", str(report)]) == 0
    capsys.readouterr()
    tables = json.loads(report.read_text())["tables"]
    assert pooled["offline"] == pytest.approx(100 * tables["full+offline"]["all"]["acc"], abs=0.051)
    assert pooled["online"] == pytest.approx(100 * tables["full"]["all"]["acc"], abs=0.051)
    assert pooled["offline"] != pooled["online"]
