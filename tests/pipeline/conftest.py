"""Tiny synthetic worlds (6 frames, 16-beam LiDAR, 320x240 camera) and one reference pipeline run."""

from __future__ import annotations

import hashlib
from pathlib import Path

import pytest

# Seeds whose three moving vehicles all carry LiDAR points from the first frame on (checked in the fixture).
SEEDS = (4, 5)


def write_tiny_world(out: Path, seed: int) -> Path:
    from sot_apps.synth import write_world

    return write_world(out, frames=6, vehicles=3, sensor="vlp16", seed=seed, cameras=True, camera_size=(320, 240))


@pytest.fixture(scope="session")
def tiny_worlds(tmp_path_factory) -> list[Path]:
    root = tmp_path_factory.mktemp("pipeline_worlds")
    return [write_tiny_world(root / f"world{seed}", seed) for seed in SEEDS]


def pipeline_doc(worlds: list[Path], out: Path) -> dict:
    return {"version": 1, "out": str(out),
            "sequences": [{"path": str(w), "objects": {"from": "annotations", "track_ids": ["veh_000", "veh_001", "veh_002"]}}
                          for w in worlds],
            "stages": {"bank": {"min_points": 0},
                       "scans": {"sensor": "pandar64", "max_entries": 1, "headings_deg": [0, 90]}}}


def output_checksums(out: Path) -> dict[str, str]:
    """sha256 of every pipeline output, except files that record run times or absolute paths
    (manifest.json, .done markers, flow stats/pair records with their per-pair milliseconds, the report)."""
    sums = {}
    for p in sorted(out.rglob("*")):
        rel = p.relative_to(out).as_posix()
        if not p.is_file() or rel.startswith((".done/", "report/")) or rel == "manifest.json":
            continue
        if "/flow/" in rel and (rel.endswith("stats.json") or "/pairs/" in rel):
            continue
        sums[rel] = hashlib.sha256(p.read_bytes()).hexdigest()
    return sums


@pytest.fixture(scope="session")
def reference_run(tiny_worlds, tmp_path_factory):
    """The pipeline over 2 sequences x 3 objects, in this process (inline executor)."""
    from sot_apps.pipeline.config import PipelineConfig
    from sot_apps.pipeline.executors import ExecutorSpec
    from sot_apps.pipeline.runner import run_pipeline

    out = tmp_path_factory.mktemp("pipeline_reference") / "out"
    config = PipelineConfig.from_json(pipeline_doc(tiny_worlds, out))
    result = run_pipeline(config, ExecutorSpec("inline"), progress=False)
    return result, output_checksums(out)
