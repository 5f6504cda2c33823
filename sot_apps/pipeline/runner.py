"""``run_pipeline``: plan, then run the tracking stage and the apps in batches through one executor.

1. tracking, one task per (sequence, chunk of its objects): one pass over the sweeps (parallel over workers);
2. the enabled apps (:mod:`sot_apps.apps`), each planning its units from the finished tracks; an app runs in
   the batch after the apps it ``needs`` (built-ins: bank, motion, flow, autolabels in the first batch, then
   scans, which reads the bank). Each app's ``finish`` runs after its units (the bank writes its index).
   After the motion app, the motion export is scored against the annotations (``motion_eval.json``).

A unit whose completion marker is valid is skipped (resume after a crash or Ctrl-C). A failed unit is
recorded in ``OUT/failures.json`` with its stage, sequence and object, and the run goes on; the units
that depend only on finished work still run. ``OUT/manifest.json`` records the config, versions, and
per unit its status, time and output checksums.
"""

from __future__ import annotations

import dataclasses
import os
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Callable

from ..apps import App, RunContext, SequenceTracks, Skip, get_app
from ..errors import InputError, OutputError
from ..io.atomic import remove_stale_temporaries, write_json
from . import WORKER_MODULES, executors
from . import stages as st
from .accounting import process_age
from .config import PipelineConfig
from .costs import estimate_costs
from .executors import ExecutorSession, ExecutorSpec, Task, TaskOutcome
from .health import health_lines, run_track_health
from .lock import RunLock
from .manifest import DoneMarker, code_digest, config_digest, write_manifest
from .plan import Plan, make_plan, open_sequences, track_chunks
from .warm import warm_environment

__all__ = ["UnitRecord", "PipelineResult", "run_pipeline", "WORKER_MODULES"]


@dataclass
class UnitRecord:
    stage: str
    key: str                 # e.g. "track/seq/object", "flow/seq/front_camera"
    sequence: str | None
    object: str | None
    status: str              # "done" (ran now), "cached" (finished before), "failed", "skipped"
    seconds: float = 0.0
    error: str | None = None
    result: dict | None = None
    outputs: dict[str, str] = field(default_factory=dict)

    def to_json(self) -> dict:
        out = {k: v for k, v in dataclasses.asdict(self).items() if v is not None}
        out["seconds"] = round(self.seconds, 3)
        return out


@dataclass
class PipelineResult:
    out: Path
    plan: Plan
    units: list[UnitRecord]
    seconds: float
    manifest: Path
    failures: Path
    stage_seconds: dict[str, float] = field(default_factory=dict)
    track_health: list[dict] = field(default_factory=list)   # per finished track: pipeline.health
    # the tracking stage's CPU seconds (of the tasks' threads) summed over its tasks: read, ground, step, refine, write,
    # overhead, cpu, wall; and the largest task's CPU seconds (max_task_cpu_s)
    track_times: dict[str, float] = field(default_factory=dict)
    # the tracking tasks' schedule (worker, start, end, CPU per task: :func:`_schedule`) and this process's own
    # phases (wall seconds from the run's start and this process's CPU seconds at their end): pipeline.accounting
    track_schedule: dict = field(default_factory=dict)
    phases: dict[str, dict[str, float]] = field(default_factory=dict)

    def by_stage(self, stage: str) -> list[UnitRecord]:
        return [u for u in self.units if u.stage == stage]

    @property
    def failed(self) -> list[UnitRecord]:
        return [u for u in self.units if u.status == "failed"]

    def unexpected_failures(self) -> list[UnitRecord]:
        """Failed units, except annotated objects the tracker could not start or follow for lack of LiDAR
        points (``TrackingFailed``): on real data far or hidden annotated vehicles are a normal outcome."""
        annotated = {f"track/{o.key}" for o in self.plan.objects if o.annotated}
        return [u for u in self.failed if not (u.key in annotated and (u.error or "").startswith("TrackingFailed"))]

    def exit_code(self) -> int:
        """The one rule of ``sot-apps run`` and ``sot-apps demo``: 1 when a unit failed unexpectedly, else 0."""
        return 1 if self.unexpected_failures() else 0

    def ran(self, stage: str) -> list[UnitRecord]:
        return [u for u in self.by_stage(stage) if u.status == "done"]

    def tracked_frames(self) -> int:
        return sum(int((u.result or {}).get("tracked_frames", 0)) for u in self.ran("track"))

    def summary(self) -> str:
        stages = list(dict.fromkeys(u.stage for u in self.units))
        w = max([8] + [len(stage) for stage in stages])
        lines = [f"{'stage':{w}s} {'done':>5s} {'cached':>6s} {'failed':>6s} {'skipped':>7s} {'seconds':>8s}"]
        for stage in stages:
            units = self.by_stage(stage)
            count = {s: sum(u.status == s for u in units) for s in ("done", "cached", "failed", "skipped")}
            lines.append(f"{stage:{w}s} {count['done']:5d} {count['cached']:6d} {count['failed']:6d} {count['skipped']:7d} "
                         f"{self.stage_seconds.get(stage, 0.0):8.1f}")
        return "\n".join(lines + health_lines(self.track_health))


@dataclass
class _Unit:
    stage: str
    key: str
    sequence: str | None
    object: str | None
    digest: str
    task: Task | None          # None when the marker says it is finished


def _marker(out: Path, key: str) -> DoneMarker:
    return DoneMarker(out, key)


def _unit_digest(digest_doc: dict) -> str:
    # the code is part of the configuration: a unit finished by other code is not reused
    return config_digest({"unit": digest_doc, "code": code_digest()})


def _make_unit(out: Path, stage: str, key: str, sequence: str | None, obj: str | None, digest_doc: dict,
               fn: Callable, kwargs: dict) -> _Unit:
    digest = _unit_digest(digest_doc)
    if _marker(out, key).is_done(digest):
        return _Unit(stage, key, sequence, obj, digest, None)
    return _Unit(stage, key, sequence, obj, digest, Task(key, fn, kwargs={**kwargs, "digest": digest}))


def _run_units(units: list[_Unit], out: Path, session: ExecutorSession, desc: str, progress: bool) -> list[UnitRecord]:
    todo = [u for u in units if u.task is not None]
    outcomes: dict[str, TaskOutcome] = {o.key: o for o in session.run([u.task for u in todo], desc, progress)}
    for o in outcomes.values():
        if o.environment:   # a full disk or an unwritable output stops the run (finished units resume)
            raise OutputError(None, o.error or "cannot write an output")
    records = []
    for u in units:
        if u.task is None:
            marker = _marker(out, u.key).record()
            records.append(UnitRecord(u.stage, u.key, u.sequence, u.object, "cached", result=marker.get("summary"),
                                      outputs=marker.get("outputs", {})))
            continue
        o = outcomes[u.key]
        if o.ok:
            records.append(UnitRecord(u.stage, u.key, u.sequence, u.object, "done", o.seconds, result=o.result,
                                      outputs=_marker(out, u.key).outputs()))
        else:
            records.append(UnitRecord(u.stage, u.key, u.sequence, u.object, "failed", o.seconds, error=o.error))
    return records


def _run_tracking(plan: Plan, out: Path, stage, session: ExecutorSession,
                  progress: bool) -> tuple[list[UnitRecord], dict[str, float], dict]:
    """The tracking stage: every unfinished object, in chunks of one sequence each tracked in one pass
    (:func:`~sot_apps.pipeline.plan.track_chunks`); one record per object (a chunk's time shared by its objects'
    CPU time) and the stage's time breakdown summed over the chunks (read, ground, step, refine, write, overhead)."""
    track_stage = dataclasses.asdict(stage)
    digests = {o.key: _unit_digest({"object": o.to_json(), "seq": o.sequence_path, "stage": track_stage})
               for o in plan.objects}
    todo = [o for o in plan.objects if not _marker(out, f"track/{o.key}").is_done(digests[o.key])]
    chunking = time.perf_counter(), time.process_time()
    chunks = track_chunks(todo, session.worker_count(), estimate=estimate_costs) if todo else []
    chunking = time.perf_counter() - chunking[0], time.process_time() - chunking[1]
    tasks = [Task(f"track/{c[0].sequence}/chunk{i}", st.track_objects,
                  kwargs={"out": str(out), "plans": c, "stage": stage,
                          "digests": {o.object_id: digests[o.key] for o in c}})
             for i, c in enumerate(chunks)]
    started = time.time()
    outcomes = session.run(tasks, "track", progress)
    schedule = _schedule(chunks, tasks, outcomes, started, time.time()) | {
        "chunking_s": round(chunking[0], 4), "chunking_cpu_s": round(chunking[1], 4)}
    for o in outcomes:
        if o.environment:   # a full disk or an unwritable output stops the run (finished objects resume)
            raise OutputError(None, o.error or "cannot write an output")
    ran: dict[str, UnitRecord] = {}
    breakdown: dict[str, float] = {}
    for chunk, outcome in zip(chunks, outcomes, strict=True):
        entries = {e["object"]: e for e in (outcome.result or {}).get("objects", [])} if outcome.ok else {}
        for name, value in ((outcome.result or {}).get("times", {}) if outcome.ok else {}).items():
            breakdown[name] = breakdown.get(name, 0.0) + value
        if outcome.ok:
            breakdown["max_task_cpu_s"] = max(breakdown.get("max_task_cpu_s", 0.0), outcome.result["times"]["cpu_s"])
        cpu = sum(e["cpu_s"] for e in entries.values()) or 1.0
        for o in chunk:
            key, e = f"track/{o.key}", entries.get(o.object_id)
            share = outcome.seconds * (e["cpu_s"] / cpu if e else 1.0 / len(chunk))
            if e is not None and e["ok"]:
                ran[o.key] = UnitRecord("track", key, o.sequence, o.object_id, "done", share, result=e["result"],
                                        outputs=_marker(out, key).outputs())
            elif e is None and _marker(out, key).is_done(digests[o.key]):   # written before the chunk failed
                ran[o.key] = UnitRecord("track", key, o.sequence, o.object_id, "done", share,
                                        outputs=_marker(out, key).outputs())
            else:
                ran[o.key] = UnitRecord("track", key, o.sequence, o.object_id, "failed", share,
                                        error=e["error"] if e else outcome.error)
    records = []
    for o in plan.objects:
        if o.key in ran:
            records.append(ran[o.key])
            continue
        marker = _marker(out, f"track/{o.key}").record()
        extra = {k: v for k, v in marker.items() if k not in ("name", "config", "outputs", "finished_unix")}
        records.append(UnitRecord("track", f"track/{o.key}", o.sequence, o.object_id, "cached", result=extra or None,
                                  outputs=marker.get("outputs", {})))
    return records, breakdown, schedule


def _schedule(chunks: list, tasks: list[Task], outcomes: list[TaskOutcome], started: float, ended: float) -> dict:
    """When and where each tracking task ran (:mod:`sot_apps.pipeline.accounting` reads it): per task its worker,
    when that worker's process began, the task's start and end (seconds from the stage's start; a worker started
    before the stage has a negative process start), CPU and its objects' own CPU seconds."""
    entries = []
    for task, chunk, outcome in zip(tasks, chunks, outcomes, strict=True):
        result = outcome.result if outcome.ok else {}
        ran = result.get("task", {})
        entry = {"key": task.key, "ok": outcome.ok, "planned_cost": round(sum(o.cost for o in chunk), 2),
                 "objects": {e["object"]: e["cpu_s"] for e in result.get("objects", [])} or [o.object_id for o in chunk]}
        if ran:
            if "server_ready_unix" in ran:
                entry["server_ready_s"] = round(ran["server_ready_unix"] - started, 3)
            entry |= {"pid": ran["pid"], "process_start_s": round(ran["process_start_unix"] - started, 3),
                      "start_s": round(ran["start_unix"] - started, 4), "end_s": round(ran["end_unix"] - started, 4),
                      **{k: v for k, v in ran.items() if not k.endswith("_unix") and k != "pid"},
                      **{k: result["times"][k] for k in ("cpu_s", "read_s", "ground_s", "sweeps", "object_frames")}}
        entries.append(entry)
    return {"wall_s": round(ended - started, 4), "run_pid": os.getpid(), "tasks": entries}


def _track_checksums(out: Path, sequence: str, objects: list[str]) -> dict[str, dict[str, str]]:
    return {o: _marker(out, f"track/{sequence}/{o}").outputs() for o in objects}


def _run_context(plan: Plan, out: Path, finished: dict[str, list[str]]) -> RunContext:
    return RunContext(out, tuple(SequenceTracks(s.name, s.path, s.format, s.frames, s.cameras, tuple(finished[s.name]),
                                                _track_checksums(out, s.name, finished[s.name]),
                                                s.objects[0].detections if s.objects else None)
                                 for s in plan.sequences))


def _app_batches(apps: tuple[tuple[str, Any], ...]) -> list[list[tuple[str, App, Any]]]:
    """The enabled apps grouped into batches run one after the other: an app goes into the batch after the last
    batch holding an app it ``needs`` (needed apps that are not enabled read what a previous run left)."""
    level: dict[str, int] = {}
    batches: list[list[tuple[str, App, Any]]] = []
    pending = [(name, get_app(name), cfg) for name, cfg in apps]
    while pending:
        ready = [(n, a, c) for n, a, c in pending
                 if all(d in level or d not in dict(apps) for d in getattr(a, "needs", ()))]
        if not ready:
            raise InputError(None, f"stages: the apps {', '.join(n for n, _, _ in pending)} need each other")
        for name, app, cfg in ready:
            level[name] = 1 + max((level[d] for d in getattr(app, "needs", ()) if d in level), default=-1)
            while len(batches) <= level[name]:
                batches.append([])
            batches[level[name]].append((name, app, cfg))
        pending = [p for p in pending if p[0] not in level]
    return batches


def _run_apps(batch: list[tuple[str, App, Any]], context: RunContext, out: Path, session: ExecutorSession,
              progress: bool) -> tuple[list[UnitRecord], dict[str, float]]:
    """Plan every app of the batch from the finished tracks, run all their units together, then each app's
    ``finish`` over its finished units' summaries."""
    units: list[_Unit] = []
    records: list[UnitRecord] = []
    for name, app, cfg in batch:
        try:
            planned = list(app.plan(cfg, context))
        except Exception as exc:  # noqa: BLE001 - a failing app is recorded; the others go on
            records.append(UnitRecord(name, name, None, None, "failed", error=f"{type(exc).__name__}: {exc}"))
            continue
        config_doc = dataclasses.asdict(cfg)
        for item in planned:
            if isinstance(item, Skip):
                records.append(UnitRecord(name, item.key, item.sequence, None, "skipped", error=item.reason))
                continue
            units.append(_make_unit(out, name, item.key, item.sequence, item.object,
                                    {"app": name, "config": config_doc, "inputs": item.inputs}, st.run_app_unit,
                                    {"app": app, "config": cfg, "out": str(out), "key": item.key, "args": item.args}))
    ran = _run_units(units, out, session, "/".join(name for name, _, _ in batch), progress)
    seconds = {name: sum(r.seconds for r in ran if r.stage == name) for name, _, _ in batch}
    for name, app, cfg in batch:
        summaries = [r.result for r in ran if r.stage == name and r.status in ("done", "cached") and r.result]
        finish = getattr(app, "finish", None)
        try:
            if finish is not None:
                finish(cfg, out, summaries)
        except OutputError:
            raise
        except Exception as exc:  # noqa: BLE001 - recorded like a failed unit
            records.append(UnitRecord(name, f"{name}/finish", None, None, "failed",
                                      error=f"{type(exc).__name__}: {exc}"))
    return ran + records, seconds


def _score_motion(context: RunContext, out: Path, app_records: list[UnitRecord], session: ExecutorSession,
                  progress: bool) -> list[UnitRecord]:
    """The motion export scored against the annotations (``OUT/<seq>/motion_eval.json``, drawn by the report),
    for every sequence whose motion unit finished."""
    exported = {r.sequence for r in app_records if r.stage == "motion" and r.status in ("done", "cached")}
    units = [_make_unit(out, "motion_eval", f"motion_eval/{s.name}", s.name, None,
                        {"tracks": s.checksums, "seq": s.path}, st.score_motion,
                        {"out": str(out), "sequence": s.name, "path": s.path, "format": s.format,
                         "object_ids": list(s.objects)})
             for s in context.sequences if s.name in exported]
    return _run_units(units, out, session, "motion_eval", progress)


def run_pipeline(config: PipelineConfig, executor: ExecutorSpec = ExecutorSpec(), progress: bool = True,
                 plan: Plan | None = None, session: ExecutorSession | None = None) -> PipelineResult:
    """Run every enabled stage of ``config``; returns what ran, was cached or failed (see module doc).

    ``session``: an open :class:`ExecutorSession` to reuse (e.g. over several runs); by default one is
    opened for this run from ``executor``. ``config.out`` is locked for the run (:class:`RunLock`): a
    concurrent run into the same directory raises InputError.
    """
    if session is None:
        with RunLock(config.out), ExecutorSession(executor) as own:
            # the workers import and open the sequences while this process plans
            own.prestart(WORKER_MODULES, environ=warm_environment([(s.path, s.format) for s in config.sequences]))
            return run_pipeline(config, executor, progress, plan, own)
    with RunLock(config.out):
        return _run_with_session(config, executor, progress, plan, session)


def _run_with_session(config: PipelineConfig, executor: ExecutorSpec, progress: bool, plan: Plan | None,
                      session: ExecutorSession) -> PipelineResult:
    started = time.time()
    t0 = time.perf_counter()
    phases = {"started": {"at_s": -process_age(), "cpu_s": round(time.process_time(), 4)}}
    if executors.forkserver_started is not None:   # this process started the workers' fork server (then: CPU, time)
        cpu, unix = executors.forkserver_started
        phases["server_started"] = {"at_s": round(unix - started, 4), "cpu_s": round(cpu, 4)}

    def phase(name: str) -> None:   # this process's wall seconds since the run's start and its CPU seconds so far
        phases[name] = {"at_s": round(time.perf_counter() - t0, 4), "cpu_s": round(time.process_time(), 4)}

    out = Path(config.out)
    out.mkdir(parents=True, exist_ok=True)
    remove_stale_temporaries(out)   # left by a killed worker or process; never under a final name
    plan = plan or make_plan(config)
    phase("planned")
    stages = config.stages
    records: list[UnitRecord] = []
    stage_seconds: dict[str, float] = {}
    track_times: dict[str, float] = {}
    track_schedule: dict = {}

    # ---- 0. every Dask worker opens the planned sequences into its cache once (tasks then reuse them)
    start = time.perf_counter()
    session.on_every_worker(open_sequences, [(s.path, s.format) for s in plan.sequences])
    stage_seconds["open"] = time.perf_counter() - start
    phase("opened")

    # ---- 1. tracking: one task per (sequence, chunk of its objects), one pass over the sweeps each
    finished: dict[str, list[str]] = {s.name: [] for s in plan.sequences}
    if stages.track.enabled:
        start = time.perf_counter()
        track_records, stage_times, track_schedule = _run_tracking(plan, out, stages.track, session, progress)
        stage_seconds["track"] = time.perf_counter() - start
        phase("tracked")
        records += track_records
        track_times.update(stage_times)
        for r in track_records:
            if r.status in ("done", "cached"):
                finished[r.sequence].append(r.object)
    else:   # later stages use tracks a previous run finished
        for o in plan.objects:
            if (st.track_dir(out, o.sequence, o.object_id) / "track.json").is_file():
                finished[o.sequence].append(o.object_id)

    # ---- 2. the apps, in batches: an app runs in the batch after the apps whose outputs it reads (``needs``)
    context = _run_context(plan, out, finished)
    for batch in _app_batches(config.stages.apps):
        batch_records, batch_seconds = _run_apps(batch, context, out, session, progress)
        records += batch_records
        stage_seconds.update(batch_seconds)
        if any(name == "motion" for name, _, _ in batch):
            start = time.perf_counter()
            records += _score_motion(context, out, batch_records, session, progress)
            stage_seconds["motion_eval"] = time.perf_counter() - start
    phase("apps")

    failures = [{"stage": r.stage, "key": r.key, "sequence": r.sequence, "object": r.object, "error": r.error}
                for r in records if r.status == "failed"]
    failures_path = out / "failures.json"
    write_json(failures_path, {"failures": failures})
    stage_docs = [{"stage": r.stage, **r.to_json()} for r in records]
    health = run_track_health(out, records)
    phase("finished")
    manifest = write_manifest(out, {**config.to_json(), "executor": executor.describe(),
                                    "objects": [o.to_json() for o in plan.objects]}, stage_docs, started,
                              {"track_health": health, "track_times": track_times,
                               "track_schedule": track_schedule, "phases": phases})
    return PipelineResult(out, plan, records, time.perf_counter() - t0, manifest, failures_path, stage_seconds,
                          health, track_times, track_schedule, phases)
