"""The motion limits (tracker/motion_limits.py): a turning car is followed, a parked car does not spin."""

from __future__ import annotations

import numpy as np
import pytest
from tracker_synthetic import make_sequence, trajectory

from tracker import get_preset, track
from tracker.config import MotionConfig
from tracker.motion_limits import limit_motion, max_yaw_rate

DT = 0.1
# full's cap around the predicted turn rate only below 100 points, the heading change capped at the physical yaw
# rate, the motion prior's reference the previous outer iteration
PHYSICAL = {"motion.max_yaw_change_points": 100, "motion.max_lateral_accel": 10.0,
            "motion.prior_reference": "iteration"}


def test_max_yaw_rate_is_steering_limited_slow_and_grip_limited_fast():
    params = MotionConfig(max_lateral_accel=10.0, min_turn_radius=4.5, yaw_rate_margin=0.1)
    assert max_yaw_rate(2.0, params) == pytest.approx(2.0 / 4.5 + 0.1)   # v / R
    assert max_yaw_rate(20.0, params) == pytest.approx(10.0 / 20.0 + 0.1)  # a_lat / v
    assert max_yaw_rate(0.0, params) == pytest.approx(0.1)                 # a standing car: the margin only


def test_a_realistic_yaw_rate_passes_and_a_parked_car_does_not_spin():
    params = MotionConfig(max_lateral_accel=10.0)
    prior = np.zeros(4)  # a stale prediction (straight) must not matter: the cap is on the motion itself
    turning = np.array([0.8, 0.0, 0.0, 0.1])  # 8 m/s, 1 rad/s (a_lat 8 m/s^2) over 0.1 s
    flags: list[str] = []
    assert limit_motion(turning.copy(), prior, 0.0, False, 5, params, flags, DT)[3] == pytest.approx(0.1)
    assert flags == []
    parked = np.array([0.0, 0.0, 0.0, 0.1])  # registration rotated a standing car by 0.1 rad
    out = limit_motion(parked.copy(), prior, 0.0, False, 5, params, flags, DT)
    assert out[3] == pytest.approx(0.1 * DT) and flags == ["yaw_clamped"]


def test_the_cap_around_the_prediction_holds_only_sparse_objects():
    params = MotionConfig(max_yaw_change=0.03, max_yaw_change_points=100)
    prior = np.array([0.8, 0.0, 0.0, 0.0])  # predicted straight on; the registration turns by 0.1 rad
    dense: list[str] = []
    assert limit_motion(np.array([0.8, 0.0, 0.0, 0.1]), prior, 0.0, False, 5, params, dense, DT, 500)[3] == 0.1
    sparse: list[str] = []
    out = limit_motion(np.array([0.8, 0.0, 0.0, 0.1]), prior, 0.0, False, 5, params, sparse, DT, 20)
    assert out[3] == pytest.approx(0.03) and dense == [] and sparse == ["yaw_clamped"]


def _max_heading_error_deg(changes: dict) -> float:
    # 8 m/s, steering in over 8 frames to 0.1 rad/frame (1 rad/s: a 8 m radius, a_lat 8 m/s^2), ~115 deg in all
    boxes = trajectory(30, speed=0.8, yaw_rate=0.1, turn_after=6, ramp_frames=8)
    sequence = make_sequence(n_frames=30, seed=1, boxes=boxes)
    result = track(sequence, boxes[0], 0, len(boxes) - 1, get_preset("full", **changes))
    err = [np.angle(np.exp(1j * (e.box.heading - b.heading))) for e, b in zip(result.estimates, boxes, strict=True)]
    return float(np.degrees(np.max(np.abs(err))))


def test_a_car_turning_at_1_rad_per_s_is_followed_within_3_degrees():
    assert _max_heading_error_deg(PHYSICAL) < 3.0
    # full's defaults (a cap of 0.03 rad/frame around the predicted turn rate, the MP term pulled toward the
    # prediction) fall behind the same turn: the prediction lags the turn's onset
    assert _max_heading_error_deg({}) > 4.5


@pytest.mark.parametrize("capped", [False, True])
def test_frame_one_heading_change_is_capped_only_when_asked(capped):
    """motion.first_yaw_capped: frame 1's heading change is capped at max_yaw_change against the prior's zero turn
    (the start box's heading is given); later frames are capped as before either way."""
    params = MotionConfig(max_yaw_change=0.03, first_yaw_capped=capped)
    rotated = np.array([0.3, 0.0, 0.0, 0.3])   # frame 1 rotated a partial view by 17 degrees
    flags: list[str] = []
    out = limit_motion(rotated.copy(), np.zeros(4), 0.0, True, 1, params, flags, DT)
    assert out[3] == pytest.approx(0.03 if capped else 0.3)
    assert flags == (["yaw_clamped"] if capped else [])
    np.testing.assert_array_equal(out[:3], rotated[:3])
    later = limit_motion(rotated.copy(), np.zeros(4), 0.0, False, 5, params, [], DT)
    assert later[3] == pytest.approx(0.03)
