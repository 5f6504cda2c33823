"""The CTRV RTS smoother against analytic trajectories (constant turn, straight, reversing)."""

from __future__ import annotations

import numpy as np
import pytest

from sot_apps.objects.smoother import SmootherConfig, central_difference_kinematics, ctrv_transition, smooth_track
from tracker.geometry import wrap_angle

from .synthetic import constant_turn, frame_times_ns, make_track


def _relative_error(estimate: np.ndarray, truth: float) -> float:
    return float(np.max(np.abs(estimate - truth)) / abs(truth))


@pytest.mark.parametrize("speed,yaw_rate,heading0", [(8.0, 0.3, 0.5), (15.0, -0.12, 3.0), (-2.5, 0.2, -1.0)])
def test_constant_turn_velocity_and_yaw_rate_within_2_percent(speed, yaw_rate, heading0):
    times = frame_times_ns(60, seed=1)  # irregular steps 0.09..0.11 s
    t = (times - times[0]) * 1e-9
    states = constant_turn(t, speed, yaw_rate, heading0=heading0)
    kin = smooth_track(make_track("a", times, states))
    heading = heading0 + yaw_rate * t
    assert kin.valid.all()
    assert _relative_error(kin.speed, abs(speed)) < 0.02
    assert _relative_error(kin.yaw_rate, yaw_rate) < 0.02
    # the velocity vector, not only its norm (reversing: velocity points against the heading)
    speed_error = np.hypot(kin.velocity[:, 0] - speed * np.cos(heading), kin.velocity[:, 1] - speed * np.sin(heading))
    assert np.max(speed_error) < 0.02 * abs(speed)
    assert np.max(np.hypot(kin.boxes[:, 0] - states[:, 0], kin.boxes[:, 1] - states[:, 1])) < 0.01
    assert np.max(np.abs(kin.acceleration)) < 0.02 * abs(speed)


def test_heading_is_unwrapped_across_the_seam():
    # heading runs from 3.0 rad through +-pi to about -2.9 rad: a wrapped difference would give a
    # yaw-rate spike of ~ -2 pi / 0.1 s at the seam
    times = frame_times_ns(40, seed=2)
    t = (times - times[0]) * 1e-9
    states = constant_turn(t, 6.0, 0.12, heading0=3.0)
    assert states[:, 3].min() < -2.5 and states[:, 3].max() > 2.9
    kin = smooth_track(make_track("a", times, states))
    assert _relative_error(kin.yaw_rate, 0.12) < 0.02
    assert np.all(np.abs(kin.boxes[:, 3]) <= np.pi)


def test_straight_line_and_standing_still():
    times = frame_times_ns(30, seed=3)
    t = (times - times[0]) * 1e-9
    kin = smooth_track(make_track("a", times, constant_turn(t, 12.0, 0.0, heading0=-2.0)))
    assert _relative_error(kin.speed, 12.0) < 0.01
    assert np.max(np.abs(kin.yaw_rate)) < 0.01
    parked = smooth_track(make_track("p", times, constant_turn(t, 0.0, 0.0)))
    assert np.max(parked.speed) < 1e-6 and np.max(np.abs(parked.yaw_rate)) < 1e-6


def test_flagged_frames_are_not_measurements_and_not_interpolated():
    times = frame_times_ns(40, seed=4)
    t = (times - times[0]) * 1e-9
    states = constant_turn(t, 10.0, 0.2)
    corrupted = states.copy()
    bad = np.array([0, 15, 16, 17, 39])
    corrupted[bad, :2] += 25.0  # wild states the tracker flagged: they must not pull the estimate
    valid = np.ones(40, dtype=bool)
    valid[bad] = False
    kin = smooth_track(make_track("a", times, corrupted, valid=valid))
    assert np.array_equal(kin.valid, valid)
    columns = {"x": kin.boxes[:, 0], "y": kin.boxes[:, 1], "heading": kin.boxes[:, 3], "velocity_x": kin.velocity[:, 0],
               **{name: getattr(kin, name) for name in ("speed", "acceleration", "yaw_rate", "position_std")}}
    for name, values in columns.items():
        assert np.isnan(values[bad]).all(), name
        assert np.isfinite(values[valid]).all(), name
    assert kin.flags[15] == ("no_points",)
    good = np.flatnonzero(valid)
    assert _relative_error(kin.speed[good], 10.0) < 0.02
    assert _relative_error(kin.yaw_rate[good], 0.2) < 0.02
    # the gap widens the uncertainty next to it compared with the middle of a run of measurements
    assert kin.position_std[18] > kin.position_std[8]


def test_noise_is_reduced_compared_with_central_differences():
    rng = np.random.default_rng(5)
    times = frame_times_ns(80, seed=5)
    t = (times - times[0]) * 1e-9
    truth = constant_turn(t, 9.0, 0.15)
    noisy = truth.copy()
    noisy[:, :2] += rng.normal(0.0, 0.05, (80, 2))
    noisy[:, 3] += rng.normal(0.0, 0.02, 80)
    track = make_track("a", times, noisy)
    smooth = smooth_track(track, SmootherConfig(sigma_position=0.05, sigma_heading=0.02))
    raw = central_difference_kinematics(track)
    inner = slice(5, -5)
    err_smooth = np.abs(smooth.speed - 9.0)[inner].mean()
    err_raw = np.abs(raw.speed - 9.0)[inner].mean()
    assert err_smooth < 0.5 * err_raw
    assert np.abs(smooth.yaw_rate - 0.15)[inner].mean() < 0.5 * np.abs(raw.yaw_rate - 0.15)[inner].mean()
    # reported 1-sigma position uncertainty is of the right size: the centre error is within 3 sigma
    centre_error = np.hypot(smooth.boxes[:, 0] - truth[:, 0], smooth.boxes[:, 1] - truth[:, 1])
    assert np.mean(centre_error < 3 * smooth.position_std) > 0.95


def test_ctrv_jacobian_matches_finite_differences():
    for omega in (0.0, 1e-5, 0.4):
        state = np.array([1.0, -2.0, 0.7, 7.0, omega, 0.3, 0.1, 0.15])
        _, F = ctrv_transition(state, 0.1)
        numeric = np.zeros_like(F)
        for j in range(8):
            step = np.zeros(8)
            step[j] = 1e-6
            numeric[:, j] = (ctrv_transition(state + step, 0.1)[0] - ctrv_transition(state - step, 0.1)[0]) / 2e-6
        assert np.allclose(F, numeric, atol=1e-6), (omega, F - numeric)


def test_central_differences_of_an_analytic_line():
    times = frame_times_ns(20, seed=7, jitter_s=0.0)
    t = (times - times[0]) * 1e-9
    kin = central_difference_kinematics(make_track("a", times, constant_turn(t, 5.0, 0.0, heading0=0.3)))
    assert np.allclose(kin.velocity[:, 0], 5.0 * np.cos(0.3), atol=1e-6)
    assert np.allclose(kin.velocity[:, 1], 5.0 * np.sin(0.3), atol=1e-6)


def test_side_slip_of_the_box_centre_is_not_forced_onto_the_heading():
    # a slow car turning a corner: its centre travels at 10 degrees to the length axis
    times = frame_times_ns(50, seed=8)
    t = (times - times[0]) * 1e-9
    slip = np.radians(10.0)
    course = constant_turn(t, 2.0, 0.35, heading0=0.4)
    states = course.copy()
    states[:, 3] = wrap_angle(course[:, 3] - slip)  # the box heading lags the direction of travel
    kin = smooth_track(make_track("a", times, states))
    direction = 0.4 + 0.35 * t
    assert np.max(np.hypot(kin.velocity[:, 0] - 2.0 * np.cos(direction), kin.velocity[:, 1] - 2.0 * np.sin(direction))) < 0.04
    assert _relative_error(kin.yaw_rate, 0.35) < 0.02
    assert np.max(np.hypot(kin.boxes[:, 0] - states[:, 0], kin.boxes[:, 1] - states[:, 1])) < 0.01
