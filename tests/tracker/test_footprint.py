"""The footprint check (tracker/footprint.py): a dense object's points turn a box whose heading they contradict."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
from tracker_synthetic import BOX_SIZE, car_points, make_sequence, trajectory

from tracker import Tracker, get_preset, offline, refine_offline
from tracker.config import FootprintConfig
from tracker.footprint import FootprintCheck, fit_heading, held_turned
from tracker.geometry import Box, rotation_z, wrap_angle
from tracker.offline import footprint_carried_back, gather_frame_points
from tracker.sotracker import TrackResult

# the check on every dense frame, not only after a re-lock (as in `full`), with a gain synthetic cars reach
EVERY_FRAME = {"footprint.min_points": 150, "footprint.min_gain": 1.1, "footprint.after_relock": 0}


@pytest.mark.parametrize("heading, start_offset, sensor", [
    (0.3, 0.2, (0.0, 0.0, 1.7)),       # seen from behind-side: back and one side
    (-2.4, -0.25, (20.0, -8.0, 1.7)),  # seen from the front-side
    (1.2, 0.15, (12.0, 30.0, 1.7)),    # side on: one long side and the roof
])
def test_the_fitted_heading_is_the_vehicles_own_from_a_search_started_off_it(heading, start_offset, sensor):
    rng = np.random.default_rng(7)
    box = Box(12.0, 4.0, 0.0, heading, *BOX_SIZE)
    points = car_points(rng, box, np.array(sensor))
    points += rng.normal(0.0, 0.02, points.shape)
    assert len(points) > 300
    fit = fit_heading(points, heading + start_offset, search_range=0.35)
    assert abs(np.degrees(wrap_angle(fit.heading - heading))) < 2.0   # 0.1 m bins over a 4.5 m side: ~1.3 deg
    assert fit.interior and fit.gain > 1.1   # flat, evenly sampled faces: real scans line up sharper
    # a start farther off than the range: the best is its end, no peak
    beyond = fit_heading(points, heading + 0.6, 0.35)
    assert abs(wrap_angle(beyond.heading - heading - 0.6)) <= 0.35 + 1e-9 and not beyond.interior
    # searched from the truth: no gain
    assert fit_heading(points, heading, 0.35).gain < 1.05


def _object_frame(points: np.ndarray, box: Box) -> np.ndarray:
    return (points - box.center) @ rotation_z(box.heading)


def test_the_check_turns_the_box_after_agreeing_dense_frames_in_a_row_once_and_only_if_the_shape_was_built_turned():
    rng = np.random.default_rng(3)
    truth = Box(10.0, 3.0, 0.0, 0.5, *BOX_SIZE)
    sensor = np.array([0.0, 0.0, 1.7])
    dense = [car_points(rng, truth, sensor) for _ in range(6)]
    sparse = dense[0][:20]
    wrong = 0.5 + 0.25
    box = Box(truth.x, truth.y, truth.z, wrong, *BOX_SIZE)
    built_turned = _object_frame(car_points(rng, truth, sensor), box)     # the real car, seen from the wrong box
    built_right = _object_frame(car_points(rng, box, sensor), box)        # a car that lines up with the box

    def check(frames: int = 3, min_points: int = 150) -> FootprintCheck:
        return FootprintCheck(FootprintConfig(min_points=min_points, min_offset=0.1, frames=frames, agreement=0.05,
                                              search_range=0.35, min_gain=1.1))

    first = check()
    assert first.test(dense[0], wrong, built_turned) is None
    assert first.test(dense[1], wrong, built_turned) is None
    assert first.test(sparse, wrong, built_turned) is None          # a sparse frame ends the run
    assert first.test(dense[2], wrong, built_turned) is None
    assert first.test(dense[3], wrong, built_turned) is None
    turned = first.test(dense[4], wrong, built_turned)
    assert turned is not None and abs(np.degrees(turned - 0.5)) < 2.0
    assert first.test(dense[5], wrong, built_turned) is None        # once per (re)start
    # the same votes against a shape that lines up with the box: the registration's own error, no turn
    second = check(frames=1)
    assert all(second.test(d, wrong, built_right) is None for d in dense)
    # a box already within min_offset is never turned
    assert all(check(frames=1).test(d, 0.5 + 0.05, built_turned) is None for d in dense)
    # off
    assert check(frames=1, min_points=0).test(dense[0], wrong, built_turned) is None


def _turn_box_against_shape(tracker: Tracker, delta: float) -> None:
    """The state a shape aggregated in a wrong frame leaves (the box on something else, or a sparse partial view,
    while the shape grew): the box turned by ``delta`` and the shape and sub-shape turned back by it, so that both
    still lie on the points in the world."""
    b = tracker.box
    tracker.box = Box(b.x, b.y, b.z, float(wrap_angle(b.heading + delta)), b.length, b.width, b.height)
    tracker.shape.turn(-delta)
    tracker.subshape.turn(-delta)


@pytest.mark.parametrize("delta_deg", [12.0, -15.0])
def test_a_dense_track_whose_shape_was_built_turned_is_turned_back_to_the_vehicles_heading(delta_deg):
    """Without the check the registration holds the box where the shape puts it (more than half of delta off for
    good); with it the box is back within 2 degrees three dense frames later, and stays there."""
    boxes = trajectory(24, speed=0.8, yaw_rate=0.0, turn_after=99)
    sequence = make_sequence(24, seed=4, boxes=boxes)

    def heading_errors(**overrides) -> tuple[np.ndarray, list[int]]:
        tracker = Tracker(get_preset("full", seed=0, **overrides))
        tracker.start(sequence.lidar_frame(0), boxes[0])
        errors, turned = [], []
        for k in range(1, 24):
            estimate = tracker.step(sequence.lidar_frame(k))
            if "footprint" in estimate.flags:
                turned.append(k)
            if k == 5:
                _turn_box_against_shape(tracker, np.radians(delta_deg))
            errors.append(abs(np.degrees(wrap_angle(tracker.box.heading - boxes[k].heading))))
        return np.array(errors), turned

    off, never = heading_errors(**{"footprint.min_points": 0})
    assert off[:4].max() < 2.0 and off[5:].min() > abs(delta_deg) / 2 and never == []
    on, turned = heading_errors(**EVERY_FRAME)
    assert np.array_equal(on[:5], off[:5])            # nothing changes before
    assert turned == [8]                              # frames 6, 7, 8 dense and agreeing: turned at the third
    assert on[7:].max() < 2.0


def test_a_box_turned_together_with_its_shape_is_left_to_the_registration():
    """Box and shape turned together (the registration's own error; the shape still lines up with the box): the
    registration turns them back within a few frames and nothing else turns the box."""
    boxes = trajectory(16, speed=0.8, yaw_rate=0.0, turn_after=99)
    sequence = make_sequence(16, seed=4, boxes=boxes)
    tracker = Tracker(get_preset("full", seed=0, **EVERY_FRAME))
    tracker.start(sequence.lidar_frame(0), boxes[0])
    flags, errors = [], []
    for k in range(1, 16):
        flags += tracker.step(sequence.lidar_frame(k)).flags
        if k == 5:
            b = tracker.box
            tracker.box = Box(b.x, b.y, b.z, float(wrap_angle(b.heading + np.radians(12.0))), b.length, b.width,
                              b.height)
        errors.append(abs(np.degrees(wrap_angle(tracker.box.heading - boxes[k].heading))))
    assert "footprint" not in flags
    assert errors[4] > 10.0 and max(errors[-5:]) < 2.0


def test_after_relock_the_check_runs_only_on_a_relocked_tracks_first_measured_frames():
    """``after_relock`` > 0: a track that was never re-locked is never tested; a re-locked one on its first
    ``after_relock`` frames only (a sparse frame uses one up too)."""
    rng = np.random.default_rng(3)
    truth = Box(10.0, 3.0, 0.0, 0.5, *BOX_SIZE)
    sensor = np.array([0.0, 0.0, 1.7])
    dense = car_points(rng, truth, sensor)
    box = Box(truth.x, truth.y, truth.z, 0.75, *BOX_SIZE)
    built_turned = _object_frame(car_points(rng, truth, sensor), box)
    config = FootprintConfig(min_points=150, min_offset=0.1, frames=1, agreement=0.05, search_range=0.35,
                             min_gain=1.1, after_relock=2)
    assert FootprintCheck(config).turn(dense, box, built_turned) is None             # never re-locked
    turned = FootprintCheck(config, relocked=True).turn(dense, box, built_turned)
    assert turned is not None and abs(np.degrees(turned + 0.25)) < 2.0
    late = FootprintCheck(config, relocked=True)
    assert late.turn(dense[:20], box, built_turned) is None and late.turn(dense[:20], box, built_turned) is None
    assert late.turn(dense, box, built_turned) is None                                # its window has passed
    every = dataclasses.replace(config, after_relock=0)                              # 0: every frame
    assert FootprintCheck(every).turn(dense, box, built_turned) is not None
    with pytest.raises(ValueError, match="after_relock"):
        FootprintConfig(after_relock=-1)


@pytest.mark.parametrize("relock_turned_deg", [12.0, -15.0])
def test_a_track_relocked_at_a_wrong_heading_is_turned_back_only_with_the_check_after_relock(relock_turned_deg):
    """A hidden car's coast turns its box; the re-lock restarts the track there, so the new shape is built turned
    and the registration holds the wrong heading. With the check after a re-lock the box is back within 2 degrees
    three dense frames later; an unrelocked track with a turned shape (the case the check in every frame would
    take) is left alone. (``min_gain`` 1.02: this synthetic car's restarted one-frame shape lines up only 1.04-1.10
    times as sharply turned, where the real hidden car's did 2.4-2.6 times; its points vote at 1.4-1.7.)"""
    from tracker.strategies.reacquire import Relock

    frames = 16
    boxes = trajectory(frames, speed=0.8, yaw_rate=0.0, turn_after=99)
    sequence = make_sequence(frames, seed=4, boxes=boxes)
    after = {"footprint.min_points": 150, "footprint.min_gain": 1.02, "footprint.after_relock": 10}

    def heading_errors(overrides: dict) -> tuple[np.ndarray, list[int]]:
        tracker = Tracker(get_preset("full", seed=0, **overrides))
        tracker.start(sequence.lidar_frame(0), boxes[0])
        errors, turned = [], []
        for k in range(1, frames):
            if k == 5:   # re-locked on the car, at the coast's heading
                b = tracker.box
                tracker.box = Box(b.x, b.y, b.z, float(wrap_angle(b.heading + np.radians(relock_turned_deg))),
                                  b.length, b.width, b.height)
                estimate = tracker._relock(sequence.lidar_frame(k), Relock(boxes[k].center[:2], np.array([8.0, 0.0])),
                                           True, 0.0)
            else:
                estimate = tracker.step(sequence.lidar_frame(k))
            turned += [k] if "footprint" in estimate.flags else []
            errors.append(abs(np.degrees(wrap_angle(tracker.box.heading - boxes[k].heading))))
        return np.array(errors), turned

    off, never = heading_errors({"footprint.min_points": 0})
    assert never == [] and off[5:].min() > abs(relock_turned_deg) / 2        # held at the wrong heading
    on, turned = heading_errors(after)
    assert turned == [8] and on[7:].max() < 2.0                               # frames 6, 7, 8 vote
    _, _, result = _track_with_turned_shape(after)
    assert all(e.turn == 0.0 for e in result.estimates)                       # never re-locked: no check


def test_a_frame_was_held_turned_when_its_dense_points_line_up_nearer_the_turned_heading():
    rng = np.random.default_rng(5)
    truth = Box(10.0, 3.0, 0.0, 0.5, *BOX_SIZE)
    points = car_points(rng, truth, np.array([0.0, 0.0, 1.7]))
    config = FootprintConfig(min_points=150)
    assert held_turned(points, 0.5 + 0.2, -0.2, config)        # its box 0.2 off: the turn brings it home
    assert held_turned(points, 0.5 + 0.15, -0.2, config)       # partly
    assert not held_turned(points, 0.5, -0.2, config)          # its box right: the turn would take it off
    assert not held_turned(points, 0.5 - 0.2, -0.2, config)    # off the other way
    assert not held_turned(points[:100], 0.5 + 0.2, -0.2, config)   # too few points to say


def _track_with_turned_shape(overrides: dict, frames: int = 16, delta_deg: float = 12.0):
    boxes = trajectory(frames, speed=0.8, yaw_rate=0.0, turn_after=99)
    sequence = make_sequence(frames, seed=4, boxes=boxes)
    config = get_preset("full", seed=0, **overrides)
    tracker = Tracker(config)
    estimates = [tracker.start(sequence.lidar_frame(0), boxes[0])]
    for k in range(1, frames):
        estimates.append(tracker.step(sequence.lidar_frame(k)))
        if k == 5:   # frames 6 and 7 are held turned with the shape; the check turns the box at frame 8
            _turn_box_against_shape(tracker, np.radians(delta_deg))
    return sequence, boxes, TrackResult(estimates, boxes[0].size, tracker.shape_points(), config)


def _heading_errors(estimates, boxes) -> np.ndarray:
    return np.array([abs(np.degrees(wrap_angle(e.box.heading - b.heading))) for e, b in zip(estimates, boxes, strict=True)])


@pytest.mark.parametrize("delta_deg", [12.0, -15.0])
def test_offline_carries_a_footprint_turn_back_over_exactly_the_frames_held_turned_with_it(delta_deg):
    sequence, boxes, result = _track_with_turned_shape(EVERY_FRAME, delta_deg=delta_deg)
    turns = {e.frame: e.turn for e in result.estimates if e.turn != 0.0}
    assert list(turns) == [8] and abs(np.degrees(turns[8]) + delta_deg) < 2.0   # the turn undoes the wrong shape
    online = _heading_errors(result.estimates, boxes)
    assert online[6:8].min() > abs(delta_deg) - 2.0 and online[:6].max() < 2.0
    carried = footprint_carried_back(result, result.config)
    after = _heading_errors(carried.estimates, boxes)
    assert after.max() < 2.0                                              # frames 6, 7 turned back ...
    assert all(a is b for a, b in zip(result.estimates[:6] + result.estimates[8:],
                                      carried.estimates[:6] + carried.estimates[8:], strict=True))   # ... and only they
    # every earlier frame held turned: carried back to the start box, never onto it
    held_from_start = TrackResult([result.estimates[0]] + [
        dataclasses.replace(e, box=dataclasses.replace(e.box, heading=float(e.box.heading - turns[8])))
        for e in result.estimates[1:6]] + result.estimates[6:], result.size, result.shape, result.config)
    assert _heading_errors(footprint_carried_back(held_from_start, result.config).estimates, boxes).max() < 2.0
    # the offline solve from the carried states: every frame within 1 degree; without the carry it starts from
    # the turn's kink
    refined = refine_offline(sequence, result)
    assert _heading_errors(refined.estimates, boxes).max() < 1.0
    kept = refine_offline(sequence, result, result.config.updated({"footprint.carry_back": False}))
    assert not np.array_equal([e.box.heading for e in kept.estimates], [e.box.heading for e in refined.estimates])


def test_offline_with_a_carried_turn_is_the_same_from_a_source_or_from_the_points_a_pass_gathered(monkeypatch):
    """A tracking pass gathers each frame's points around its online box while it tracks and solves from them
    (sot_apps.tracking); tracking alone reads the source: the carried boxes must not change which points (here the
    car stands alone, so the turned regions would hold the same points: the boxes gathered around are checked)."""
    sequence, _, result = _track_with_turned_shape(EVERY_FRAME)
    assert any(e.turn != 0.0 for e in result.estimates)
    config = result.config
    gathered = gather_frame_points(sequence, result, config, config.refinement.offline)
    around = []

    def spy(source, track, *args, **kwargs):
        around.append([e.box for e in track.estimates])
        return gather_frame_points(source, track, *args, **kwargs)

    monkeypatch.setattr(offline, "gather_frame_points", spy)
    alone, passed = refine_offline(sequence, result), refine_offline(None, result, points=gathered)
    assert around == [[e.box for e in result.estimates]]   # once, around the online boxes
    assert [e.box for e in alone.estimates] == [e.box for e in passed.estimates]
    assert np.array_equal(alone.shape, passed.shape)
