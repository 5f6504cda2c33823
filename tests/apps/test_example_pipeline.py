"""examples/pipeline.json, written for the version-1 stages, runs unchanged through the registered apps."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[2]


@pytest.mark.slow
@pytest.mark.realdata
def test_examples_pipeline_json_runs_unchanged(tmp_path, pandaset_root):
    from sot_apps.cli.main import main

    out = tmp_path / "out"
    assert main(["run", str(REPO / "examples" / "pipeline.json"), "--out", str(out), "--quiet"]) == 0
    manifest = json.loads((out / "manifest.json").read_text())
    status = {}
    for unit in manifest["stages"]:
        status.setdefault(unit["stage"], []).append(unit["status"])
    assert status == {"track": ["done"] * 2, "bank": ["done"], "motion": ["done"], "flow": ["done"],
                      "motion_eval": ["done"], "scans": ["done"] * 2}
    [seq] = [p for p in out.iterdir() if (p / "tracks").is_dir()]
    assert sorted(p.name[:8] for p in (seq / "tracks").iterdir()) == ["20d13d1d", "8ac00bad"]
    for rel in ("motion.mcap", "motion.parquet", "motion.npz", "motion_eval.json", "flow/front_camera/stats.json"):
        assert (seq / rel).is_file(), rel
    index = json.loads((out / "bank" / "index.json").read_text())
    assert len(index["entries"]) >= 1
    scenes = sorted(p.name for p in (out / "scans").iterdir())
    assert len(scenes) == 2 and scenes[0].endswith("__r20m") and scenes[1].endswith("__r40m")
    # the manifest's config is a valid version-1 pipeline file again
    from sot_apps.pipeline.config import PipelineConfig

    doc = {k: manifest["config"][k] for k in ("version", "description", "out", "sequences", "stages")}
    assert [n for n, _ in PipelineConfig.from_json(doc).stages.apps] == ["bank", "motion", "flow", "scans"]
