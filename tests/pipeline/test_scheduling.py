"""The tracking stage's scheduling: chunks of equal estimated cost, the cost estimate itself, identical tracks when a
sequence is split, and the schedule accounting."""

from __future__ import annotations

import dataclasses
import os

import numpy as np

from sot_apps.pipeline import plan as plan_module
from sot_apps.pipeline.plan import ObjectPlan, track_chunks
from tracker import Box

from .conftest import output_checksums

BOX = Box(0.0, 0.0, 0.0, 0.0, 4.0, 2.0, 1.5)


def _objects(sequence: str, costs: list[float], frames: int = 10) -> list[ObjectPlan]:
    return [ObjectPlan(sequence, f"/data/{sequence}", None, f"o{i}", "Car", 0, frames, BOX, cost=0.0)
            for i in range(len(costs))]


def test_chunks_split_a_sequence_into_equal_estimated_costs_costliest_first(monkeypatch):
    """Longest processing time first: objects of equal length but costs 7, 5, 4, 3, 1 over 2 chunks give {7, 3} and
    {5, 4, 1}, 10 each (splitting by frames would give 12 and 8); the costliest chunk comes first, plan order inside."""
    monkeypatch.setattr(plan_module, "SPLIT_PER_WORKER", 1)
    costs = [3.0, 7.0, 1.0, 5.0, 4.0]
    calls = []

    def estimate(objs):
        calls.append([o.object_id for o in objs])
        return [dataclasses.replace(o, cost=costs[int(o.object_id[1:])]) for o in objs]

    chunks = track_chunks(_objects("s", costs), workers=2, estimate=estimate)
    assert calls == [["o0", "o1", "o2", "o3", "o4"]]
    assert [[o.object_id for o in c] for c in chunks] == [["o0", "o1"], ["o2", "o3", "o4"]]
    assert [sum(o.cost for o in c) for c in chunks] == [10.0, 10.0]
    by_frames = track_chunks(_objects("s", costs), workers=2)   # no estimate: every object counts its 10 frames
    assert sorted(len(c) for c in by_frames) == [2, 3]


def test_sequences_are_not_split_nor_estimated_when_there_are_enough_of_them():
    calls = []
    objects = _objects("a", [1.0, 1.0]) + _objects("b", [1.0, 1.0, 1.0])
    chunks = track_chunks(objects, workers=2, estimate=lambda objs: calls.append(objs) or objs)
    assert calls == [] and [[o.key for o in c] for c in chunks] == [["b/o0", "b/o1", "b/o2"], ["a/o0", "a/o1"]]
    # a sequence cut because it has too many objects (max_objects) among enough sequences: by frames, no estimate
    chunks = track_chunks(objects, workers=2, max_objects=2, estimate=lambda objs: calls.append(objs) or objs)
    assert calls == [] and sorted(len(c) for c in chunks) == [1, 2, 2]


def test_cost_estimate_counts_the_points_in_each_box_at_the_sampled_sweeps(pandaset_root):
    """The estimate of three dev vehicles is their frames x frame_cost(mean points in their annotated boxes at the
    sampled frames), the points counted here by brute force over the whole sweep; the near dense car (20d13d1d,
    ~1,600 points, 61 ms per frame measured) is estimated costlier than the far one (b09e1c68, ~20 points, 13 ms)."""
    from sot_apps.io import open_sequence
    from sot_apps.pipeline.config import ObjectSource, SequenceConfig
    from sot_apps.pipeline.costs import SAMPLE_FRAMES, estimate_costs, frame_cost
    from tracker import points_in_box

    source = ObjectSource("annotations", track_ids=("20d13d1d", "91aa5b5c", "b09e1c68"))
    planned = plan_module.plan_sequence(SequenceConfig(str(pandaset_root), objects=source, frames=(0, 40))).objects
    estimated = estimate_costs(list(planned))
    seq = open_sequence(pandaset_root)
    grid = np.linspace(0, 40, SAMPLE_FRAMES).round().astype(int)
    for o, e in zip(planned, estimated, strict=True):
        boxes = dict(o.annotated)
        counts = [int(points_in_box(seq.lidar_frame(k).points_world(), boxes[k]).sum()) for k in grid]
        assert e.cost == round((o.end - o.start) * float(np.mean([frame_cost(n) for n in counts])), 1)
    near, mid, far = (e.cost for e in estimated)
    assert near > mid > far and near > 3 * far


def test_a_split_sequence_gives_the_tracks_of_one_pass(tiny_worlds, tmp_path, monkeypatch):
    """Splitting a sequence by estimated cost (as with 2 workers) changes who tracks which object, not the tracks."""
    from sot_apps.pipeline.config import PipelineConfig
    from sot_apps.pipeline.executors import ExecutorSession, ExecutorSpec
    from sot_apps.pipeline.runner import run_pipeline

    def config(out):
        return PipelineConfig.from_json({"version": 1, "out": str(out), "sequences": [
            {"path": str(tiny_worlds[0]), "objects": {"from": "annotations", "track_ids": ["veh_000", "veh_001", "veh_002"]}}],
            "stages": {name: {"enabled": False} for name in ("bank", "motion", "flow", "scans")}})

    one = run_pipeline(config(tmp_path / "one"), ExecutorSpec("inline"), progress=False)
    monkeypatch.setattr(ExecutorSession, "worker_count", lambda self: 2)
    split = run_pipeline(config(tmp_path / "split"), ExecutorSpec("inline"), progress=False)
    assert len(one.track_schedule["tasks"]) == 1 and len(split.track_schedule["tasks"]) == 3
    assert {u.status for u in split.by_stage("track")} == {"done"}
    assert output_checksums(tmp_path / "split") == output_checksums(tmp_path / "one")
    # the schedule says where each chunk ran (here: this process) and what its objects cost
    assert split.track_schedule["run_pid"] == os.getpid()
    for task in split.track_schedule["tasks"]:
        assert task["pid"] == os.getpid() and task["planned_cost"] > 0
        assert task["process_start_s"] < 0   # this process began before the stage
        assert 0 <= task["start_s"] <= task["end_s"] <= split.track_schedule["wall_s"]
        assert abs(sum(task["objects"].values()) - (task["cpu_s"] - task["read_s"] - task["ground_s"])) < 0.5


def test_worker_accounting_adds_up_a_schedule():
    """Two workers over a 10 s stage: busy, idle, wait (busy wall without the process's CPU), start-up, balance."""
    from sot_apps.pipeline.accounting import schedule_balance, worker_accounting

    def task(pid, start, end, cpu, process_cpu, before, objects):
        return {"pid": pid, "start_s": start, "end_s": end, "cpu_s": cpu, "process_cpu_s": process_cpu,
                "process_cpu_before_s": before, "open_cpu_s": 0.1 if before < 0.5 else 0.0, "read_s": 0.2,
                "ground_s": 0.1, "sweeps": 50, "object_frames": 100, "objects": objects}

    schedule = {"wall_s": 10.0, "tasks": [task(1, 0.5, 6.0, 5.0, 5.2, 0.05, {"a": 4.0}),
                                          task(1, 6.0, 9.0, 2.5, 2.6, 5.3, {"b": 2.0}),
                                          task(2, 0.6, 10.0, 8.0, 8.4, 0.04, {"c": 5.0, "d": 2.5})]}
    busiest, other = worker_accounting(schedule)
    assert (busiest["pid"], busiest["tasks"], busiest["busy_s"], busiest["idle_s"]) == (2, 1, 9.4, 0.6)
    assert (other["busy_s"], other["idle_s"], other["task_cpu_s"], other["wait_s"]) == (8.5, 1.5, 7.5, 0.7)
    assert (other["startup_cpu_s"], other["open_cpu_s"], other["sweep_read_s"], other["sweeps"]) == (0.05, 0.1, 0.6, 100)
    assert other["object_frames_per_s"] == round(200 / 8.5, 2)
    b = schedule_balance(schedule, 2)
    assert (b["task_cpu_s"], b["busiest_worker_cpu_s"], b["even_share_s"], b["costliest_object_s"]) == (15.5, 8.0, 7.75, 5.0)


def test_predicted_makespan_schedules_the_tasks_cpu_after_the_serial_start():
    """From CPU seconds only: 2 workers become ready when both the run's process (1.0 s: its CPU at the first batch
    plus the cost estimate) and the fork server (started at 0.2 s, 1.1 s of its own CPU: ready at 1.3 s) are done,
    plus the worker's start-up (0.1 s); tasks of 5, 4, 3, 2 s handed out in that order to the worker free first:
    {5, 2} and {4, 3}, 8.4 s, then the run's end (0.1 s). Inline (the run's own process tracks): its first task
    starts at its CPU then (imports included) and the tasks run one after the other."""
    from sot_apps.pipeline.accounting import predicted_makespan

    def task(pid, start, cpu, before):
        return {"pid": pid, "start_s": start, "cpu_s": cpu, "process_cpu_before_s": before,
                "server_ready_cpu_s": 1.1}

    phases = {"started": {"at_s": -0.5, "cpu_s": 0.4}, "server_started": {"at_s": -0.4, "cpu_s": 0.2},
              "opened": {"at_s": 0.3, "cpu_s": 0.9}, "tracked": {"at_s": 9.0, "cpu_s": 1.0},
              "finished": {"at_s": 9.1, "cpu_s": 1.1}}
    schedule = {"run_pid": 1, "chunking_cpu_s": 0.1,
                "tasks": [task(2, 0.5, 5.0, 0.1), task(3, 0.5, 4.0, 0.1), task(3, 4.5, 3.0, 4.2),
                          task(2, 5.5, 2.0, 5.2)]}
    p = predicted_makespan(schedule, phases, 2)
    assert (p["serial_s"], p["server_s"], p["first_task_s"]) == (1.0, 1.3, 1.4)
    assert (p["tasks_cpu_s"], p["end_s"], p["makespan_s"], p["even_s"]) == (14.0, 0.1, 8.5, 8.5)
    schedule["tasks"][0]["cpu_s"] = 7.0   # {7, 2} against {4, 3}: the tail
    assert predicted_makespan(schedule, phases, 2)["makespan_s"] == 10.5
    inline = {"run_pid": 1, "tasks": [{"pid": 1, "start_s": 0.4, "cpu_s": 14.0, "process_cpu_before_s": 1.3}]}
    p = predicted_makespan(inline, phases, 1)
    assert (p["first_task_s"], p["makespan_s"], p["server_s"]) == (1.3, 15.4, None)
