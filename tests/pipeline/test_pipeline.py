"""The pipeline end to end on two tiny synthetic sequences x 3 objects: every output, resume, executors, failures."""

from __future__ import annotations

import hashlib
import json
from pathlib import Path

import numpy as np
import pytest

from sot_apps.pipeline import stages as stage_module
from sot_apps.pipeline.config import PipelineConfig
from sot_apps.pipeline.executors import ExecutorSpec
from sot_apps.pipeline.runner import run_pipeline

from .conftest import output_checksums, pipeline_doc

OBJECTS = ("veh_000", "veh_001", "veh_002")


def _sha(path: Path) -> str:
    return hashlib.sha256(path.read_bytes()).hexdigest()


def test_every_output_of_two_sequences_by_three_objects(reference_run, tiny_worlds):
    import pyarrow.parquet as pq
    from mcap.reader import make_reader

    from sot_apps.io import open_sequence
    from sot_apps.io.tracks import read_track
    from tracker import refine_offline
    from tracker.config import get_preset
    from tracker.sotracker import track as track_api

    result, sums = reference_run
    out = result.out
    assert result.failed == []
    assert json.loads((out / "failures.json").read_text()) == {"failures": []}
    names = [s.name for s in result.plan.sequences]
    assert names == ["synth_s4", "synth_s5"]
    for name, world in zip(names, tiny_worlds, strict=True):
        seq = open_sequence(world)
        gt = seq.tracks()
        for obj in OBJECTS:
            header, track = read_track(out / name / "tracks" / obj)
            shape = track.shape_points
            assert track.object_id == obj and track.frames.tolist() == list(range(6))
            assert len(shape) > 0
            # the pipeline's track is the tracker API's result from the annotated start box, refined offline
            # (the track stage's default mode for data generation)
            direct = track_api(seq, gt[obj].box_at(0), 0, 5, get_preset("full"))
            direct = refine_offline(seq, direct, direct.config)
            assert header.config["mode"] == "offline"
            assert np.allclose(track.states,
                               [[e.state.x, e.state.y, e.state.z, e.state.heading] for e in direct.estimates])
            assert track.num_points.tolist() == [e.num_points for e in direct.estimates]
            assert np.allclose(shape, direct.shape)
        # motion export: MCAP readable by the mcap library, parquet rows for the three objects, dense npz
        with open(out / name / "motion.mcap", "rb") as handle:
            topics = {channel.topic for _, channel, _ in make_reader(handle).iter_messages()}
        assert topics, "MCAP has no messages"
        table = pq.read_table(out / name / "motion.parquet").to_pydict()
        assert sorted(set(table["track_id"])) == list(OBJECTS)
        with np.load(out / name / "motion.npz") as npz:
            assert len(npz.files) > 0
        # flow: one KITTI PNG per pair and the three objects in the instance mapping
        cam = out / name / "flow" / "front_camera"
        assert sorted(p.name for p in (cam / "flow_occ").glob("*.png")) == [f"{k:06d}.png" for k in range(5)]
        stats = json.loads((cam / "stats.json").read_text())
        assert [i["object_id"] for i in stats["instances"]] == list(OBJECTS)
    # bank: one surfel mesh per tracked object
    index = json.loads((out / "bank" / "index.json").read_text())
    assert sorted(e["id"] for e in index["entries"]) == sorted(f"{n}__{o}" for n in names for o in OBJECTS)
    for e in index["entries"]:
        assert (out / "bank" / e["mesh"]).is_file()
    # simulated scans at 20 m and 40 m: the farther vehicle gets fewer points
    scans = sorted((out / "scans").iterdir())
    assert [p.name.split("__r")[1] for p in scans] == ["20m", "40m"]
    counts = [sum(b["num_points"] for b in json.loads((p / "boxes.json").read_text())["boxes"]) for p in scans]
    assert counts[0] > counts[1] > 0
    # manifest: every unit with checksums that match the files
    manifest = json.loads((out / "manifest.json").read_text())
    units = {u["key"]: u for u in manifest["stages"]}
    assert {f"track/{n}/{o}" for n in names for o in OBJECTS} <= set(units)
    assert {"bank/synth_s4", "motion/synth_s5", "flow/synth_s4/front_camera"} <= set(units)
    checked = 0
    for u in units.values():
        assert u["status"] == "done"
        for rel, checksum in u.get("outputs", {}).items():
            assert _sha(out / rel) == checksum
            checked += 1
    assert checked >= len(sums) - 2   # every output except failures.json and bank/index.json is checksummed
    assert "numpy" in manifest["versions"]


def test_interrupted_run_resumes_without_redoing_finished_objects(reference_run, tiny_worlds, tmp_path, monkeypatch):
    _, reference_sums = reference_run
    out = tmp_path / "out"
    config = PipelineConfig.from_json(pipeline_doc(tiny_worlds, out))
    original = stage_module.write_object
    calls: list[str] = []

    def interrupt_after_three(out, plan, track, digest):
        if len(calls) == 3:
            raise KeyboardInterrupt   # Ctrl-C while the fourth object is being written
        calls.append(plan.key)
        return original(out, plan, track, digest)

    monkeypatch.setattr(stage_module, "write_object", interrupt_after_three)
    with pytest.raises(KeyboardInterrupt):
        run_pipeline(config, ExecutorSpec("inline"), progress=False)
    assert calls == ["synth_s4/veh_000", "synth_s4/veh_001", "synth_s4/veh_002"]
    assert not (out / "manifest.json").exists()
    assert not (out / "synth_s5" / "tracks").exists()
    finished = {p: p.stat().st_mtime_ns for p in sorted((out / "synth_s4" / "tracks").rglob("*")) if p.is_file()}
    assert len(finished) == 3 * 3   # track.json, shape.ply, shape_growth.json of each finished object
    leftovers = [p for p in out.rglob("*") if ".tmp" in p.name]
    assert leftovers == []

    rerun: list[str] = []

    def counting(out, plan, track, digest):
        rerun.append(plan.key)
        return original(out, plan, track, digest)

    monkeypatch.setattr(stage_module, "write_object", counting)
    result = run_pipeline(config, ExecutorSpec("inline"), progress=False)
    assert rerun == ["synth_s5/veh_000", "synth_s5/veh_001", "synth_s5/veh_002"]
    assert [u.status for u in result.by_stage("track")] == ["cached"] * 3 + ["done"] * 3
    assert {p: p.stat().st_mtime_ns for p in finished} == finished
    assert result.failed == []
    assert output_checksums(out) == reference_sums

    # a third run finds everything finished
    again = run_pipeline(config, ExecutorSpec("inline"), progress=False)
    assert {u.status for u in again.units} == {"cached"}
    assert output_checksums(out) == reference_sums

    # other code (e.g. an upgraded tracker) does not reuse the markers: every unit runs again
    from sot_apps.pipeline import runner as runner_module

    monkeypatch.setattr(runner_module, "code_digest", lambda: "0123456789abcdef")
    upgraded = run_pipeline(config, ExecutorSpec("inline"), progress=False)
    assert {u.status for u in upgraded.units} == {"done"}
    assert output_checksums(out) == reference_sums


def test_local_processes_give_the_same_outputs(reference_run, tiny_worlds, tmp_path):
    _, reference_sums = reference_run
    out = tmp_path / "out"
    config = PipelineConfig.from_json(pipeline_doc(tiny_worlds, out))
    result = run_pipeline(config, ExecutorSpec("local", workers=2), progress=False)
    assert result.failed == []
    assert output_checksums(out) == reference_sums


@pytest.mark.slow
def test_dask_local_cluster_gives_the_same_outputs(reference_run, tiny_worlds, tmp_path):
    _, reference_sums = reference_run
    out = tmp_path / "out"
    config = PipelineConfig.from_json(pipeline_doc(tiny_worlds, out))
    result = run_pipeline(config, ExecutorSpec("dask", workers=2), progress=False)
    assert result.failed == []
    assert output_checksums(out) == reference_sums


def test_object_without_points_fails_while_the_others_finish(tiny_worlds, tmp_path, capsys):
    from sot_apps.cli.main import main
    from sot_apps.io import open_sequence

    world = tiny_worlds[0]
    gt = open_sequence(world).tracks()
    boxes = []
    for obj in ("veh_000", "veh_001"):
        b = gt[obj].box_at(0)
        boxes.append({"id": obj, "frame": 0, "box": {"x": b.x, "y": b.y, "z": b.z, "heading": b.heading,
                                                      "length": b.length, "width": b.width, "height": b.height}})
    boxes.insert(1, {"id": "empty", "frame": 0, "box": {"x": 150.0, "y": -150.0, "z": 1.0, "heading": 0.0,
                                                         "length": 4.5, "width": 1.9, "height": 1.6}})
    doc = {"out": "out", "sequences": [{"path": str(world), "objects": {"from": "boxes", "boxes": boxes}}],
           "stages": {"flow": {"enabled": False}, "scans": {"enabled": False}, "bank": {"min_points": 0}}}
    path = tmp_path / "pipeline.json"
    path.write_text(json.dumps(doc))
    code = main(["run", str(path), "--quiet"])
    printed = capsys.readouterr().out
    assert code == 1
    assert "FAILED track/synth_s4/empty" in printed
    out = tmp_path / "out"
    failures = json.loads((out / "failures.json").read_text())["failures"]
    assert [(f["stage"], f["sequence"], f["object"]) for f in failures] == [("track", "synth_s4", "empty")]
    assert "0 LiDAR points in the initial box" in failures[0]["error"]
    assert sorted(p.name for p in (out / "synth_s4" / "tracks").iterdir()) == ["veh_000", "veh_001"]
    import pyarrow.parquet as pq

    assert sorted(set(pq.read_table(out / "synth_s4" / "motion.parquet").to_pydict()["track_id"])) == ["veh_000", "veh_001"]
    bank = json.loads((out / "bank" / "index.json").read_text())
    assert sorted(e["source"]["object_id"] for e in bank["entries"]) == ["veh_000", "veh_001"]


def test_bench_counts_the_object_frames_and_reads_each_sweep_once(tiny_worlds, tmp_path):
    """`sot-apps bench pipeline` measures what it says: frames tracked after each start, per configuration; the
    two objects share one pass (each of the 4 sweeps read once) and the CPU breakdown adds up to the tasks' CPU."""
    from sot_apps.bench.pipeline import PARTS, format_table, measure
    from sot_apps.pipeline.config import ObjectSource, PipelineConfig, SequenceConfig, Stages, TrackStage

    config = PipelineConfig(str(tmp_path / "out"), (SequenceConfig(str(tiny_worlds[0]), objects=ObjectSource(
        "annotations", max_objects=2)),), Stages(track=TrackStage(max_frames=3)))
    rows = measure(config, [("inline", 1, None)])
    assert [(r["objects"], r["failed"], r["object_frames"], r["sweeps_read"]) for r in rows] == [(2, 0, 6, 4)]
    r = rows[0]
    assert r["executor"] == "in process" and r["object_frames_per_s"] > 0 and r["speedup"] == 1.0
    assert r["cpu_breakdown_s"]["step"] > 0 and r["cpu_breakdown_s"]["refine"] > 0   # offline: refined
    assert abs(sum(r["cpu_breakdown_s"].values()) - r["cpu_s"]) < 0.05 + 0.01 * len(PARTS)
    assert "| 2 | 6 |" in format_table(rows)


def test_annotated_object_starts_at_its_first_box_with_enough_points(tiny_worlds, tmp_path):
    """stages.track.start = first_with_points: the track starts at the first annotated frame whose box the
    tracker finds min_init_points points in; first_annotated keeps frame 0 (and then fails)."""
    from sot_apps.io import open_sequence
    from sot_apps.io.tracks import read_track
    from tracker.config import get_preset
    from tracker.sotracker import Tracker

    seq = open_sequence(tiny_worlds[0])
    counts = {}
    for obj in ("veh_000", "veh_001", "veh_002"):
        gt = seq.tracks()[obj]
        counts[obj] = [Tracker(get_preset("full")).start(seq.lidar_frame(k), gt.box_at(k)).num_points for k in range(5)]
    # an object and a threshold that frame 0 misses but a later frame (not the last) reaches
    choices = [(obj, k, c[k]) for obj, c in counts.items() for k in range(1, 5) if c[k] > max(c[:k])]
    assert choices, counts
    obj, expected, threshold = choices[0]
    doc = {"out": str(tmp_path / "out"), "sequences": [{"path": str(tiny_worlds[0]),
                                                         "objects": {"from": "annotations", "track_ids": [obj]}}],
           "stages": {"track": {"min_init_points": threshold, "mode": "online"}, "bank": {"enabled": False},
                      "motion": {"enabled": False}, "flow": {"enabled": False}, "scans": {"enabled": False}}}
    result = run_pipeline(PipelineConfig.from_json(doc), ExecutorSpec("inline"), progress=False)
    assert result.failed == []
    header, track = read_track(tmp_path / "out" / "synth_s4" / "tracks" / obj)
    assert header.start_frame == expected and track.frames[0] == expected
    assert track.num_points[0] == threshold

    doc["out"] = str(tmp_path / "strict")
    doc["stages"]["track"]["start"] = "first_annotated"
    strict = run_pipeline(PipelineConfig.from_json(doc), ExecutorSpec("inline"), progress=False)
    assert [u.key for u in strict.failed] == [f"track/synth_s4/{obj}"]


def test_objects_from_a_detections_file_follow_the_documented_rule(tiny_worlds, tmp_path):
    """Seed frame = the file's first frame; score >= min_score; highest score first; ids det<frame>_<index>
    unless given; every track runs to the end of the range."""
    from sot_apps.io import open_sequence
    from sot_apps.pipeline.plan import make_plan

    seq = open_sequence(tiny_worlds[0])
    gt = seq.tracks()

    def det(obj, k, score, **extra):
        b = gt[obj].box_at(k)
        return {"x": b.x, "y": b.y, "z": b.z, "heading": b.heading, "length": b.length, "width": b.width,
                "height": b.height, "score": score, **extra}

    dets = {"frames": [{"frame": 2, "boxes": [det("veh_000", 2, 0.9)]},     # later frame: not a seed
                       {"frame": 1, "boxes": [det("veh_000", 1, 0.4), det("veh_001", 1, 0.95, id="car_a"),
                                              det("veh_002", 1, 0.7)]}]}
    (tmp_path / "dets.json").write_text(json.dumps(dets))
    doc = {"out": "out", "sequences": [{"path": str(tiny_worlds[0]), "frames": [0, 4],
                                        "objects": {"from": "detections", "path": "dets.json", "min_score": 0.5}}]}
    (tmp_path / "p.json").write_text(json.dumps(doc))
    from sot_apps.pipeline.config import load_config

    plan = make_plan(load_config(tmp_path / "p.json"))
    objects = plan.objects
    assert [o.object_id for o in objects] == ["car_a", "det0001_02"]
    assert [(o.start, o.end) for o in objects] == [(1, 4), (1, 4)]
    b = gt["veh_002"].box_at(1)
    assert objects[1].init_box == b and objects[1].annotated == ()
