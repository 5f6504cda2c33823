"""Everything the benchmark takes from other apps, in one place (to re-point when shared code moves).

- the sensor model and scan simulation (lidar_sim: sensors, noise, scan, raycast, bank);
- the tracker evaluation pieces (sot_apps.evaluation.tracker).
"""

from __future__ import annotations

from ..evaluation.tracker import CachedSource, EvalConfig, TrackSpec, json_safe, resolve_presets, score_result
from ..lidar_sim.bank import Bank, BankEntry, read_bank
from ..lidar_sim.noise import Realism
from ..raycast import RaycastScene
from ..lidar_sim.scan import Scan, SimObject, invert_transform_batch, simulate_scan
from ..objects.trajectory import Trajectory, world_from_object
from ..lidar_sim.scene import OCCLUDER_MARGIN_M
from ..lidar_sim.sensors import Sensor, load_sensor

def eval_ground_params():
    """The ground removal ``sot-apps eval`` uses for pseudo-ground-truth shapes (default tracker settings)."""
    from tracker import TrackerConfig

    return TrackerConfig().ground_params()

__all__ = ["eval_ground_params", "CachedSource", "EvalConfig", "TrackSpec", "json_safe", "resolve_presets", "score_result", "Bank", "BankEntry", "read_bank", "Realism",
           "RaycastScene", "Scan", "SimObject", "Trajectory", "invert_transform_batch", "simulate_scan",
           "world_from_object", "OCCLUDER_MARGIN_M", "Sensor", "load_sensor"]
