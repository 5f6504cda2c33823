"""A tiny synthetic world (6 frames, 16-beam LiDAR, no camera) for the app tests."""

from __future__ import annotations

from pathlib import Path

import pytest


@pytest.fixture(scope="session")
def tiny_world(tmp_path_factory) -> Path:
    from sot_apps.synth import write_world

    return write_world(tmp_path_factory.mktemp("apps_world") / "world", frames=6, vehicles=3, sensor="vlp16", seed=4,
                       cameras=False)


def tracking_doc(world: Path, out: Path, **apps: dict) -> dict:
    """Track the world's three vehicles; only the given apps run after the tracking stage."""
    stages = {name: {"enabled": False} for name in ("bank", "motion", "flow", "scans")}
    return {"version": 1, "out": str(out),
            "sequences": [{"path": str(world), "objects": {"from": "annotations",
                                                           "track_ids": ["veh_000", "veh_001", "veh_002"]}}],
            "stages": {**stages, **apps}}
