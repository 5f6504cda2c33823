"""Placement: swept boxes, the raster start search against the point test, and planned paths clear of real
objects and of each other in space and time (every instant of every frame's sweep window)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from sot_apps.benchmark import placement
from sot_apps.benchmark.deps import read_bank
from sot_apps.benchmark.make import MakeConfig, _context, plan_copies, range_bands
from sot_apps.io import open_sequence
from sot_apps.objects.motion_profiles import MotionSpec, integrate_motion, sample_motion
from tracker.geometry import Box, points_in_box
from tracker.metrics import bev_corners_batch, bev_intersection_area_batch


def test_swept_box_of_a_straight_run_is_the_box_stretched_by_the_window():
    path = integrate_motion(MotionSpec("constant_speed", 20.0), 1.0, placement.STEP_S)
    window = np.arange(30, 41)[None]  # 0.30 s .. 0.40 s
    (x, y, h, length, width), = placement.swept_boxes(path.states(), window, 4.0, 2.0)
    assert length == pytest.approx(4.0 + 20.0 * 0.1) and width == pytest.approx(2.0)
    assert x == pytest.approx(20.0 * 0.35) and y == pytest.approx(0.0) and h == pytest.approx(0.0)


def test_swept_box_holds_every_pose_of_a_turning_window():
    path = integrate_motion(sample_motion("u_turn", np.random.default_rng(0), 6.0), 6.0, placement.STEP_S)
    states = path.states()
    window = np.arange(0, len(states) - 10, 7)[:, None] + np.arange(11)[None]
    boxes = placement.swept_boxes(states, window, 4.5, 1.9)
    corners = np.array([[1, 1], [1, -1], [-1, -1], [-1, 1]]) * [4.5 / 2, 1.9 / 2]
    for (x, y, h, length, width), idx in zip(boxes, window, strict=True):
        xyh = states[idx]
        pts = placement._rigid(corners[None], xyh[:, 0:1], xyh[:, 1:2], xyh[:, 2:3]).reshape(-1, 2)
        box = Box(x, y, 0.0, h, length + 1e-6, width + 1e-6, 1.0)
        assert points_in_box(np.column_stack([pts, np.zeros(len(pts))]), box).all()


def test_range_bands():
    assert range_bands((5.0, 80.0), (17.0, 40.0)) == [(5.0, 17.0), (17.0, 40.0), (40.0, 80.0)]
    assert range_bands((6.0, 30.0), (17.0, 40.0)) == [(6.0, 17.0), (17.0, 30.0)]
    assert range_bands((6.0, 30.0), ()) == [(6.0, 30.0)]


def test_start_search_by_cell_offsets_agrees_with_the_point_test(background, bank, small_config, monkeypatch):
    """Every start the raster search returns passes the point-by-point ground test, and it finds them all."""
    monkeypatch.setattr(placement, "MAX_STARTS", 10 ** 9)
    seq = open_sequence(background)
    config = MakeConfig(str(background), str(bank), 1, small_config["frames"], 0, "unused",
                        range_m=small_config["range_m"])
    ctx = _context(seq, list(range(*small_config["frames"])), config)
    rng = np.random.default_rng(0)
    size = (4.5, 1.8, 1.5)
    for speed, heading in ((3.0, 0.0), (9.0, math.pi), (5.0, 0.7)):
        path, times_ns = placement._path(ctx, MotionSpec("constant_speed", speed))
        fp = placement._footprint(path.states(), placement._window_index(ctx, times_ns), size, ctx.margin)
        starts = placement._starts(ctx, fp, heading, (0.0, 1e9), rng)
        probe = np.union1d(rng.choice(len(ctx._start_xy), 400, replace=False), starts[:50])
        xy = ctx._start_xy[probe]
        pts = placement._rigid(fp.points[None], xy[:, None, None, 0], xy[:, None, None, 1], heading).reshape(-1, 2)
        coarse = placement._rigid(fp.coarse[None], xy[:, None, None, 0], xy[:, None, None, 1], heading).reshape(-1, 2)
        n = len(probe)
        ok = ~ctx.ground.blocked_at(pts).reshape(n, -1).any(axis=1) & \
            (ctx.ground.free(pts).reshape(n, -1).mean(axis=1) >= placement.MIN_GROUND_FRACTION)
        r, c, inside = ctx.ground.index(coarse)  # the search's coarse pre-test (a heuristic): mostly ground,
        coarse_ok = (ctx.ground.free(coarse).reshape(n, -1).mean(axis=1) >= 0.75) & \
            ~(inside & ctx._bad[r, c]).reshape(n, -1).any(axis=1)  # and no never-free cell
        found = np.isin(probe, starts)
        assert ok[found].all()
        assert np.array_equal(found, ok & coarse_ok)
        assert starts.size  # the synthetic road has room for all three


def _window_boxes(vehicle, t_end: int, window_ns: int) -> np.ndarray:
    times = np.arange(t_end - window_ns, t_end + 1, 10_000_000)
    s = vehicle.states_at(times)
    return np.array([[x, y, z, h, *vehicle.size] for x, y, z, h in s])


def test_planned_paths_never_meet_real_objects_or_each_other_in_space_time(background, bank):
    """A crowded plan (16 tracklets in one copy) on the synthetic background: at every frame, the true boxes of
    any two inserted vehicles at ANY two instants of the frame's sweep window do not intersect, nor does any
    inserted box of the window intersect a real annotated box of that frame."""
    seq = open_sequence(background)
    config = MakeConfig(str(background), str(bank), 16, (0, 6), 5, "unused", per_copy=16, range_m=(6.0, 40.0))
    plans = plan_copies(seq, read_bank(bank), config)
    assert sum(len(p.vehicles) for p in plans) >= 16
    window = int(np.median(np.diff([f.timestamp_ns for f in seq.frames])))
    checked = 0
    for plan in plans:
        for k in range(6):
            t_k = seq.frames[k].timestamp_ns
            per = [_window_boxes(v, t_k, window) for v in plan.vehicles]
            real = np.array([a.box.to_array() for a in seq.annotations[k]]).reshape(-1, 7)
            for i, a in enumerate(per):
                others = [b for j, b in enumerate(per) if j != i] + [real]
                b = np.vstack(others)
                pa = np.repeat(a, len(b), axis=0)
                pb = np.tile(b, (len(a), 1))
                area = bev_intersection_area_batch(bev_corners_batch(pa), bev_corners_batch(pb))
                assert np.all(area < 1e-9), f"{plan.name} frame {k}: {plan.vehicles[i].id} meets another box"
                checked += len(pa)
    assert checked > 10_000


def test_a_box_across_the_scan_seam_is_refused():
    from types import SimpleNamespace

    ctx = SimpleNamespace(seam_deg=-90.0, sensor_xyh=np.array([[0.0, 0.0, 0.3]]))
    seam = math.radians(-90.0) + 0.3

    def box(angle: float, dist: float = 10.0) -> np.ndarray:
        return np.array([[dist * math.cos(angle), dist * math.sin(angle), 0.0, 0.0, 4.5, 1.9, 1.5]])

    assert placement._on_seam(ctx, box(seam))
    assert placement._on_seam(ctx, box(seam + 0.1))      # 1 m off the ray: the 4.5 m box still crosses it
    assert not placement._on_seam(ctx, box(seam + 0.4))
    assert not placement._on_seam(ctx, box(seam + math.pi))  # the opposite direction is no seam


def test_occluder_falls_back_to_a_parked_car_on_the_line_of_sight(background, bank, monkeypatch):
    """Where no driving occluder fits (here every moving candidate is refused, as on a busy street with no free
    lane for a 20 m swept path), the occluder is a parked car that still stands on the sensor-target line of
    sight at the middle frame, clear of the target."""
    seq = open_sequence(background)
    config = MakeConfig(str(background), str(bank), 1, (0, 6), 1, "unused", range_m=(10.0, 30.0))
    ctx = _context(seq, list(range(6)), config)
    entry = read_bank(bank).entries[0]
    size = (4.7, 2.0, 1.6)
    rng = np.random.default_rng(5)
    target = None
    for _ in range(5):
        target = placement.place_vehicle(ctx, rng, "ins_t", entry.id, "Car", size, "constant_speed")
        if target is not None:
            break
    assert target is not None
    exact = placement._exact_ok
    monkeypatch.setattr(placement, "_exact_ok",
                        lambda c, boxes: bool(np.ptp(boxes[:, 0]) < 1e-9 and np.ptp(boxes[:, 1]) < 1e-9)
                        and exact(c, boxes))
    occ = placement.place_occluder(ctx, rng, target, "occ_t", entry.id, "Car", size)
    assert occ is not None and occ.motion.speed0 == 0.0 and not occ.listed and occ.occluder_of == "ins_t"
    mid = len(ctx.frame_times_ns) // 2
    t_mid = int(ctx.frame_times_ns[mid])
    s, p = ctx.sensor_xyh[mid, :2], target.states_at(t_mid)[:2]
    o = occ.states_at(t_mid)
    assert np.ptp(occ.states[:, :2], axis=0).max() < 1e-9               # parked for the whole tracklet
    u = (p - s) / np.linalg.norm(p - s)
    d = o[:2] - s
    along, across = float(np.dot(d, u)), float(abs(u[0] * d[1] - u[1] * d[0]))
    assert 0.2 * np.linalg.norm(p - s) < along < 0.85 * np.linalg.norm(p - s) and across < 1.0


def test_ground_profile_keeps_a_real_slope_and_drops_what_no_road_does():
    """A 5 % climb at 1 m per frame is kept exactly; a 1.3 m spike at the first frame and a 14.8 m one in the
    middle (a roof's or a wall top's height under part of the footprint) leave at most a grade step's trace."""
    step = np.full(39, 1.0)
    slope = 0.05 * np.arange(40)
    assert np.allclose(placement.ground_profile(slope, step), slope)
    raw = slope.copy()
    raw[0] += 1.3
    raw[20:22] += 14.8
    z = placement.ground_profile(raw, step)
    assert np.abs(z - slope).max() <= 0.2 + 1e-9
    assert np.abs(z - slope)[3:19].max() < 1e-9 and np.abs(z - slope)[24:].max() < 1e-9
    assert np.all(np.abs(np.diff(z)) <= placement.MAX_GRADE * step + 0.02 + 1e-12)
    standing = placement.ground_profile(np.array([0.4, -0.2, -0.2, -0.2]), np.zeros(3))  # parked: no step at all
    assert np.allclose(standing, [-0.18, -0.2, -0.2, -0.2])


def _ground_map_of(xyz: np.ndarray, root):
    """The ground map of one sweep (ego frame = world frame)."""
    from sot_apps.benchmark.background import build_ground_map
    from sot_apps.io.sequence import FrameInfo, Sequence, Sweep

    sweep = Sweep(np.asarray(xyz, dtype=np.float32))
    seq = Sequence(id="s", root=root, format="test", frames=[FrameInfo(0, 0, np.eye(4), None)],
                   load_sweep=lambda k: sweep)
    return build_ground_map(seq, [0], stride=1)


def test_ground_where_no_point_fell_is_the_road_not_a_roof(tmp_path):
    """A flat road at z = 0 with a hole (no points: an occluded patch) beside a canopy at 6 m: the hole's cells
    nearest the canopy are road, 0 m up (they used to take the canopy's 6 m)."""
    g = np.mgrid[-20:20:0.2, -20:20:0.2].reshape(2, -1).T
    hole = (np.abs(g[:, 0] - 8.0) < 2.0) & (np.abs(g[:, 1]) < 2.0)
    canopy = (g[:, 0] >= 10.0) & (g[:, 0] < 13.0) & (np.abs(g[:, 1]) < 2.0)
    road = g[~hole & ~canopy]
    xyz = np.vstack([np.column_stack([road, np.zeros(len(road))]),
                     np.column_stack([g[canopy], np.full(canopy.sum(), 6.0)])])
    ground = _ground_map_of(xyz, tmp_path)
    assert ground.blocked_at(np.array([[11.5, 0.0]]))[0]  # the canopy is no ground
    near_canopy = np.array([[9.8, 0.0], [9.8, 1.5], [9.8, -1.5], [8.0, 0.0], [6.2, 0.0]])
    assert np.allclose(ground.z(near_canopy), 0.0)
    assert np.allclose(ground.z(np.array([[11.5, 0.0]])), 0.0)


def test_far_sparse_road_takes_the_surface_not_one_low_cell(tmp_path):
    """Far out the rings leave lone cells with points: a footprint there stands on the road surface around it (the
    blocks' median), not on whichever lone cell is nearest; here the nearest is 0.45 m low (a stray return)."""
    rng = np.random.default_rng(0)
    near = np.mgrid[-10:10:0.2, -10:10:0.2].reshape(2, -1).T          # a dense road around the sensor
    rings = np.column_stack([rng.uniform(30, 60, 300), rng.uniform(-15, 15, 300)])   # lone far returns
    xy = np.vstack([near, rings])
    z = np.zeros(len(xy))
    xy = np.vstack([xy, [[45.3, 0.3]]])
    z = np.r_[z, -0.45]
    ground = _ground_map_of(np.column_stack([xy, z]), tmp_path)
    around = np.array([[45.3 + dx, 0.3 + dy] for dx in (-1.0, -0.5, 0.5, 1.0) for dy in (-0.7, 0.0, 0.7)])
    assert np.abs(ground.z(around)).max() < 0.1
