"""Where the real files of other datasets are (../shared/data/readers; README + SOURCE.md there)."""

from __future__ import annotations

import os
from pathlib import Path

READERS = Path(os.environ.get("SOT_APPS_READERS", Path(__file__).resolve().parents[2].parent / "shared" / "data" / "readers"))
AV2_LOGS = READERS / "av2_sensor_test" / "sensor" / "val"
AV2_LOG_A = AV2_LOGS / "7fab2350-7eaf-3b7e-a39d-6937a4c1bede"
AV2_LOG_B = AV2_LOGS / "adcf7d18-0510-35b0-a2fa-b4cea13a6d76"
NUSCENES_DEMO = READERS / "nuscenes_demo"
KITTI_TRACKING = READERS / "kitti_tracking_labels" / "training"
VOD = READERS / "kitti_object_vod"
