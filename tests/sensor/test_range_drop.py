"""The sensor's range drop: returns lost with probability clip(a + b * r, 0, 1), seeded, off for other presets."""

from __future__ import annotations

import numpy as np

from sot_apps.objects.trajectory import Trajectory
from sot_apps.sensor.model import PRESETS, load_sensor
from sot_apps.sensor.noise import Realism
from sot_apps.sensor.scan import SimObject, simulate_scan


def _wall(distance: float) -> SimObject:
    """A 60 m wide, 40 m tall wall facing the sensor at ``distance`` along +x."""
    v = np.array([[distance, -30, -20], [distance, 30, -20], [distance, 30, 20], [distance, -30, 20]], dtype=float)
    return SimObject(v, np.array([[0, 1, 2], [0, 2, 3]]), Trajectory.static(0, 0, 0, 0))


def _scan(sensor, distance: float, drop_range: bool, seed: int = 0):
    realism = Realism(range_noise=False, drop_grazing=False, intensity=False, motion_distortion=False,
                      drop_range=drop_range, seed=seed)
    return simulate_scan(sensor, [_wall(distance)], np.eye(4), realism=realism)


def _returns(sensor, distance: float, drop_range: bool, seed: int = 0) -> int:
    return len(_scan(sensor, distance, drop_range, seed))


def test_range_drop_matches_its_probability():
    sensor = PRESETS["pandaset_pandar64"]
    assert np.allclose(sensor.range_drop_probability(np.array([0.0, 40.0, 500.0])), [0.05, 0.25, 1.0])
    for distance in (10.0, 40.0):
        hits = _scan(sensor, distance, drop_range=False).distance.astype(np.float64)
        p = sensor.range_drop_probability(hits)
        kept = _returns(sensor, distance, drop_range=True)
        expected, sigma = float((1 - p).sum()), float(np.sqrt((p * (1 - p)).sum()))
        assert abs(kept - expected) < 4 * sigma, (kept, expected, sigma)
    assert _returns(sensor, 40.0, True, seed=3) == _returns(sensor, 40.0, True, seed=3)


def test_sensors_without_range_drop_are_unchanged():
    sensor = PRESETS["pandar64"]
    assert not sensor.has_range_drop and "drop_per_m" not in sensor.to_dict()
    assert _returns(sensor, 30.0, drop_range=True) == _returns(sensor, 30.0, drop_range=False)
    assert load_sensor(PRESETS["pandaset_pandar64"].to_dict()) == PRESETS["pandaset_pandar64"]
