"""``benchmark make`` on a small synthetic background: ground truth, placement, determinism, resume, list."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from sot_apps.benchmark.lists import read_list
from sot_apps.io import open_sequence
from sot_apps.objects.motion_profiles import PROFILES
from tracker.geometry import points_in_box, transform_points
from tracker.metrics import bev_corners_batch, bev_intersection_area_batch


def _copies(root: Path) -> list[Path]:
    return sorted(p.parent for p in root.glob("*/inserted.json"))


def test_list_validates_and_has_every_profile(small_benchmark, small_config):
    entries = read_list(small_benchmark / "benchmark.json")  # validated against data_schema/benchmark
    assert len(entries) == small_config["tracklets"]
    assert {t.profile for t in entries} == set(PROFILES)
    n = small_config["frames"][1] - small_config["frames"][0]
    assert all(t.frame_range == (0, n - 1) and t.difficulty in ("easy", "medium", "hard") for t in entries)
    for level in ("easy", "medium", "hard"):
        assert [e.id for e in read_list(small_benchmark / f"{level}.json")] == \
            [e.id for e in entries if e.difficulty == level]
    made = json.loads((small_benchmark / "make.json").read_text())
    assert sum(made["counts"]["profile"].values()) == small_config["tracklets"]


def test_every_box_holds_95_percent_of_its_simulated_points(small_benchmark):
    """A vehicle straddling the scan's seam would be seen at both ends of the sweep (0.1 s apart), as a real
    spinning LiDAR sees it, and no single box could hold both: placement keeps vehicles off the seam, so none is."""
    checked = seams = 0
    for copy in _copies(small_benchmark):
        seq = open_sequence(copy)
        ids = [v["id"] for v in json.loads((copy / "inserted.json").read_text())["vehicles"]]
        for k in range(len(seq)):
            instance = np.load(copy / "labels" / f"{k:06d}.npz")["instance"]
            world = seq.points_world(k)
            times = seq.sweep(k).time_offset_ns
            assert len(instance) == len(world)
            boxes = {a.track_id: a.box for a in seq.annotations[k]}
            for i, vid in enumerate(ids):
                mine = world[instance == i]
                if len(mine) == 0:
                    continue
                if np.ptp(times[instance == i]) > 50_000_000:
                    seams += 1
                    continue
                inside = points_in_box(mine, boxes[vid]).mean()
                assert inside >= 0.95, f"{copy.name} frame {k} {vid}: {inside:.3f} of {len(mine)} points in its box"
                checked += 1
    assert checked > 20 and seams == 0


def test_no_inserted_vehicle_overlaps_a_real_object_or_another_inserted_one(small_benchmark, background):
    real_seq = open_sequence(background)
    for copy in _copies(small_benchmark):
        seq = open_sequence(copy)
        inserted_ids = {v["id"] for v in json.loads((copy / "inserted.json").read_text())["vehicles"]}
        for k in range(len(seq)):
            anns = seq.annotations[k]
            assert {a.track_id for a in anns} - inserted_ids == {a.track_id for a in real_seq.annotations[k]}
            boxes = np.array([a.box.to_array() for a in anns])
            ins = np.array([a.track_id in inserted_ids for a in anns])
            pairs = [(i, j) for i in np.flatnonzero(ins) for j in range(len(anns)) if j != i]
            a = bev_corners_batch(boxes[[i for i, _ in pairs]])
            b = bev_corners_batch(boxes[[j for _, j in pairs]])
            assert np.all(bev_intersection_area_batch(a, b) < 1e-9), f"{copy.name} frame {k}: boxes overlap"


def test_same_seed_same_bytes_and_rerun_resumes(small_benchmark, background, bank, make_small, tmp_path):
    make_small(background, bank, tmp_path / "again")
    files = sorted(p.relative_to(small_benchmark) for p in small_benchmark.rglob("*") if p.is_file())
    assert files == sorted(p.relative_to(tmp_path / "again") for p in (tmp_path / "again").rglob("*") if p.is_file())
    for rel in files:
        if rel.name == "make.json":  # carries the run time
            continue
        assert (small_benchmark / rel).read_bytes() == (tmp_path / "again" / rel).read_bytes(), rel
    stamps = {p: p.stat().st_mtime_ns for p in (tmp_path / "again").rglob("points/*.npz")}
    make_small(background, bank, tmp_path / "again")  # done copies are skipped
    assert stamps == {p: p.stat().st_mtime_ns for p in (tmp_path / "again").rglob("points/*.npz")}
    other = tmp_path / "seed1"
    make_small(background, bank, other, seed=1)
    assert (other / "benchmark.json").read_bytes() != (small_benchmark / "benchmark.json").read_bytes()


def test_inserted_points_sit_where_the_ground_truth_says(small_benchmark):
    """Point counts in the list match the sequences (the difficulty statistic is the sweep's own)."""
    entries = read_list(small_benchmark / "benchmark.json")
    for t in entries:
        seq = open_sequence(small_benchmark / t.segment_name)
        track = seq.tracks()[t.id]
        counts = [int(points_in_box(seq.points_world(k), track.box_at(k)).sum()) for k in range(min(10, len(seq)))]
        assert abs(np.mean(counts) - t.extra["mean_points_first10"]) < 0.01
        centre = track.box_at(0).center
        sensor = transform_points(seq.frames[0].world_from_ego, np.zeros((1, 3)))[0]
        assert 3.0 < np.hypot(*(centre - sensor)[:2]) < 45.0


def test_replicas_stand_in_for_real_tracks_on_their_own_path(background, tmp_path):
    """--replicas: the real car's points are cut and its bank vehicle is simulated on the real path."""
    from sot_apps.benchmark.make import MakeConfig, make_benchmark
    from sot_apps.objects.bank import Bank, entries_from_annotations, write_bank_index

    seq = open_sequence(background)
    tid = sorted(t for t in seq.tracks() if t.startswith("veh_"))[0]
    bank = Bank(tmp_path / "bank", [])
    entries, _ = entries_from_annotations(bank.root, seq, [tid])
    bank.entries = entries
    write_bank_index(bank)
    out = tmp_path / "rep"
    make_benchmark(MakeConfig(str(background), str(bank.root), 0, (0, 6), 0, str(out), replicas=(tid,)), progress=False)
    (entry,) = read_list(out / "benchmark.json")
    assert entry.profile == "replica" and entry.frame_range == (0, 5)
    copy = open_sequence(out / entry.segment_name)
    for k in range(len(copy)):
        ids = {a.track_id for a in copy.annotations[k]}
        assert tid not in ids and entry.id in ids  # the real track is replaced, not doubled
        real_box = seq.tracks()[tid].box_at(k)
        assert np.linalg.norm(copy.tracks()[entry.id].box_at(k).center[:2] - real_box.center[:2]) < 0.5
        instance = np.load(out / entry.segment_name / "labels" / f"{k:06d}.npz")["instance"]
        pts = copy.points_world(k)
        assert points_in_box(pts[instance < 0], real_box).sum() == 0  # no real point of the car is left
        assert (instance == 0).sum() > 50
    # `benchmark realism` pairs the copy with its real track, frame by frame
    from sot_apps.benchmark.realism import format_replicas, replica_counts

    (pair,) = replica_counts(out)
    assert pair.track == tid and len(pair.real) == len(copy) == 6
    for k in range(len(copy)):
        assert pair.real[k] == points_in_box(seq.points_world(k), seq.tracks()[tid].box_at(k)).sum()
        assert pair.copy[k] == points_in_box(copy.points_world(k), copy.tracks()[entry.id].box_at(k)).sum()
    assert f"| {tid[:8]} |" in format_replicas([pair])


def test_realism_curve_and_plot(small_benchmark, tmp_path, capsys):
    from sot_apps.cli.main import main

    png = tmp_path / "curve.png"
    assert main(["benchmark", "realism", str(small_benchmark), "--plot", str(png), "--json", str(tmp_path / "r.json")]) == 0
    out = capsys.readouterr().out
    assert "| range (m) | real vehicles | inserted vehicles |" in out
    doc = json.loads((tmp_path / "r.json").read_text())
    assert sum(b["n"] for b in doc["inserted"]) >= 8 * 6 and sum(b["n"] for b in doc["real"]) > 0
    import cv2

    image = cv2.imread(str(png))
    assert image is not None and image.shape[0] > 300 and image.shape[1] > 600


def test_inserted_vehicles_stand_on_the_road(small_benchmark, background):
    """Every inserted vehicle's box bottom sits on the background's ground under it (within 0.15 m of the lowest
    real point around its centre, where the sweeps have one), and never climbs or drops between frames by more
    than the road grade allows over the distance it moved."""
    from sot_apps.benchmark.background import MAX_GRADE

    real = open_sequence(background)   # the background's own sweeps: no inserted vehicle in them
    ground = np.vstack([real.points_world(k) for k in range(len(real))])
    checked = 0
    for copy in _copies(small_benchmark):
        seq = open_sequence(copy)
        for vid, track in seq.tracks().items():
            if not vid.startswith("ins_"):
                continue
            boxes = [track.box_at(k) for k in range(len(seq))]
            z = np.array([b.z - b.height / 2 for b in boxes])
            xy = np.array([[b.x, b.y] for b in boxes])
            assert np.all(np.abs(np.diff(z)) <= MAX_GRADE * np.hypot(*np.diff(xy, axis=0).T) + 0.02 + 1e-6), vid
            for b, bottom in zip(boxes, z, strict=True):
                near = ground[np.hypot(ground[:, 0] - b.x, ground[:, 1] - b.y) < 0.5 * b.width]
                if len(near) >= 5:
                    assert abs(bottom - near[:, 2].min()) < 0.15, f"{copy.name} {vid}: {bottom:.2f} vs {near[:, 2].min():.2f}"
                    checked += 1
    assert checked > 10
