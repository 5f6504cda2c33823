"""The CTRV motion model, the height filter and the frame-1 hypotheses against analytic cases."""

from __future__ import annotations

import numpy as np
import pytest

from sot_apps.bench.rear_view import rear_view_sequence
from tracker.config import get_preset
from tracker.first_frame import explained_points, motion_hypotheses
from tracker.geometry import Box, wrap_angle
from tracker.motion_filter import AverageMotion, CTRVFilter, HeightFilter, ctrv_predict_state, travel_heading
from tracker.sotracker import Tracker


def _arc(v: float, w: float, t: np.ndarray, start=(0.0, 0.0, 0.3)) -> np.ndarray:
    """Exact constant-turn poses (x, y, heading) at times t."""
    x0, y0, h0 = start
    h = h0 + w * t
    return np.column_stack([x0 + v / w * (np.sin(h) - np.sin(h0)), y0 + v / w * (np.cos(h0) - np.cos(h)), h])


def test_prediction_uses_elapsed_seconds():
    s = np.array([1.0, 2.0, 0.3, 8.0, 0.25])
    exact = _arc(8.0, 0.25, np.array([0.4]), start=(1.0, 2.0, 0.3))[0]
    one_gap = ctrv_predict_state(s, 0.4)
    steps = s
    for _ in range(4):
        steps = ctrv_predict_state(steps, 0.1)
    np.testing.assert_allclose(one_gap[:3], exact, atol=1e-9)
    np.testing.assert_allclose(steps, one_gap, atol=1e-9)
    straight = ctrv_predict_state(np.array([0.0, 0.0, 0.5, 10.0, 0.0]), 0.4)
    np.testing.assert_allclose(straight[:2], 4.0 * np.array([np.cos(0.5), np.sin(0.5)]), atol=1e-9)


def test_constant_turn_drive_keeps_its_turn_rate_within_5_percent():
    """Noise-free: exact; with 5 cm / 1 deg measurement noise: the turn rate averaged over the steady part
    (the filter is tuned to follow abrupt steering, 3 rad/s^2, so single frames scatter ~15 %)."""
    rng = np.random.default_rng(0)
    v, w, dt = 8.0, 0.3, 0.1
    poses = _arc(v, w, dt * np.arange(60))
    exact = CTRVFilter(*poses[0])
    for k in range(1, 60):
        exact.predict(dt)
        exact.update_heading(poses[k, 2], 0.05)
        exact.update_position(poses[k, :2], 0.1)
    assert abs(exact.turn_rate - w) <= 1e-3 * w and abs(exact.speed - v) <= 1e-3 * v
    f = CTRVFilter(*poses[0])
    rates = []
    for k in range(1, 60):
        f.predict(dt)
        f.update_heading(poses[k, 2] + rng.normal(0.0, 0.02), 0.05)
        f.update_position(poses[k, :2] + rng.normal(0.0, 0.05, 2), 0.1)
        d = poses[k, :2] - poses[k - 1, :2] + rng.normal(0.0, 0.05, 2)
        travel = travel_heading(d, 0.05, 0.02, 0.2)
        f.update_heading(travel[0], travel[1], fold_pi=True, age=0.5 * dt)
        rates.append(f.turn_rate)
    assert abs(np.mean(rates[19:]) - w) <= 0.05 * w, np.mean(rates[19:])
    assert abs(f.speed - v) <= 0.05 * v, f.speed
    assert abs(wrap_angle(f.heading - poses[-1, 2])) < np.radians(1.0)


@pytest.mark.parametrize("along", [False, True])
def test_the_first_motion_seeds_the_prior_along_the_start_heading(along):
    start = Box(10.0, 5.0, 0.0, 0.4, 4.5, 1.8, 1.5)
    motion = AverageMotion(0.6, "turn", 0.5, per_second=True, first_along_heading=along)
    forward, sideways = np.array([np.cos(0.4), np.sin(0.4)]), np.array([-np.sin(0.4), np.cos(0.4)])
    first = np.r_[1.0 * forward + 0.05 * sideways, 0.02, 0.0]   # 1 m ahead, 5 cm sideways in 0.1 s
    assert np.array_equal(motion.update(start, first, None, None, 0.1), first)   # the state keeps its motion
    predicted = motion.predict(start, 0.1)
    assert predicted[:2] @ forward == pytest.approx(1.0)
    assert predicted[:2] @ sideways == pytest.approx(0.0 if along else 0.05, abs=1e-12)
    assert predicted[2] == pytest.approx(0.02)
    second = np.r_[1.1 * forward + 0.05 * sideways, 0.0, 0.0]   # later motions are averaged as they are
    motion.update(start, second, None, None, 0.1)
    expected_sideways = 0.4 * 0.05 + (0.6 * 0.05 if not along else 0.0)
    assert motion.predict(start, 0.1)[:2] @ sideways == pytest.approx(expected_sideways, abs=1e-12)


@pytest.mark.parametrize("max_slip", [0.0, 0.17])
@pytest.mark.parametrize("sign", [1.0, -1.0], ids=["forward", "reversing"])
def test_a_coasting_prediction_moves_within_the_slip_cap_of_the_heading_line(max_slip, sign):
    """The averaged velocity points 36 degrees off the box's heading (a partial view slid sideways as the object
    vanished). A frame with data is predicted on it as it is; a frame without data (coasting) keeps its part along
    the heading and caps the part across at tan(max_slip) x that (max_slip 0: as it is), the turn rate decaying."""
    box = Box(10.0, 5.0, 0.0, 0.4, 4.5, 1.8, 1.5)
    forward, sideways = np.array([np.cos(0.4), np.sin(0.4)]), np.array([-np.sin(0.4), np.cos(0.4)])
    motion = AverageMotion(0.6, "world", 0.5, per_second=True, coast_max_slip=max_slip)
    delta = np.r_[sign * 0.31 * forward + 0.225 * sideways, 0.0, 0.02]     # 0.1 s: 3.1 m/s along, 2.25 across
    motion.update(box, delta, None, None, 0.1)
    held = motion.predict(box, 0.1)
    assert held[:2] @ sideways == pytest.approx(0.225, rel=1e-3)           # with data: as averaged
    coast = motion.predict(box, 0.1, coasting=2)
    assert coast[:2] @ forward == pytest.approx(held[:2] @ forward, abs=1e-12)   # the part along is kept
    across = 0.225 if max_slip == 0 else 0.31 * np.tan(max_slip)
    assert coast[:2] @ sideways == pytest.approx(across, rel=1e-3)
    assert coast[3] == pytest.approx(0.25 * held[3])                     # the turn rate decays as before
    small = AverageMotion(0.6, "world", 0.5, per_second=True, coast_max_slip=max_slip)
    small.update(box, np.r_[0.31 * forward + 0.02 * sideways, 0.0, 0.0], None, None, 0.1)
    assert np.array_equal(small.predict(box, 0.1, coasting=1), small.predict(box, 0.1))   # within the cap


@pytest.mark.parametrize(("across_speed", "capped"), [(2.25, True), (6.0, False)])
def test_a_sideways_speed_beyond_a_slide_is_not_capped(across_speed, capped):
    """With ``coast_max_slide`` 3 m/s the cap applies only where the velocity's part across the heading is at most
    3 m/s (0.3 m per 0.1 s frame: what a vanishing partial view slides); a car driving at 14 m/s 25 degrees off
    the box's heading (6 m/s across) says the box turned off it, and its coast keeps its velocity."""
    box = Box(10.0, 5.0, 0.0, 0.4, 4.5, 1.8, 1.5)
    forward, sideways = np.array([np.cos(0.4), np.sin(0.4)]), np.array([-np.sin(0.4), np.cos(0.4)])
    motion = AverageMotion(0.6, "world", 0.5, per_second=True, coast_max_slip=0.17, coast_max_slide=3.0)
    motion.update(box, np.r_[0.1 * (12.6 * forward + across_speed * sideways), 0.0, 0.0], None, None, 0.1)
    coast = motion.predict(box, 0.1, coasting=1)
    expected = 1.26 * np.tan(0.17) if capped else 0.1 * across_speed
    assert coast[:2] @ sideways == pytest.approx(expected, rel=1e-6)
    assert coast[:2] @ forward == pytest.approx(1.26, rel=1e-6)


@pytest.mark.parametrize(("headings_deg", "capped"), [
    ([23.0, 22.0, 24.0, 23.5, 22.9], True),          # held within 2 degrees of the last: a line to coast along
    ([0.0, 5.0, 10.0, 17.0, 23.0], False),           # swung 23 degrees in five frames (a brake, a turn)
    ([23.0, 23.0, 23.0], False),                     # too few updates to say
    ([179.0, -179.5, 178.5, -178.0, 179.9], True),   # steady across the +-180 degree seam
])
def test_the_slip_cap_applies_only_after_a_steady_heading(headings_deg, capped):
    """With ``coast_steady_frames`` 5 and ``coast_steady_max`` 0.1 rad the coast is capped only when the box's
    heading after each of the last 5 updates (its heading plus the registered turn) lay within 0.1 rad of the
    last one; otherwise the averaged velocity is coasted on as it is (the motion then is a box's turned heading,
    not a sideways slide)."""
    motion = AverageMotion(0.6, "world", 0.5, per_second=True, coast_max_slip=0.17, coast_steady_frames=5,
                           coast_steady_max=0.1)
    headings = np.radians(headings_deg)
    for before, after in zip(np.r_[headings[0], headings[:-1]], headings, strict=True):
        box = Box(10.0, 5.0, 0.0, float(before), 4.5, 1.8, 1.5)
        heading = float(after)
        forward, sideways = np.array([np.cos(heading), np.sin(heading)]), np.array([-np.sin(heading),
                                                                                     np.cos(heading)])
        delta = np.r_[0.31 * forward + 0.225 * sideways, 0.0, float(wrap_angle(after - before))]
        motion.update(box, delta, None, None, 0.1)
    last = Box(10.0, 5.0, 0.0, float(headings[-1]), 4.5, 1.8, 1.5)
    held, coast = motion.predict(last, 0.1), motion.predict(last, 0.1, coasting=1)
    along = float(held[:2] @ forward)
    across = float(coast[:2] @ sideways)
    assert coast[:2] @ forward == pytest.approx(along, abs=1e-12)
    if capped:
        assert abs(across) == pytest.approx(abs(along) * np.tan(0.17), rel=1e-6)
    else:
        assert across == pytest.approx(float(held[:2] @ sideways), abs=1e-12)
        assert abs(across) > 2 * abs(along) * np.tan(0.17)                # ... which the cap would have cut


@pytest.mark.parametrize("points", [0, 15, 200, 5000])
def test_the_first_heading_change_seeds_the_turn_rate_as_far_as_its_points_pin_it(points):
    """motion.first_turn_points n0: the first motion's heading change seeds the averaged turn rate with weight
    n / (n + n0); its translation and the returned motion are untouched; later motions are averaged in full."""
    start = Box(0.0, 0.0, 0.0, 0.0, 4.5, 1.8, 1.5)
    first = np.array([0.3, 0.0, 0.0, 0.3])                      # a partial view rotated 17 deg in frame 1
    plain = AverageMotion(0.6, "turn", 0.5, per_second=True, first_along_heading=True)
    weighted = AverageMotion(0.6, "turn", 0.5, per_second=True, first_along_heading=True, first_turn_points=200)
    assert np.array_equal(weighted.update(start, first.copy(), None, None, 0.1, points), first)
    plain.update(start, first.copy(), None, None, 0.1, points)
    share = points / (points + 200)
    assert weighted.predict(start, 0.1)[3] == pytest.approx(0.3 * share, abs=1e-12)
    assert plain.predict(start, 0.1)[3] == pytest.approx(0.3)
    assert np.linalg.norm(weighted.predict(start, 0.1)[:2]) == pytest.approx(0.3)   # the speed is seeded in full
    turn = np.array([0.3, 0.0, 0.0, 0.05])
    weighted.update(start, turn, None, None, 0.1, 0)                               # later: averaged as they come
    assert weighted.predict(start, 0.1)[3] == pytest.approx(0.6 * 0.3 * share + 0.4 * 0.05, abs=1e-12)


@pytest.mark.parametrize("first_turn", [0.3, -0.3, 0.01])
def test_the_first_heading_change_seeds_the_turn_rate_at_most_at_the_cap(first_turn):
    """motion.first_turn_max: the first motion's heading change seeds the turn rate clipped to +- the cap (rad per
    frame; a per-second prior holds it over dt); a smaller change and the translation are seeded as they are."""
    start = Box(0.0, 0.0, 0.0, 0.0, 4.5, 1.8, 1.5)
    first = np.array([0.3, 0.0, 0.0, first_turn])
    capped = AverageMotion(0.6, "turn", 0.5, per_second=True, first_along_heading=True, first_turn_max=0.03)
    assert np.array_equal(capped.update(start, first.copy(), None, None, 0.1, 15), first)
    assert capped.predict(start, 0.1)[3] == pytest.approx(float(np.clip(first_turn, -0.03, 0.03)), abs=1e-12)
    assert np.linalg.norm(capped.predict(start, 0.1)[:2]) == pytest.approx(0.3)
    capped.update(start, np.array([0.3, 0.0, 0.0, 0.2]), None, None, 0.1, 15)     # later: not capped
    assert capped.predict(start, 0.1)[3] == pytest.approx(0.6 * float(np.clip(first_turn, -0.03, 0.03)) + 0.4 * 0.2)


def test_travel_heading_is_folded_for_a_reversing_vehicle_and_skipped_when_standing():
    f = CTRVFilter(0.0, 0.0, 0.2)
    theta, sigma = travel_heading(np.array([-np.cos(0.25), -np.sin(0.25)]), 0.05, 0.02, 0.2)
    f.update_heading(theta, sigma, fold_pi=True)
    assert 0.2 < f.heading < 0.25  # pulled towards 0.25, not towards 0.25 - pi
    assert travel_heading(np.array([0.05, 0.0]), 0.05, 0.02, 0.2) is None


def test_height_filter_follows_the_road_and_ignores_a_drifting_fit():
    h = HeightFilter(z=0.8, road=0.0, drift_sigma=0.02, fit_sigma=0.15, road_sigma=0.05, offset_gain=0.05)
    for k in range(40):  # the road rises 2 cm per frame, the fit drifts 1 cm per frame upwards on top
        road = 0.02 * k
        z = h.update(0.8 + road + 0.01 * k, road)
    assert abs(z - (0.8 + 0.02 * 39)) < 0.12
    far = HeightFilter(z=0.8, road=None, drift_sigma=0.02, fit_sigma=0.15, road_sigma=0.05, offset_gain=0.05)
    assert abs(far.update(0.9, None) - 0.8) < 0.05  # no road: the fit moves z only slowly


def test_height_filter_offset_from_the_fit_absorbs_a_slowly_growing_road_bias():
    """A far road seen with a bias that grows 10 cm over 30 frames (a car driving away from 47 to 64 m on the
    PandaSet street, docs/tracker-decisions.md) and an unbiased registration z (5 cm noise, seeded): with the offset
    learned from the estimate (gain 0.05) the box follows the road's bias up; learned from the registration (gain
    0.2) it stays."""
    rng = np.random.default_rng(0)
    bias = np.linspace(0.0, 0.10, 30)
    fits = 0.8 + rng.normal(0.0, 0.05, 30)
    last = {}
    for from_fit in (False, True):
        h = HeightFilter(z=0.8, road=0.0, drift_sigma=0.02, fit_sigma=0.15, road_sigma=0.05, offset_gain=0.05,
                         offset_fit_gain=0.2)
        last[from_fit] = np.mean([h.update(fits[k], bias[k], offset_from_fit=from_fit) for k in range(30)][-5:])
    assert last[False] - 0.8 > 0.06       # the road's bias carries the box up
    assert abs(last[True] - 0.8) < 0.035  # the registration's z holds it


def test_first_frame_hypotheses_span_the_heading_and_score_the_points():
    hyps = motion_hypotheses(0.5, 9, 3.0, 1.0)
    assert np.allclose(hyps[0], 0.0) and len(hyps) >= 9
    along = [h[0] * np.cos(0.5) + h[1] * np.sin(0.5) for h in hyps]
    assert min(along) == pytest.approx(-1.0) and max(along) == pytest.approx(3.0)
    assert all(abs(h[0] * -np.sin(0.5) + h[1] * np.cos(0.5)) < 1e-12 for h in hyps)
    pts = np.random.default_rng(0).uniform(-1, 1, (200, 3)) * [2.0, 0.8, 0.6]
    box = Box(0, 0, 0, 0, 4.5, 1.8, 1.5)
    assert explained_points(pts, box, pts, 0.2) == 200
    assert explained_points(pts, box, pts + [5.0, 0, 0], 0.2) == 0


@pytest.mark.parametrize("scene", [0, 1, 2, 3])
def test_straight_drive_seen_only_from_behind_keeps_its_heading_within_2_degrees(scene):
    """The issue's bound, on 4 scenes. Measured on 12 such scenes x 3 seeds (`sot-apps bench rear-view`;
    docs/tracker.md, "First motion along the heading"):
    `full` stays within 1.80 degrees (mean 0.30) since frame 1's motion seeds the prior only along the start
    heading; before that 12 of the 36 runs went above 2 degrees (at most 2.58), the box sliding
    sideways along the face, and this test, on one scene, had passed by luck."""
    frames, boxes = rear_view_sequence(40, seed=scene)
    tracker = Tracker(get_preset("full"))
    tracker.start(frames[0], boxes[0])
    errors = np.array([abs(np.degrees(wrap_angle(tracker.step(f).box.heading - b.heading)))
                       for f, b in zip(frames[1:], boxes[1:], strict=True)])
    assert errors.max() < 2.0, np.round(errors, 2)
    assert errors.mean() < 1.0, np.round(errors, 2)


@pytest.mark.parametrize("scene", [0, 1, 2])
def test_a_gap_of_four_frames_is_predicted_with_the_elapsed_time(scene):
    frames, boxes = rear_view_sequence(20, speed=12.0, seed=scene)
    tracker = Tracker(get_preset("full"))
    tracker.start(frames[0], boxes[0])
    for f in frames[1:8]:
        tracker.step(f)
    est = tracker.step(frames[12])  # 0.5 s later: the box must be 6 m further, not 1.2 m
    heading = boxes[12].heading
    offset = est.box.center[:2] - boxes[12].center[:2]
    along = offset @ [np.cos(heading), np.sin(heading)]
    # the distance travelled over the gap (measured on 12 scenes x 3 seeds: |along| <= 0.04 m, in all <= 0.13 m;
    # before frame 1's motion seeded the prior along the heading, the box slid sideways along the face, up to
    # 0.41 m in all; `sot-apps bench rear-view`, docs/tracker.md "First motion along the heading")
    assert abs(along) < 0.1, offset
    assert np.hypot(*offset) < 0.3, offset


def _ground(n: int, z: float, rng: np.random.Generator) -> np.ndarray:
    """``n`` flat road points at height ``z`` in the 3 m ring around a 4.5 x 1.8 m box at the origin."""
    xy = rng.uniform([-5.0, -3.8], [5.0, 3.8], size=(4 * n, 2))
    ring = xy[(np.abs(xy[:, 0]) > 2.25) | (np.abs(xy[:, 1]) > 0.9)][:n]
    return np.column_stack([ring, np.full(len(ring), z)])


@pytest.mark.parametrize("road_points", [0, 200])
def test_a_road_plane_through_few_ground_points_holds_the_height_weakly(road_points):
    """height.road_points: the road seen through 25 points (a far road) pulls the box less than the road seen
    through 300 (a near one); the near road holds the box in either case, and without the setting both pull alike."""
    from tracker.strategies.height import FilterHeight, road_plane

    rng = np.random.default_rng(0)
    params = get_preset("full", **{"height.road_points": road_points}).height
    box = Box(0.0, 0.0, 0.8, 0.0, 4.5, 1.8, 1.5)
    dense, sparse = _ground(300, 0.0, rng), _ground(25, 0.1, rng)
    assert road_plane(sparse, np.zeros(2), box)[1] == 25
    pulled = {}
    for name, road in (("dense", _ground(300, 0.1, rng)), ("sparse", sparse)):
        height = FilterHeight(params)
        height.start(box, dense)                       # the start: 0.8 m above a road at 0
        prev = box
        for _ in range(20):                            # the fit holds z; the road reads 0.1 m higher
            prev = Box(prev.x, prev.y, prev.z + height.motion(np.zeros(4), prev, road, True)[2], 0.0, 4.5, 1.8, 1.5)
        pulled[name] = prev.z - 0.8
    assert 0.05 < pulled["dense"] < 0.1                # the dense road is followed in either case
    if road_points:
        assert pulled["sparse"] < 0.75 * pulled["dense"]   # sigma x sqrt(200 / 25): the fit holds more
    else:
        assert pulled["sparse"] == pytest.approx(pulled["dense"], abs=0.01)
