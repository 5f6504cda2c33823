"""``run_pipeline``: plan, then run the stages in three batches through one executor.

1. tracking, one task per (sequence, chunk of its objects): one pass over the sweeps (parallel over workers);
2. bank entries, motion export and flow, one task per sequence (flow: per sequence and camera);
   then the bank index is written;
3. simulated scans, one task per (bank entry, range).

A unit whose completion marker is valid is skipped (resume after a crash or Ctrl-C). A failed unit is
recorded in ``OUT/failures.json`` with its stage, sequence and object, and the run goes on; the units
that depend only on finished work still run. ``OUT/manifest.json`` records the config, versions, and
per unit its status, time and output checksums.
"""

from __future__ import annotations

import dataclasses
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Callable

from ..errors import OutputError
from ..io.atomic import remove_stale_temporaries, write_json
from .config import PipelineConfig
from .executors import ExecutorSession, ExecutorSpec, Task, TaskOutcome
from .health import health_lines, run_track_health
from .lock import RunLock
from .manifest import DoneMarker, code_digest, config_digest, write_manifest
from .plan import Plan, make_plan, open_sequences, safe_name, track_chunks
from . import stages as st

__all__ = ["UnitRecord", "PipelineResult", "run_pipeline"]


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
        lines = [f"{'stage':8s} {'done':>5s} {'cached':>6s} {'failed':>6s} {'skipped':>7s} {'seconds':>8s}"]
        for stage in ("track", "bank", "motion", "flow", "scans"):
            units = self.by_stage(stage)
            if not units:
                continue
            count = {s: sum(u.status == s for u in units) for s in ("done", "cached", "failed", "skipped")}
            lines.append(f"{stage:8s} {count['done']:5d} {count['cached']:6d} {count['failed']:6d} {count['skipped']:7d} "
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
            extra = {k: v for k, v in marker.items() if k not in ("name", "config", "outputs", "finished_unix")}
            records.append(UnitRecord(u.stage, u.key, u.sequence, u.object, "cached", result=extra or None,
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
                  progress: bool) -> tuple[list[UnitRecord], dict[str, float]]:
    """The tracking stage: every unfinished object, in chunks of one sequence each tracked in one pass
    (:func:`~sot_apps.pipeline.plan.track_chunks`); one record per object (a chunk's time shared by its objects'
    CPU time) and the stage's time breakdown summed over the chunks (read, ground, step, refine, write, overhead)."""
    track_stage = dataclasses.asdict(stage)
    digests = {o.key: _unit_digest({"object": o.to_json(), "seq": o.sequence_path, "stage": track_stage})
               for o in plan.objects}
    todo = [o for o in plan.objects if not _marker(out, f"track/{o.key}").is_done(digests[o.key])]
    chunks = track_chunks(todo, session.worker_count()) if todo else []
    tasks = [Task(f"track/{c[0].sequence}/chunk{i}", st.track_objects,
                  kwargs={"out": str(out), "plans": c, "stage": stage,
                          "digests": {o.object_id: digests[o.key] for o in c}})
             for i, c in enumerate(chunks)]
    outcomes = session.run(tasks, "track", progress)
    for o in outcomes:
        if o.environment:   # a full disk or an unwritable output stops the run (finished objects resume)
            raise OutputError(None, o.error or "cannot write an output")
    ran: dict[str, UnitRecord] = {}
    breakdown: dict[str, float] = {}
    for chunk, outcome in zip(chunks, outcomes):
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
    return records, breakdown


def _track_checksums(out: Path, sequence: str, objects: list[str]) -> dict[str, dict[str, str]]:
    return {o: _marker(out, f"track/{sequence}/{o}").outputs() for o in objects}


def run_pipeline(config: PipelineConfig, executor: ExecutorSpec = ExecutorSpec(), progress: bool = True,
                 plan: Plan | None = None, session: ExecutorSession | None = None) -> PipelineResult:
    """Run every enabled stage of ``config``; returns what ran, was cached or failed (see module doc).

    ``session``: an open :class:`ExecutorSession` to reuse (e.g. over several runs); by default one is
    opened for this run from ``executor``. ``config.out`` is locked for the run (:class:`RunLock`): a
    concurrent run into the same directory raises InputError.
    """
    if session is None:
        with RunLock(config.out), ExecutorSession(executor) as own:
            return run_pipeline(config, executor, progress, plan, own)
    with RunLock(config.out):
        return _run_with_session(config, executor, progress, plan, session)


def _run_with_session(config: PipelineConfig, executor: ExecutorSpec, progress: bool, plan: Plan | None,
                      session: ExecutorSession) -> PipelineResult:
    started = time.time()
    t0 = time.perf_counter()
    out = Path(config.out)
    out.mkdir(parents=True, exist_ok=True)
    remove_stale_temporaries(out)   # left by a killed worker or process; never under a final name
    plan = plan or make_plan(config)
    stages = config.stages
    records: list[UnitRecord] = []
    stage_seconds: dict[str, float] = {}
    track_times: dict[str, float] = {}

    # ---- 0. every Dask worker opens the planned sequences into its cache once (tasks then reuse them)
    start = time.perf_counter()
    session.on_every_worker(open_sequences, [(s.path, s.format) for s in plan.sequences])
    stage_seconds["open"] = time.perf_counter() - start

    # ---- 1. tracking: one task per (sequence, chunk of its objects), one pass over the sweeps each
    finished: dict[str, list[str]] = {s.name: [] for s in plan.sequences}
    if stages.track.enabled:
        start = time.perf_counter()
        track_records, stage_times = _run_tracking(plan, out, stages.track, session, progress)
        stage_seconds["track"] = time.perf_counter() - start
        records += track_records
        track_times.update(stage_times)
        for r in track_records:
            if r.status in ("done", "cached"):
                finished[r.sequence].append(r.object)
    else:   # later stages use tracks a previous run finished
        for o in plan.objects:
            if (st.track_dir(out, o.sequence, o.object_id) / "track.json").is_file():
                finished[o.sequence].append(o.object_id)

    # ---- 2. bank entries, motion, flow (per sequence / camera)
    units, skipped = [], []
    for s in plan.sequences:
        objs = finished[s.name]
        checks = _track_checksums(out, s.name, objs)
        if not objs:
            for stage in ("bank", "motion", "flow"):
                if getattr(stages, stage).enabled:
                    skipped.append(UnitRecord(stage, f"{stage}/{s.name}", s.name, None, "skipped",
                                              error="no object of this sequence was tracked"))
            continue
        if stages.bank.enabled:
            stage_doc = dataclasses.asdict(stages.bank)
            units.append(_make_unit(out, "bank", f"bank/{s.name}", s.name, None, {"tracks": checks, "stage": stage_doc},
                                    st.bank_sequence, {"out": str(out), "sequence": s.name, "object_ids": objs,
                                                       "stage": stages.bank}))
        if stages.motion.enabled:
            stage_doc = dataclasses.asdict(stages.motion)
            units.append(_make_unit(out, "motion", f"motion/{s.name}", s.name, None,
                                    {"tracks": checks, "stage": stage_doc, "seq": s.path},
                                    st.motion_sequence, {"out": str(out), "sequence": s.name, "path": s.path,
                                                         "format": s.format, "object_ids": objs, "stage": stages.motion}))
        if stages.flow.enabled:
            stage_doc = dataclasses.asdict(stages.flow)
            wanted = s.cameras if stages.flow.cameras is None else [c for c in stages.flow.cameras if c in s.cameras]
            if not wanted:
                skipped.append(UnitRecord("flow", f"flow/{s.name}", s.name, None, "skipped",
                                          error="the sequence has no (selected) camera"))
            for camera in wanted:
                units.append(_make_unit(out, "flow", f"flow/{s.name}/{camera}", s.name, None,
                                        {"tracks": checks, "stage": stage_doc, "seq": s.path, "camera": camera},
                                        st.flow_camera, {"out": str(out), "sequence": s.name, "path": s.path,
                                                         "format": s.format, "camera": camera, "object_ids": objs,
                                                         "stage": stages.flow}))
    start = time.perf_counter()
    batch = _run_units(units, out, session, "bank/motion/flow", progress)
    elapsed = time.perf_counter() - start
    for stage in ("bank", "motion", "flow"):
        stage_seconds[stage] = sum(r.seconds for r in batch if r.stage == stage) if len(units) > 1 else elapsed
    records += batch + skipped

    # ---- bank index (written here, from every sequence's entries)
    bank_entries: list[dict] = []
    if stages.bank.enabled:
        from ..objects.bank import Bank, BankEntry, write_bank_index

        for r in batch:
            if r.stage == "bank" and r.status in ("done", "cached") and r.result:
                bank_entries += r.result.get("entries", [])
        if bank_entries:
            bank = Bank(out / "bank", [BankEntry.from_json(e) for e in bank_entries])
            write_bank_index(bank)

    # ---- 3. simulated scans (per bank entry and range)
    if stages.scans.enabled:
        from ..objects.bank import read_bank

        scan_stage = stages.scans
        bank = read_bank(out / "bank", must_exist=False)
        entries = sorted(bank.entries, key=lambda e: (-e.quality, e.id))[: scan_stage.max_entries]
        units = []
        for e in entries:
            mesh_sum = _sha_or_none(out / "bank" / e.mesh)
            for r in scan_stage.ranges_m:
                name = st.scene_name(e.id, float(r))
                units.append(_make_unit(out, "scans", f"scans/{name}", None, e.id,
                                        {"mesh": mesh_sum, "range": r, "stage": dataclasses.asdict(scan_stage)},
                                        st.simulate_scene, {"out": str(out), "entry_id": e.id, "range_m": float(r),
                                                            "headings_deg": list(scan_stage.headings_deg),
                                                            "sensor": scan_stage.sensor}))
        if not entries:
            records.append(UnitRecord("scans", "scans", None, None, "skipped", error="the bank has no entries"))
        start = time.perf_counter()
        records += _run_units(units, out, session, "scans", progress)
        stage_seconds["scans"] = time.perf_counter() - start

    failures = [{"stage": r.stage, "key": r.key, "sequence": r.sequence, "object": r.object, "error": r.error}
                for r in records if r.status == "failed"]
    failures_path = out / "failures.json"
    write_json(failures_path, {"failures": failures})
    stage_docs = [{"stage": r.stage, **r.to_json()} for r in records]
    health = run_track_health(out, records)
    manifest = write_manifest(out, {**config.to_json(), "executor": executor.describe(),
                                    "objects": [o.to_json() for o in plan.objects]}, stage_docs, started,
                              {"track_health": health, "track_times": track_times})
    return PipelineResult(out, plan, records, time.perf_counter() - t0, manifest, failures_path, stage_seconds,
                          health, track_times)


def _sha_or_none(path: Path) -> str | None:
    from .manifest import sha256_file

    return sha256_file(path) if path.is_file() else None


def default_name(path: str) -> str:
    return safe_name(Path(path).name)
