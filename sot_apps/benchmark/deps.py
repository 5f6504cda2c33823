"""Everything the benchmark takes from outside its package, in one place.

- the sensor model and scan simulation from the floor (``sot_apps.sensor``: model, noise, scan, occlusion),
  the vehicle bank (``sot_apps.objects.bank``) and the ray-casting engine (``sot_apps.raycast``); the benchmark
  never imports another app (lidar_sim);
- the tracker evaluation pieces (sot_apps.evaluation.tracker).
"""

from __future__ import annotations

from ..evaluation.tracker import (CachedSource, EvalConfig, TrackSpec, json_safe, refined_modes, resolve_presets,
                                  score_result)
from ..objects.bank import Bank, BankEntry, read_bank
from ..objects.trajectory import Trajectory, world_from_object
from ..raycast import RaycastScene
from ..sensor.model import Sensor, load_sensor
from ..sensor.noise import Realism
from ..sensor.occlusion import angular_tolerance, blocked_by_real
from ..sensor.scan import Scan, SimObject, invert_transform_batch, simulate_scan


def eval_ground_params():
    """The ground removal ``sot-apps eval`` uses for pseudo-ground-truth shapes (default tracker settings)."""
    from tracker import TrackerConfig

    return TrackerConfig().ground.params()


__all__ = ["eval_ground_params", "CachedSource", "EvalConfig", "TrackSpec", "json_safe", "resolve_presets",
           "score_result", "refined_modes", "Bank", "BankEntry", "read_bank", "Realism", "RaycastScene", "Scan", "SimObject",
           "Trajectory", "invert_transform_batch", "simulate_scan", "world_from_object", "angular_tolerance",
           "blocked_by_real", "Sensor", "load_sensor"]
