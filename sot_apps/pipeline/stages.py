"""The units of work of each stage, as top-level (picklable) functions run by the executors.

Every unit writes its outputs through the atomic writers, then its completion marker (``OUT/.done``)
listing the outputs' sha256 checksums; a unit whose marker is valid is skipped on a rerun.
"""

from __future__ import annotations

import dataclasses
import json
import math
import shutil
import time
from pathlib import Path

import numpy as np

from ..tracking import ObjectRequest, ObjectTrack, TrackingFailed, write_shape_growth, write_track_result
from ..tracking import track_objects as track_objects_pass
from .config import BankStage, FlowStage, MotionStage, TrackStage
from .manifest import DoneMarker
from .plan import ObjectPlan, open_cached

__all__ = ["TrackingFailed", "track_objects", "write_object", "bank_sequence", "motion_sequence", "flow_camera",
           "simulate_scene", "track_dir", "scene_name", "MOTION_EVAL_FILE"]


def track_dir(out: str | Path, sequence: str, object_id: str) -> Path:
    return Path(out) / sequence / "tracks" / object_id


def _files_under(directory: Path) -> list[Path]:
    return sorted(p for p in directory.rglob("*") if p.is_file())


# ---------------------------------------------------------------------------------------------- track

def track_objects(out: str, plans: list[ObjectPlan], stage: TrackStage, digests: dict[str, str]) -> dict:
    """Track a chunk of one sequence's objects in one pass over its sweeps (:func:`sot_apps.tracking.track_objects`:
    each sweep read and grounded once) and write each object as it finishes:
    ``OUT/<seq>/tracks/<object>/{track.json, shape.ply, shape_growth.json}`` and its completion marker
    (``digests[object_id]``). Returns per object its result or error (``TrackingFailed: ...`` when it had too few
    LiDAR points to start or follow) and where the chunk's time went (CPU seconds)."""
    from tracker import get_preset

    t0, cpu0 = time.perf_counter(), time.thread_time()
    first = plans[0]
    seq = open_cached(first.sequence_path, first.format)
    config = get_preset(stage.preset, **dict(stage.overrides or {}))
    detections = None
    if first.detections:
        from ..io.detections import read_sequence_detections

        detections = read_sequence_detections(first.detections, seq)
    by_id = {p.object_id: p for p in plans}
    requests = [ObjectRequest(p.object_id, p.init_box, p.start, p.end,
                              p.annotated if stage.start == "first_with_points" else (), stage.max_frames)
                for p in plans]
    written: dict[str, dict] = {}
    write_seconds = [0.0]

    def write(track: ObjectTrack) -> None:
        if track.error is None:
            cpu = time.thread_time()
            written[track.object_id] = write_object(out, by_id[track.object_id], track, digests[track.object_id])
            write_seconds[0] += time.thread_time() - cpu

    tracks, times = track_objects_pass(seq, requests, config, stage.mode, stage.lag, detections, stage.min_init_points,
                                       shape_growth=True, on_done=write)
    objects = []
    for t in tracks:
        plan = by_id[t.object_id]
        if t.error is None:
            objects.append({"object": t.object_id, "ok": True, "cpu_s": round(t.seconds, 4),
                            "result": written[t.object_id]})
        else:
            error = f"TrackingFailed: {plan.key}: {t.error}" if t.lacks_points else t.error
            objects.append({"object": t.object_id, "ok": False, "cpu_s": round(t.seconds, 4), "error": error})
    cpu = time.thread_time() - cpu0
    breakdown = times.to_json() | {"write_s": round(write_seconds[0], 4), "cpu_s": round(cpu, 4),
                                   "wall_s": round(time.perf_counter() - t0, 4)}
    breakdown["overhead_s"] = round(cpu - times.read - times.ground - times.step - times.refine - write_seconds[0], 4)
    return {"sequence": first.sequence, "objects": objects, "times": breakdown}


def write_object(out: str, plan: ObjectPlan, track: ObjectTrack, digest: str) -> dict:
    """One tracked object's outputs and completion marker; returns its summary for the manifest."""
    result = track.result
    directory = track_dir(out, plan.sequence, plan.object_id)
    # Per-frame time_ms is left out (it differs run to run): pipeline outputs are reproducible byte for byte;
    # the unit's total time is in the manifest.
    write_track_result(directory, open_cached(plan.sequence_path, plan.format), result, plan.object_id,
                       track.init_box, plan.label, with_time_ms=False)
    growth_path = write_shape_growth(directory, track.growth)
    qualities = [float(np.clip(e.quality, 0.0, 1.0)) for e in result.estimates]
    DoneMarker(Path(out), f"track/{plan.key}").mark(digest, [directory / "track.json", directory / "shape.ply",
                                                             growth_path],
                                                    extra={"frames": len(qualities)})
    return {"sequence": plan.sequence, "object": plan.object_id, "frames": len(qualities),
            "tracked_frames": len(qualities) - 1, "seconds": round(track.seconds, 3),
            "mean_quality": round(float(np.mean(qualities)), 4), "shape_points": int(len(result.shape))}


# ----------------------------------------------------------------------------------------------- bank

def bank_sequence(out: str, sequence: str, object_ids: list[str], stage: BankStage, digest: str) -> dict:
    """Bank entries (surfel meshes) from one sequence's tracked shapes; the index is written by the runner."""
    from ..io.tracks import read_track
    from ..objects.bank import entry_from_points

    bank_root = Path(out) / "bank"
    entries, skipped, outputs = [], [], []
    for object_id in object_ids:
        directory = track_dir(out, sequence, object_id)
        track, shape = read_track(directory)
        quality = float(np.mean([r.quality for r in track.frames])) if track.frames else 0.0
        if len(shape) < stage.min_points or quality < stage.min_quality:
            skipped.append({"object": object_id, "shape_points": int(len(shape)), "quality": round(quality, 4)})
            continue
        size = (track.size.length, track.size.width, track.size.height)
        source = {"kind": "track", "sequence": track.sequence, "object_id": object_id,
                  "track": str(Path(sequence) / "tracks" / object_id)}
        entry = entry_from_points(bank_root, f"{sequence}__{object_id}", shape, source, quality, label=track.label,
                                  mirror=stage.mirror, size=size)
        entry.build_seconds = None   # keep index.json reproducible
        entries.append(entry.to_json())
        outputs += [bank_root / entry.mesh, bank_root / entry.points]
    DoneMarker(Path(out), f"bank/{sequence}").mark(digest, outputs, extra={"entries": entries, "skipped": skipped})
    return {"sequence": sequence, "entries": entries, "skipped": skipped}


# --------------------------------------------------------------------------------------------- motion

MOTION_EVAL_FILE = "motion_eval.json"
MOTION_EVAL_HORIZON = 30    # frames after each track's start

def motion_sequence(out: str, sequence: str, path: str, format: str | None, object_ids: list[str], stage: MotionStage,
                    digest: str) -> dict:
    """``OUT/<seq>/motion.mcap`` (+ ``motion.parquet``, ``motion.npz``) from the sequence's tracks, and, when the
    sequence is annotated, ``OUT/<seq>/motion_eval.json``: the export's error against the annotations
    (:func:`sot_apps.evaluation.motion.evaluate_motion`), which the report draws."""
    from ..evaluation.motion import evaluate_motion
    from ..io.atomic import write_text
    from ..motion_export.export import export_motion
    from ..motion_export.sources import tracks_from_dirs

    seq = open_cached(path, format)
    root = Path(out) / sequence
    dirs = [track_dir(out, sequence, o) for o in object_ids]
    tracks = tracks_from_dirs(dirs, seq)
    for t in tracks:   # relative sources keep the MCAP independent of where OUT lives
        t.source = str(Path(t.source).relative_to(Path(out)))
    outputs = {"mcap": root / "motion.mcap"}
    if stage.parquet:
        outputs["parquet"] = root / "motion.parquet"
    if stage.npz:
        outputs["npz"] = root / "motion.npz"
    result = export_motion(seq, tracks, outputs["mcap"], parquet=outputs.get("parquet"), npz=outputs.get("npz"),
                           with_points=stage.with_points, progress=False)
    annotated = seq.tracks()
    evaluated = [t for t in tracks if t.object_id in annotated]
    if evaluated:
        horizon = max(1, min(MOTION_EVAL_HORIZON, max(len(t.frames) for t in evaluated) - 1))
        accuracy = evaluate_motion(seq, evaluated, horizon=horizon, source="pipeline tracks")
        outputs["evaluation"] = root / MOTION_EVAL_FILE
        write_text(outputs["evaluation"], json.dumps(accuracy.to_json()))
    DoneMarker(Path(out), f"motion/{sequence}").mark(digest, list(outputs.values()))
    return {"sequence": sequence, "objects": len(tracks), "messages": result.mcap.messages if result.mcap else 0,
            "outputs": {k: str(v.relative_to(Path(out))) for k, v in outputs.items()}}


# ----------------------------------------------------------------------------------------------- flow

def flow_camera(out: str, sequence: str, path: str, format: str | None, camera: str, object_ids: list[str],
                stage: FlowStage, digest: str) -> dict:
    """Optical flow of one camera's image pairs: ``OUT/<seq>/flow/<camera>/...`` (see docs/flow.md)."""
    from ..flow.annotate import FlowOptions, annotate_camera
    from ..flow.objects import objects_for_pairs

    seq = open_cached(path, format)
    flow_root = Path(out) / sequence / "flow"
    cam_root = flow_root / camera
    last = len(seq.cameras[camera].frames) - 1
    max_pairs = stage.max_pairs
    pairs = (0, last if max_pairs is None else min(last, int(max_pairs)))
    objects = objects_for_pairs(seq, [track_dir(out, sequence, o) for o in object_ids], pairs)
    objects = [dataclasses.replace(o, source=f"track:{sequence}/tracks/{o.object_id}") for o in objects]
    stats_path = cam_root / "stats.json"
    if stats_path.is_file():   # a previous run with another set of objects: its pairs are stale
        try:
            previous = [i["object_id"] for i in json.loads(stats_path.read_text()).get("instances", [])]
        except (OSError, json.JSONDecodeError):
            previous = None
        if previous != [o.object_id for o in objects]:
            shutil.rmtree(cam_root)
    options = FlowOptions(mode=stage.mode, use_lidar=stage.use_lidar)
    doc = annotate_camera(seq, camera, objects, flow_root, pairs=pairs, options=options, progress=False,
                          source="pipeline tracks")
    outputs = _files_under(cam_root)
    DoneMarker(Path(out), f"flow/{sequence}/{camera}").mark(digest, outputs)
    return {"sequence": sequence, "camera": camera, "pairs": len(doc["pairs"]), "objects": len(objects)}


# ---------------------------------------------------------------------------------------------- scans

def scene_name(entry_id: str, range_m: float) -> str:
    return f"{entry_id}__r{range_m:g}m"


def simulate_scene(out: str, entry_id: str, range_m: float, headings_deg: list[float], sensor: str,
                   digest: str) -> dict:
    """One bank vehicle placed ``len(headings)`` times at ``range_m`` (evenly spread azimuths, one heading each)
    and ray cast: ``OUT/scans/<entry>__r<range>m/`` (scan.npz, boxes.json, labels_kitti.txt, preview.png, scene.json)."""
    from ..objects.bank import read_bank
    from ..sensor.noise import Realism
    from ..lidar_sim.scene import SceneObject, SceneSpec
    from ..sensor.model import load_sensor
    from ..lidar_sim.simulate import run_simulation

    bank = read_bank(Path(out) / "bank")
    entry = bank.get(entry_id)
    n = len(headings_deg)
    objects = []
    for i, heading in enumerate(headings_deg):
        azimuth = 2.0 * math.pi * i / n + math.radians(20.0)
        objects.append(SceneObject(entry.id, round(range_m * math.cos(azimuth), 4), round(range_m * math.sin(azimuth), 4),
                                   None, math.radians(float(heading)), entry.label))
    sensor_model = load_sensor(sensor)
    spec = SceneSpec(sensor_model, -1.8, objects, Realism(motion_distortion=False, seed=0))
    directory = Path(out) / "scans" / scene_name(entry_id, range_m)
    outputs = run_simulation(spec, bank, directory, preview_extent=max(25.0, range_m * 1.25))
    counts = [int((outputs.result.scan.instance == i).sum()) for i in range(len(objects))]
    DoneMarker(Path(out), f"scans/{scene_name(entry_id, range_m)}").mark(
        digest, outputs.files, extra={"scene": scene_name(entry_id, range_m), "entry": entry_id, "range_m": range_m,
                                      "counts": counts})
    return {"scene": scene_name(entry_id, range_m), "entry": entry_id, "range_m": range_m,
            "headings_deg": list(headings_deg), "points": counts}
