"""The units of work, as top-level (picklable) functions run by the executors: the tracking stage's chunks,
any app's unit (:func:`run_app_unit`) and the motion export's scoring.

Every unit writes its outputs through the atomic writers, then its completion marker (``OUT/.done``)
listing the outputs' sha256 checksums; a unit whose marker is valid is skipped on a rerun.
"""

from __future__ import annotations

import copy
import json
import os
import time
from concurrent.futures import Future, ThreadPoolExecutor
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from ..apps import track_dir
from ..evaluation.track_health import track_health
from .accounting import process_age
from .config import TrackStage
from .manifest import DoneMarker
from .plan import ObjectPlan, open_cached

if TYPE_CHECKING:
    from ..tracking import TrackOutcome

# The tracking machinery (sot_apps.tracking, the tracker's step and offline modules) is imported by the tasks that
# use it, not with this module: the run's own process plans and hands out tasks without it when workers track
# (a 1-worker run imports it at its first task; workers have it from their fork server, WORKER_MODULES).

__all__ = ["track_objects", "write_object", "run_app_unit", "score_motion", "track_dir",
           "MOTION_EVAL_FILE"]


# ---------------------------------------------------------------------------------------------- track

def track_objects(out: str, plans: list[ObjectPlan], stage: TrackStage, digests: dict[str, str]) -> dict:
    """Track a chunk of one sequence's objects in one pass over its sweeps (:func:`sot_apps.tracking.track_objects`:
    each sweep read and grounded once) and write each object as it finishes:
    ``OUT/<seq>/tracks/<object>/{track.json, shape.ply, shape_growth.json}`` and its completion marker
    (``digests[object_id]``). Returns per object its result or error (``TrackingFailed: ...`` when it had too few
    LiDAR points to start or follow) and where the chunk's time went (CPU seconds)."""
    from tracker import get_preset

    from ..tracking import ObjectRequest
    from ..tracking import track_objects as track_objects_pass

    t0, cpu0, process0, started = time.perf_counter(), time.thread_time(), time.process_time(), time.time()
    forked = started - process_age()   # when this worker process began (a fork server's child: its fork)
    first = plans[0]
    opened = open_cached.cache_info().misses
    seq = open_cached(first.sequence_path, first.format)
    open_s = time.thread_time() - cpu0
    config = get_preset(stage.preset, **dict(stage.overrides or {}))
    detections = None
    if first.detections:
        from ..io.detections import read_sequence_detections

        detections = read_sequence_detections(first.detections, seq)
    by_id = {p.object_id: p for p in plans}
    requests = [ObjectRequest(p.object_id, p.init_box, p.start, p.end,
                              p.annotated if stage.start == "first_with_points" else (), stage.max_frames)
                for p in plans]
    # Each finished object is written on a writer thread while the pass goes on: the atomic writes' fsyncs
    # (~10 ms of disk wait per file here) overlap with tracking instead of adding to it. The results are waited for
    # before the task returns (a write's error, e.g. a full disk, fails the task as before); on an interrupt the
    # write under way finishes (atomic) and the queued ones are dropped.
    writes: dict[str, Future] = {}
    writer = ThreadPoolExecutor(max_workers=1, thread_name_prefix="track-writer")

    def write(track: TrackOutcome) -> None:
        if track.error is None:   # a copy: the pass releases the object's result once this returns
            writes[track.object_id] = writer.submit(_write_timed, out, by_id[track.object_id], copy.copy(track),
                                                    digests[track.object_id])

    try:
        tracks, times = track_objects_pass(seq, requests, config, stage.mode, stage.lag, detections,
                                           stage.min_init_points, shape_growth=True, on_done=write)
        done = {object_id: future.result() for object_id, future in writes.items()}
    finally:
        writer.shutdown(wait=True, cancel_futures=True)
    written = {object_id: summary for object_id, (summary, _) in done.items()}
    write_seconds = sum(seconds for _, seconds in done.values())
    objects = []
    for t in tracks:
        plan = by_id[t.object_id]
        if t.error is None:
            objects.append({"object": t.object_id, "ok": True, "cpu_s": round(t.seconds, 4),
                            "result": written[t.object_id]})
        else:
            error = f"TrackingFailed: {plan.key}: {t.error}" if t.lacks_points else t.error
            objects.append({"object": t.object_id, "ok": False, "cpu_s": round(t.seconds, 4), "error": error})
    cpu = time.thread_time() - cpu0 + write_seconds   # this thread's CPU and the writer thread's
    breakdown = times.to_json() | {"write_s": round(write_seconds, 4), "cpu_s": round(cpu, 4),
                                   "wall_s": round(time.perf_counter() - t0, 4)}
    breakdown["overhead_s"] = round(cpu - times.read - times.ground - times.step - times.refine - write_seconds, 4)
    # where and when it ran (pipeline.accounting): the worker process and when it began, its CPU before this task (its start-up when
    # this is its first task), the whole process's CPU during the task (the task's threads and anything else the
    # worker runs meanwhile, e.g. Dask's event loop), and the sequence opening (a worker's first task opens it)
    from . import warm

    server = warm.server_ready or {}   # the fork server this worker came from, when it was warmed
    task = {"pid": os.getpid(), "process_start_unix": forked, "start_unix": started, "end_unix": time.time(),
            **({"server_ready_unix": server["unix"], "server_ready_cpu_s": server["cpu_s"]} if server else {}),
            "process_cpu_before_s": round(process0, 4), "process_cpu_s": round(time.process_time() - process0, 4),
            "open_cpu_s": round(open_s, 4) if open_cached.cache_info().misses > opened else 0.0}
    return {"sequence": first.sequence, "objects": objects, "times": breakdown, "task": task}


def _write_timed(out: str, plan: ObjectPlan, track: TrackOutcome, digest: str) -> tuple[dict, float]:
    """:func:`write_object` and the CPU seconds it took (of the thread running it)."""
    cpu = time.thread_time()
    return write_object(out, plan, track, digest), time.thread_time() - cpu


def write_object(out: str, plan: ObjectPlan, track: TrackOutcome, digest: str) -> dict:
    """One tracked object's outputs and completion marker; returns its summary for the manifest."""
    from ..tracking import track_result_to_track, write_shape_growth, write_track_result

    result = track.result
    directory = track_dir(out, plan.sequence, plan.object_id)
    # Per-frame time_ms is left out (it differs run to run): pipeline outputs are reproducible byte for byte;
    # the unit's total time is in the manifest.
    seq = open_cached(plan.sequence_path, plan.format)
    write_track_result(directory, seq, result, plan.object_id, track.init_box, plan.label, with_time_ms=False)
    growth_path = write_shape_growth(directory, track.growth)
    qualities = [float(np.clip(e.quality, 0.0, 1.0)) for e in result.estimates]
    # the run's track-health verdict from the records just written (pipeline.health: no re-reading of the file)
    health = track_health(track_result_to_track(seq, result, plan.object_id, track.init_box, plan.label,
                                                with_time_ms=False)[1]).to_json()
    DoneMarker(Path(out), f"track/{plan.key}").mark(digest, [directory / "track.json", directory / "shape.ply",
                                                             growth_path],
                                                    extra={"frames": len(qualities), "health": health})
    return {"sequence": plan.sequence, "object": plan.object_id, "frames": len(qualities),
            "tracked_frames": len(qualities) - 1, "seconds": round(track.seconds, 3),
            "mean_quality": round(float(np.mean(qualities)), 4), "shape_points": int(len(result.shape)),
            "health": health}


# ----------------------------------------------------------------------------------------------- apps

def run_app_unit(app, config, out: str, key: str, args: dict, digest: str) -> dict:
    """One unit of an app (:mod:`sot_apps.apps`): run it, then write its completion marker with the checksums of
    the files it wrote and its summary; returns the summary."""
    output = app.run(config, Path(out), **args)
    DoneMarker(Path(out), key).mark(digest, output.files, extra={"summary": output.summary})
    return output.summary


# ------------------------------------------------------------------------------------ motion evaluation

MOTION_EVAL_FILE = "motion_eval.json"
MOTION_EVAL_HORIZON = 30    # frames after each track's start


def score_motion(out: str, sequence: str, path: str, format: str | None, object_ids: list[str], digest: str) -> dict:
    """``OUT/<seq>/motion_eval.json``: the motion export's error against the sequence's annotations
    (:func:`sot_apps.evaluation.motion.evaluate_motion`, scoring the tracks the motion app exported), which the
    report draws. Nothing is written for an unannotated sequence."""
    from ..evaluation.motion import evaluate_motion
    from ..io.atomic import write_text
    from ..motion_export.sources import tracks_from_dirs

    seq = open_cached(path, format)
    annotated = seq.tracks()
    tracks = [t for t in tracks_from_dirs([track_dir(out, sequence, o) for o in object_ids], seq)
              if t.object_id in annotated]
    outputs = []
    if tracks:
        horizon = max(1, min(MOTION_EVAL_HORIZON, max(len(t.frames) for t in tracks) - 1))
        accuracy = evaluate_motion(seq, tracks, horizon=horizon, source="pipeline tracks")
        outputs.append(Path(out) / sequence / MOTION_EVAL_FILE)
        write_text(outputs[0], json.dumps(accuracy.to_json()))
    summary = {"sequence": sequence, "tracks": len(tracks)}
    DoneMarker(Path(out), f"motion_eval/{sequence}").mark(digest, outputs, extra={"summary": summary})
    return summary
