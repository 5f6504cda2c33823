"""The motion model's trend (motion.trend, Holt's double exponential smoothing in tracker/motion.py): a braking or
turning vehicle is predicted without the moving average's lag; coasting and sparse frames keep the average."""

from __future__ import annotations

import numpy as np
import pytest
from tracker_synthetic import BOX_SIZE, make_sequence, trajectory

from tracker import get_preset, track
from tracker.geometry import Box
from tracker.motion import MotionPrior
from tracker.motion_filter import AverageMotion

DT = 0.1
TREND = {"motion.trend": 0.5, "motion.trend_points": 200}


def _braking_errors(trend: float, support: float = 1.0) -> list[float]:
    """One-step prediction errors (m/s) of a car at 14 m/s that brakes at 8 m/s^2 from frame 10 on (per-second
    averages at 10 Hz, alpha 0.6 as in full); entry i is the prediction for frame i + 1."""
    prior = MotionPrior(0.6, "turn", trend)
    errors = []
    for k in range(40):
        speed = 14.0 if k < 10 else max(14.0 - 0.8 * (k - 9), 0.0)
        if k > 0:
            errors.append(float(prior.predict(0.0, DT)[0]) - speed)
        prior.update(np.array([speed, 0.0, 0.0, 0.0]), 0.0, DT, support)
    return errors


def test_a_braking_ramp_is_predicted_without_the_averages_lag():
    average, trend = _braking_errors(0.0), _braking_errors(0.5)
    # the average lags a ramp by (alpha / (1 - alpha) + 1) frames: 2.5 x 0.8 m/s
    assert average[25] == pytest.approx(2.0, abs=1e-3)
    # the trend's prediction catches the ramp within 7 frames of its onset (frame 10) and stays on it
    assert max(abs(e) for e in trend[16:26]) < 0.25
    assert abs(trend[25]) < 0.05
    # the onset itself is a surprise to both
    assert trend[9] == pytest.approx(average[9])


def test_sparse_support_adds_no_trend_and_coasting_predicts_on_the_average():
    # a motion registered on few points (support ~ 0) leaves the trend at 0: the prediction is the level's
    sparse = _braking_errors(0.5, support=0.0)
    assert sparse[25] > 1.0
    holt = MotionPrior(0.6, "turn", 0.5)
    plain = MotionPrior(0.6, "turn", 0.0)
    for k in range(15):
        motion = np.array([10.0 - 0.5 * k, 0.2, 0.0, 0.05 * k])
        holt.update(motion, 0.0, DT)
        plain.update(motion, 0.0, DT)
    np.testing.assert_array_equal(holt.predict(0.0, DT, trend_share=0.0), plain.predict(0.0, DT))
    assert abs(holt.predict(0.0, DT)[3] - 0.05 * 15) < abs(plain.predict(0.0, DT)[3] - 0.05 * 15) / 3
    # the tracker's model: a coasting frame (no data) is predicted on the average
    model = AverageMotion(0.6, "turn", 0.5, per_second=True, trend=0.5, trend_points=200)
    box = Box(0.0, 0.0, 0.0, 0.0, *BOX_SIZE)
    for k in range(15):
        model.update(box, np.array([1.0 - 0.05 * k, 0.0, 0.0, 0.0]), None, None, DT, points=5000)
    coast = model.predict(box, DT, coasting=1)
    np.testing.assert_allclose(coast[:3], model.prior.predict(0.0, DT, trend_share=0.0)[:3] * DT)


def test_a_braking_car_is_followed_within_20_cm():
    # 12 m/s, braking at 8 m/s^2 from frame 8 to a stop at frame 23, ~1300 points
    x, step, boxes = 12.0, 1.2, []
    for k in range(30):
        boxes.append(Box(x, 4.0, 0.0, 0.0, *BOX_SIZE))
        step = max(step - 0.08, 0.0) if k >= 8 else step
        x += step
    sequence = make_sequence(n_frames=30, seed=1, boxes=boxes)

    def max_error(changes: dict) -> float:
        result = track(sequence, boxes[0], 0, len(boxes) - 1, get_preset("full", **changes))
        return max(abs(e.box.x - b.x) for e, b in zip(result.estimates, boxes, strict=True))

    assert max_error(TREND) < 0.2
    # without the trend the motion prior, pulled toward the lagging average, keeps the box driving on: > 1 m ahead
    assert max_error({}) > 1.0


def test_a_car_turning_at_1_rad_per_s_lags_less_with_the_trend():
    # the turn of test_motion_limits (full's defaults lag > 4.5 deg there)
    boxes = trajectory(30, speed=0.8, yaw_rate=0.1, turn_after=6, ramp_frames=8)
    sequence = make_sequence(n_frames=30, seed=1, boxes=boxes)
    result = track(sequence, boxes[0], 0, len(boxes) - 1, get_preset("full", **TREND))
    err = [np.angle(np.exp(1j * (e.box.heading - b.heading))) for e, b in zip(result.estimates, boxes, strict=True)]
    assert np.degrees(np.max(np.abs(err))) < 3.5
