"""The containment check (tracker/containment.py): analytic cases of the slide, and a car seen broadside whose start
box lies behind it, tracked with and without the check."""

from __future__ import annotations

import numpy as np
import pytest
from test_reacquire_clusters import _scene
from tracker_synthetic import BOX_SIZE, SyntheticSequence, car_points, ground_points

from sot_apps.io.tracks import TRACKER_FLAGS
from tracker import Box, get_preset, track
from tracker.config import ContainmentConfig, TrackerConfig
from tracker.containment import containment_shift
from tracker.frames import LidarFrame
from tracker.geometry import rotation_z

ON = ContainmentConfig(min_points=30)
BOX = Box(10.0, 5.0, 1.0, 0.0, 4.5, 1.8, 1.5)


def _side(rng: np.random.Generator, x0: float, x1: float, n: int = 400) -> np.ndarray:
    """Points on the near side (y = -0.9 in the box frame) of an object from x0 to x1 along the box's length,
    z over its height above the floor band."""
    side = np.c_[rng.uniform(x0, x1, n), np.full(n, -0.9), rng.uniform(-0.4, 0.75, n)]
    return side + [BOX.x, BOX.y, BOX.z]


@pytest.mark.parametrize("heading", [0.0, 1.2, -2.4])
def test_points_running_out_of_the_front_move_the_box_by_the_spill(heading):
    """The object's side runs from 0.7 m inside the box's rear end to 0.5 m beyond its front: the box moves forward
    by as much as the points spill (they then fit), whatever its heading; mirrored, backwards."""
    rng = np.random.default_rng(0)
    box = Box(BOX.x, BOX.y, BOX.z, heading, *BOX.size)
    local = _side(rng, -2.25 + 0.7, 2.25 + 0.5) - BOX.center
    points = _turned(local, heading)
    beyond = local[:, 0].max() - 2.25
    assert 0.45 < beyond < 0.5
    assert containment_shift(points, box, ON, 3.0) == pytest.approx(beyond, abs=1e-9)
    assert containment_shift(_flip_along(points, box), box, ON, -3.0) == pytest.approx(-beyond, abs=1e-9)


def test_no_slide_against_the_motion_nor_for_a_still_object():
    """The box falls behind the way the object moves; points beyond its other end are something else."""
    rng = np.random.default_rng(4)
    points = _side(rng, -2.25 + 0.7, 2.25 + 0.5)
    assert containment_shift(points, BOX, ON, -3.0) == 0.0
    assert containment_shift(points, BOX, ON, 0.5) == 0.0
    assert containment_shift(points, BOX, ON, 1.0) > 0.45


def test_either_way_slides_against_the_motion_too():
    """While a re-locked track settles (``settle_frames``), where its candidate put the box along the object is a
    guess: points spilling out of the end the object moves away from move the box back, as far as they spill."""
    rng = np.random.default_rng(4)
    points = _side(rng, -2.25 - 0.4, 2.25 - 0.7)
    assert containment_shift(points, BOX, ON, 3.0) == 0.0
    assert containment_shift(points, BOX, ON, 3.0, either_way=True) == pytest.approx(-0.4, abs=0.02)
    assert containment_shift(points, BOX, ON, 0.5, either_way=True) == 0.0     # still: no slide either way


def test_no_slide_for_a_box_turned_away_from_its_object():
    """A box 15 degrees off the object's side spills its points at one end too: sliding it along its own length
    would move it sideways. The points line up sharpest 15 degrees off: no slide."""
    rng = np.random.default_rng(5)
    turned = _turned(_side(rng, -2.25 + 0.7, 2.25 + 0.5) - BOX.center, 0.26)
    assert containment_shift(turned, BOX, ON, 3.0) == 0.0
    assert containment_shift(turned, Box(BOX.x, BOX.y, BOX.z, 0.26, *BOX.size), ON, 3.0) > 0.45


def _turned(local: np.ndarray, angle: float) -> np.ndarray:
    """Points given relative to ``BOX``'s centre, turned by ``angle`` about it (world)."""
    return local @ rotation_z(angle).T + BOX.center


def _flip_along(points: np.ndarray, box: Box) -> np.ndarray:
    """``points`` mirrored along ``box``'s length (about the plane through its centre across it)."""
    direction = np.array([np.cos(box.heading), np.sin(box.heading), 0.0])
    along = (points - box.center) @ direction
    return points - 2.0 * along[:, None] * direction


def test_the_slide_is_at_most_the_empty_room_at_the_other_end():
    """The points run 0.5 m beyond the front, but the box's rear end holds points 0.2 m from its face: 0.2 m."""
    rng = np.random.default_rng(1)
    shift = containment_shift(_side(rng, -2.25 + 0.2, 2.25 + 0.5), BOX, ON, 3.0)
    assert shift == pytest.approx(0.2, abs=0.02)


def test_no_slide_when_the_points_fit_spill_both_ways_break_off_or_are_few():
    rng = np.random.default_rng(2)
    assert containment_shift(_side(rng, -2.0, 2.0), BOX, ON, 3.0) == 0.0                    # they fit
    assert containment_shift(_side(rng, -2.6, 2.6), BOX, ON, 3.0) == 0.0                    # both ends
    gap = np.vstack([_side(rng, -1.5, 2.1), _side(rng, 2.6, 3.5)])                     # another object 0.5 m on
    assert containment_shift(gap, BOX, ON, 3.0) == 0.0
    assert containment_shift(_side(rng, -1.5, 2.6, n=20), BOX, ON, 3.0) == 0.0              # sparse
    assert containment_shift(_side(rng, -1.5, 2.6), BOX, ContainmentConfig(), 3.0) == 0.0   # off
    assert containment_shift(np.zeros((0, 3)), BOX, ON, 3.0) == 0.0
    assert containment_shift(_side(rng, -1.5, 2.3), BOX, ON, 3.0) == 0.0                    # below min_shift


def test_road_points_along_the_floor_and_points_beside_the_box_do_not_count():
    """Road left by the ground removal runs on under the box's bottom; a wall runs beside it: neither moves it."""
    rng = np.random.default_rng(3)
    body = _side(rng, -1.8, 2.0)
    road = np.c_[rng.uniform(-1.8, 6.0, 400), rng.uniform(-0.9, 0.9, 400), np.full(400, -0.7)] + BOX.center
    wall = np.c_[rng.uniform(-1.8, 6.0, 400), np.full(400, -1.3), rng.uniform(-0.5, 0.7, 400)] + BOX.center
    assert containment_shift(np.vstack([body, road, wall]), BOX, ON, 3.0) == 0.0
    assert containment_shift(np.vstack([body, _side(rng, 2.0, 2.4)]), BOX, ON, 3.0) > 0.1   # but the body's own do


def test_settings_are_checked():
    for bad in ({"gap": 0.0}, {"max_shift": -1.0}, {"max_turn": 0.0}, {"min_points": -1}, {"min_speed": -1.0},
                {"margin": -0.1}, {"floor": -0.1}, {"shape": "object"}, {"settle_frames": -1}):
        with pytest.raises(ValueError, match="footprint.containment"):
            ContainmentConfig(**bad)
    config = TrackerConfig.from_dict({"footprint": {"containment": {"min_points": 40, "shape": "world"}}})
    assert config.footprint.containment == ContainmentConfig(min_points=40, shape="world")


def _broadside(n_frames: int = 30, speed: float = 0.28) -> SyntheticSequence:
    """A car driving along +x at 2.8 m/s, 15 m to the side of a still sensor: its side faces the sensor, only the
    ends of its side pin it along its length."""
    rng = np.random.default_rng(0)
    boxes = [Box(-4.0 + speed * k, 15.0, 0.0, 0.0, *BOX_SIZE) for k in range(n_frames)]
    frames = []
    for k, box in enumerate(boxes):
        points = np.vstack([car_points(rng, box, np.zeros(3)), ground_points(rng, box.center[:2], 10.0)])
        points += rng.normal(0.0, 0.01, points.shape)
        frames.append(LidarFrame(index=k, timestamp_ns=1_000_000_000 + k * 100_000_000,
                                 points_ego=points.astype(np.float32), world_from_ego=np.eye(4)))
    return SyntheticSequence(frames, boxes)


def test_a_start_box_behind_a_broadside_car_catches_up_with_it():
    """The start box lies 0.6 m behind the car. Its shape is the car without its front 0.6 m, so the registration
    holds the box 0.6 m behind for good. With the check (the shape staying where it lies in the world) the box
    slides 0.5 m at frame 1 (``max_shift``) and holds the car within 0.12 m from frame 2 on (a slide below
    ``min_shift`` = 0.1 m is none)."""
    seq = _broadside()
    start = Box(seq.boxes[0].x - 0.6, *seq.boxes[0].center[1:], 0.0, *BOX_SIZE)

    def errors(**settings) -> tuple[np.ndarray, int]:
        result = track(seq, start, 0, len(seq) - 1, get_preset("full", **settings))
        slid = sum("contained" in e.flags for e in result.estimates)
        return np.array([b.x - g.x for b, g in zip(result.boxes, seq.boxes, strict=True)])[1:], slid

    off, none = errors(**{"footprint.containment.min_points": 0})
    world, slid = errors(**{"footprint.containment.min_points": 30, "footprint.containment.shape": "world"})
    assert none == 0 and slid >= 1 and "contained" in TRACKER_FLAGS   # a flag motion-export's --invalid-flags takes
    assert np.all(off < -0.5)
    assert -0.13 < world[0] < -0.09
    assert np.all(np.abs(world[1:]) < 0.12)


def test_a_relocked_box_ahead_of_a_car_that_emerges_from_behind_an_occluder_slides_back_onto_it():
    """A car at 5 m/s is hidden for 6 frames and speeds up to 9 m/s meanwhile; it re-appears ahead of the
    prediction, front first from behind an occluder (1 m of it seen, then 0.9 m more each frame). The search's
    candidate, centred on the part seen, puts the box ahead of the car, and the track's shape starts from that part:
    the registration leaves the box 0.35 m ahead 4 frames later, 0.18 m 7 frames later. Settling
    (``settle_frames=10``: the box slides either way for 10 frames after the re-lock) moves it back onto the car as
    its rear comes into view."""
    xs = 6.0 + np.concatenate([[0.0], np.cumsum([0.5] * 8 + [0.9] * 23)])
    boxes = [Box(float(x), 4.0, 0.0, 0.0, *BOX_SIZE) for x in xs]
    back = 14
    edge = boxes[back].x + 0.5 * BOX_SIZE[0] - 1.0          # the occluder's edge (x, world)
    front = {k: float(np.clip(boxes[k].x + 0.5 * BOX_SIZE[0] - edge, 0.0, BOX_SIZE[0])) for k in range(back, 32)}
    seq = _scene(boxes, 0, hidden=range(8, back), front_seen=front)

    def along_errors(settle: int) -> tuple[np.ndarray, tuple[str, ...]]:
        result = track(seq, boxes[0], 0, len(seq) - 1, get_preset("full", seed=0, **{
            "footprint.containment.settle_frames": settle}))
        flags = tuple(f for e in result.estimates[back:] for f in e.flags)
        return np.array([e.box.x - b.x for e, b in zip(result.estimates, boxes, strict=True)]), flags

    off, off_flags = along_errors(0)
    settled, flags = along_errors(10)
    assert "reacquired" in off_flags and "reacquired" in flags
    assert np.all(np.abs(off[:9]) < 0.1) and np.all(settled[:back] == off[:back])   # the same until it re-appears
    assert off[back + 4: back + 8].min() > 0.15                 # still ahead without settling
    assert np.abs(settled[back + 4:]).max() < 0.1               # on the car from 4 frames after re-appearing
