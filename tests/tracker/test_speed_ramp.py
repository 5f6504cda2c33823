"""The speed ramp (motion.ramp_frames, tracker/speed_ramp.py): an accelerating vehicle is predicted at the speed it
will have, not the moving average's lagging one; a steady track's prediction is the average's, unchanged."""

from __future__ import annotations

import numpy as np
import pytest
from tracker_synthetic import BOX_SIZE, make_sequence

from tracker import get_preset, track
from tracker.geometry import Box
from tracker.motion_filter import AverageMotion
from tracker.speed_ramp import SpeedRamp

DT = 0.1
BOX = Box(0.0, 0.0, 0.0, 0.3, *BOX_SIZE)


def _models(frames: int = 10, accelerating_only: bool = False) -> tuple[AverageMotion, AverageMotion]:
    """full's moving average (turn frame, alpha 0.6, per second) without and with the speed ramp (the defaults of
    motion.ramp_min_t and motion.ramp_min_accel; ``accelerating_only``: motion.ramp_accelerating_only)."""
    return (AverageMotion(0.6, "turn", 0.5, per_second=True),
            AverageMotion(0.6, "turn", 0.5, per_second=True,
                          ramp=SpeedRamp(frames, 4.0, 1.0, accelerating_only=accelerating_only)))


def _feed(models: tuple[AverageMotion, ...], speeds: np.ndarray) -> list[np.ndarray]:
    """Each model's predicted speed (m/s) for frame k + 1 after the motions of frames 1..k (heading 0.3 rad)."""
    heading = np.array([np.cos(0.3), np.sin(0.3)])
    out = [[] for _ in models]
    for k, speed in enumerate(speeds):
        if k > 0:
            for model, row in zip(models, out, strict=True):
                row.append(float(model.predict(BOX, DT)[:2] @ heading) / DT)
        for model in models:
            model.update(BOX, np.array([*(speed * DT * heading), 0.0, 0.0]), None, None, DT, points=500)
    return [np.array(row) for row in out]


def test_a_constant_acceleration_is_predicted_at_the_speed_it_reaches():
    # 2 m/s, then +3 m/s^2 from frame 5 on: each motion's speed is that of the middle of its interval
    t_mid = (np.arange(40) - 0.5) * DT
    speeds = 2.0 + 3.0 * np.clip(t_mid - 0.5, 0.0, None)
    average, ramp = _feed(_models(), speeds)
    truth = speeds[1:]
    # the average lags the ramp by (alpha / (1 - alpha) + 1) frames: 2.5 x 0.3 m/s
    assert average[-1] - truth[-1] == pytest.approx(-0.75, abs=1e-6)
    # the ramp is exact once its 10 motions lie on the line (the onset's kink takes 10 frames to leave the window)
    np.testing.assert_allclose(ramp[15:], truth[15:], atol=1e-9)


def test_a_ramp_that_ends_is_let_go_within_half_a_window():
    # 2 m/s, +3 m/s^2 from 0.5 s to 2.5 s, then 8 m/s steady: the whole window's line would drive on accelerating
    t_mid = (np.arange(50) - 0.5) * DT
    speeds = 2.0 + 3.0 * np.clip(t_mid - 0.5, 0.0, 2.0)
    average, ramp = _feed(_models(), speeds)
    truth = speeds[1:]
    # frame 26 is the first at 8 m/s (entry 24): the ramp overshoots by at most 0.35 m/s for four frames (the
    # average is 0.6 m/s slow there); from the fifth, the recent half of the window is flat and it is the average's
    assert (ramp[24:30] - truth[24:30]).max() < 0.35
    assert (truth[24:27] - average[24:27]).min() > 0.35
    np.testing.assert_array_equal(ramp[30:], average[30:])


def test_a_braking_ramp_stops_at_zero_and_never_reverses():
    # 8 m/s braking at 4 m/s^2 to a stop at frame 20, then standing
    speeds = np.maximum(8.0 - 4.0 * np.arange(40) * DT, 0.0)
    average, ramp = _feed(_models(), speeds)
    truth = speeds[1:]
    # on the ramp from its 10th motion on, and at the stop, the prediction is the truth (the average: 1 m/s on)
    np.testing.assert_allclose(ramp[9:21], truth[9:21], atol=1e-9)
    assert (average[9:19] - truth[9:19]).min() > 0.9
    # the line runs on below 0 after the stop; the prediction does not (then the average's decay takes over)
    assert ramp.min() >= 0.0
    np.testing.assert_array_equal(ramp[30:], average[30:])


def test_a_steady_track_keeps_the_averages_prediction():
    # 10 m/s with registration noise of 3 cm per frame (0.3 m/s on each registered speed): no line is
    # significant, the prediction is the average's bit for bit
    rng = np.random.default_rng(3)
    speeds = 10.0 + rng.normal(0.0, 0.3, 400)
    average, ramp = _feed(_models(), speeds)
    np.testing.assert_array_equal(ramp, average)


def test_accelerating_only_follows_a_constant_acceleration():
    # as above (2 m/s, +3 m/s^2 from frame 5 on): a rising line is taken as with both directions
    t_mid = (np.arange(40) - 0.5) * DT
    speeds = 2.0 + 3.0 * np.clip(t_mid - 0.5, 0.0, None)
    average, ramp = _feed(_models(accelerating_only=True), speeds)
    truth = speeds[1:]
    assert average[-1] - truth[-1] == pytest.approx(-0.75, abs=1e-6)
    np.testing.assert_allclose(ramp[15:], truth[15:], atol=1e-9)


def test_accelerating_only_leaves_braking_to_the_average():
    # 8 m/s braking at 4 m/s^2 to a stop, then standing; and 12 m/s braking at 8 m/s^2 with registration noise:
    # every prediction is the moving average's, bit for bit (the both-directions ramp follows the braking)
    rng = np.random.default_rng(5)
    for speeds in (np.maximum(8.0 - 4.0 * np.arange(40) * DT, 0.0),
                   np.maximum(12.0 - 8.0 * np.arange(30) * DT, 0.0) + rng.normal(0.0, 0.05, 30)):
        average, ramp = _feed(_models(accelerating_only=True), speeds)
        np.testing.assert_array_equal(ramp, average)
        both = _feed(_models(), speeds)[1]
        assert np.abs(both - average).max() > 0.5


def test_accelerating_only_keeps_a_steady_track_bit_for_bit():
    rng = np.random.default_rng(3)
    speeds = 10.0 + rng.normal(0.0, 0.3, 400)
    average, ramp = _feed(_models(accelerating_only=True), speeds)
    np.testing.assert_array_equal(ramp, average)


def test_noisy_speeds_weaken_the_ramp_and_a_loss_starts_it_afresh():
    line = SpeedRamp(6, 4.0, 1.0)
    for k in range(6):
        line.add(2.0 + 0.3 * k, DT)
    slope, weight = line.ramp()
    assert slope == pytest.approx(3.0) and weight == 1.0
    noisy = SpeedRamp(6, 4.0, 1.0)
    for k, jitter in enumerate([0.0, 0.2, -0.2, 0.2, -0.2, 0.0]):
        noisy.add(2.0 + 0.3 * k + jitter, DT)
    assert 0.0 < noisy.ramp()[1] < 1.0
    # a frame without data (a coasting prediction) breaks the run: the next prediction is the average's
    _, model = _models()
    for k in range(12):
        model.update(BOX, np.array([0.2 + 0.03 * k, 0.0, 0.0, 0.0]), None, None, DT, points=500)
    ramped = model.predict(BOX, DT)
    model.predict(BOX, DT, coasting=1)
    assert model.ramp is not None and model.ramp.ramp() == (0.0, 0.0)
    plain = model.prior.predict(BOX.heading, DT) * DT
    assert ramped[0] > plain[0] + 0.005


def test_an_accelerating_car_is_followed_closer_with_the_ramp():
    # 3 m/s, accelerating at 4 m/s^2 from frame 6 (0.04 m per frame per frame), ~1300 points
    x, step, boxes = 12.0, 0.3, []
    for k in range(30):
        boxes.append(Box(x, 4.0, 0.0, 0.0, *BOX_SIZE))
        step = step + 0.04 if k >= 6 else step
        x += step

    sequence = make_sequence(n_frames=30, seed=1, boxes=boxes)

    def along_errors(changes: dict) -> np.ndarray:
        # the containment check off: it slides a box that falls behind the car onto it (0.06-0.12 m behind then)
        result = track(sequence, boxes[0], 0, len(boxes) - 1,
                       get_preset("full", **{"footprint.containment.min_points": 0, **changes}))
        return np.array([e.box.x - b.x for e, b in zip(result.estimates, boxes, strict=True)])

    plain, ramp = along_errors({}), along_errors({"motion.ramp_frames": 10})
    # full trails the car by 0.12-0.21 m through the ramp (the MP term pulls toward the lagging average); the
    # ramp's prediction takes less than half of that
    assert np.abs(plain[15:]).mean() > 0.12
    assert np.abs(ramp[15:]).mean() < 0.5 * np.abs(plain[15:]).mean()
