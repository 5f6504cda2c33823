"""The profiles that provoke unseen-vehicle failures generate what they claim: checked on the written copies
(the simulated points, per-point labels, ground-truth boxes and sensor poses), not on the list's own figures."""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest

from sot_apps.benchmark.hard_profiles import geometry_ok, hidden_frames, viewing_angle_deg
from sot_apps.benchmark.lists import read_list
from sot_apps.io import open_sequence
from tracker.geometry import points_in_box


def _tracks(bench: Path) -> list[dict]:
    """Per listed tracklet: its entry, per-frame truth boxes, points in the box, own points, sensor x, y."""
    out = []
    entries = json.loads((bench / "benchmark.json").read_text())
    for seg in sorted({e["segment_name"] for e in entries}):
        seq = open_sequence(bench / seg)
        ids = [v["id"] for v in json.loads((bench / seg / "inserted.json").read_text())["vehicles"]]
        sensor = np.array([(f.world_from_ego @ seq.ego_from_lidar)[:2, 3] for f in seq.frames])
        frames = [(seq.points_world(k), np.load(bench / seg / "labels" / f"{k:06d}.npz")["instance"],
                   {a.track_id: a.box for a in seq.annotations[k]}) for k in range(len(seq))]
        for e in (e for e in entries if e["segment_name"] == seg):
            a, b = e["frame_range"]
            i = ids.index(e["id"])
            boxes = [frames[k][2][e["id"]] for k in range(a, b + 1)]
            out.append({"entry": e, "boxes": boxes, "sensor": sensor[a:b + 1],
                        "in_box": np.array([points_in_box(frames[k][0], box).sum()
                                            for k, box in zip(range(a, b + 1), boxes, strict=True)]),
                        "own": np.array([(frames[k][1] == i).sum() for k in range(a, b + 1)])})
    return out


@pytest.fixture(scope="module")
def tracks(hard_benchmark) -> dict[str, list[dict]]:
    by_profile: dict[str, list[dict]] = {}
    for t in _tracks(hard_benchmark):
        by_profile.setdefault(t["entry"]["profile"], []).append(t)
    return by_profile


def test_every_hard_profile_is_listed_and_validates(hard_benchmark, tracks):
    read_list(hard_benchmark / "benchmark.json")  # the schema holds the new fields
    assert set(tracks) == {"far_approach", "passing", "hidden", "oblique"}


def _centres(t) -> np.ndarray:
    return np.array([[b.x, b.y] for b in t["boxes"]])


def test_far_approach_starts_far_and_sparse_and_closes_at_5_to_12_mps(tracks):
    for t in tracks["far_approach"]:
        r = np.hypot(*(_centres(t) - t["sensor"]).T)
        assert r[0] >= 55.0 and t["in_box"][0] <= 30
        closing = (r[0] - r[-1]) / (0.1 * (len(r) - 1))
        assert 5.0 <= closing <= 12.0
        near = np.flatnonzero(r <= 30.0)
        assert t["entry"]["near_frame"] == (int(near[0]) if near.size else None)


def test_hidden_has_no_points_while_hidden_and_points_before_and_after(tracks):
    for t in tracks["hidden"]:
        first, last = t["entry"]["hidden_frames"]
        assert 5 <= last - first + 1 <= 15 and t["entry"]["reappear_frame"] == last + 1
        assert (t["own"][first:last + 1] == 0).all()
        assert t["own"][:first].max() > 0 and t["own"][last + 1:].max() > 0


def test_oblique_is_seen_from_behind_side_with_15_to_120_points(tracks):
    for t in tracks["oblique"]:
        assert 15 <= np.median(t["in_box"]) <= 120
        rel = _centres(t) - t["sensor"]
        view = np.degrees(np.abs(np.angle(np.exp(1j * (np.arctan2(rel[:, 1], rel[:, 0]) -
                                                          np.array([b.heading for b in t["boxes"]]))))))
        assert ((view >= 20.0) & (view <= 70.0)).all()


def test_passing_vehicle_comes_as_near_as_its_lane_offset(tracks):
    """The nearest range is the sensor's distance from the vehicle's path relative to the (moving) sensor, its
    lane offset, up to half a frame's relative travel: the vehicle really drives past."""
    for t in tracks["passing"]:
        rel = _centres(t) - t["sensor"]
        r = np.hypot(*rel.T)
        k = int(np.argmin(r))
        assert 0 < k < len(r) - 1  # nearest in the middle: it comes, passes and leaves
        direction = (rel[k + 1] - rel[k - 1]) / np.linalg.norm(rel[k + 1] - rel[k - 1])
        offset = abs(direction[0] * rel[k, 1] - direction[1] * rel[k, 0])
        half_step = np.linalg.norm(rel[k + 1] - rel[k - 1]) / 4
        assert offset - 1e-6 <= r[k] <= math.hypot(offset, half_step) + 0.1
        assert 4.0 <= r[k] <= 15.0 and t["entry"]["min_range_m"] == pytest.approx(r[k], abs=0.02)


def test_geometry_rules_on_analytic_paths():
    t = np.arange(11) * 0.1
    sensor = np.zeros((11, 3))
    towards = np.stack([60.0 - 8.0 * t, np.full_like(t, 3.0)], axis=1)            # 60 m out, closing at 8 m/s
    away = np.stack([60.0 + 8.0 * t, np.full_like(t, 3.0)], axis=1)
    pos = np.stack([towards, away])
    assert geometry_ok("far_approach", pos, np.full((2, 11), math.pi), sensor, t).tolist() == [True, False]
    assert geometry_ok("far_approach", towards[None], np.full((1, 11), math.pi / 2), sensor, t).tolist() == [False]
    past = np.stack([-5.0 + 10.0 * t, np.full_like(t, 4.0)], axis=1)               # drives past at 4 m
    short = np.stack([5.0 + 10.0 * t, np.full_like(t, 4.0)], axis=1)               # already past
    assert geometry_ok("passing", np.stack([past, short]), np.zeros((2, 11)), sensor, t).tolist() == [True, False]
    diag = np.stack([30.0 + t, 30.0 + t], axis=1)                                    # line of sight at 45 deg
    assert geometry_ok("oblique", diag[None], np.zeros((1, 11)), sensor, t).tolist() == [True]
    assert geometry_ok("oblique", diag[None], np.full((1, 11), math.pi / 4), sensor, t).tolist() == [False]
    assert viewing_angle_deg(np.array([10.0, 0.0]), np.array(math.pi)) == pytest.approx(180.0)


def test_hidden_frames_leave_five_frames_each_side():
    rng = np.random.default_rng(0)
    for n in (15, 20, 40):
        for _ in range(50):
            first, last = hidden_frames(rng, n)
            assert first >= 5 and last <= n - 6 and 5 <= last - first + 1 <= 15
    assert hidden_frames(rng, 14) is None
