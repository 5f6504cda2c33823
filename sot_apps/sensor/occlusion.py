"""Simulated returns against the real ones of the same sweep: a real object in front hides a simulated one.

A simulated return is *blocked* when a real return within ``tolerance`` (radians, on the unit sphere of ray
directions) of its direction is nearer by more than ``OCCLUDER_MARGIN_M``: a pole, a wall or another car
stands in front of the inserted vehicle. The tolerance is the sensor's angular footprint: half its azimuth
step, at least 0.1 degree (:func:`angular_tolerance`).
"""

from __future__ import annotations

import math

import numpy as np
from scipy.spatial import cKDTree

from .model import Sensor

__all__ = ["OCCLUDER_MARGIN_M", "angular_tolerance", "blocked_by_real"]

OCCLUDER_MARGIN_M = 0.3


def angular_tolerance(sensor: Sensor) -> float:
    """Radians: half the azimuth step, at least 0.1 degree."""
    return max(math.radians(sensor.azimuth_resolution_deg) / 2.0, math.radians(0.1))


def blocked_by_real(real_dirs: np.ndarray, real_dist: np.ndarray, sim_dirs: np.ndarray, sim_dist: np.ndarray,
                    tolerance: float, margin: float = OCCLUDER_MARGIN_M) -> np.ndarray:
    """(M,) bool: simulated returns (unit directions, ranges) with a nearer real return (unit directions,
    ranges) within ``tolerance`` radians of their direction (8 nearest real directions looked at)."""
    if len(sim_dirs) == 0 or len(real_dirs) == 0:
        return np.zeros(len(sim_dirs), dtype=bool)
    dist, idx = cKDTree(real_dirs).query(sim_dirs, k=8, distance_upper_bound=tolerance)
    near = np.where(np.isfinite(dist), np.asarray(real_dist)[np.minimum(idx, len(real_dist) - 1)], np.inf)
    return (near < np.asarray(sim_dist)[:, None] - margin).any(axis=1)
