"""Scaling of the pipeline's tracking stage: object-frames per second against the number of workers, with local
processes and on a Dask cluster, and where the time goes (``sot-apps bench pipeline``).

Each configuration tracks the same objects into a fresh output directory (tracking stage only): the work unit
is a chunk of one sequence's objects tracked in one pass over its sweeps (docs/pipeline.md). The pool is
started and warmed up first (every worker imports the toolkit and opens the sequence, as the planner does in
the main process); that start-up time is reported separately from the tracking time. Object-frames = frames
after each object's start frame. "local processes" with 1 worker runs the tasks in this process (as
``sot-apps run`` does); a Dask LocalCluster of 1 worker is one worker process. Speed-up is relative to 1
worker of the same executor.

Columns: object-frames/s (wall) and per worker; "task s" sums the tasks' wall durations, concurrency = task s /
wall s; "CPU ms/obj-frame" is the tasks' CPU time (of the thread running each task) per object-frame (less
sensitive to other processes on the machine than wall time: compare it between 1 and 2 workers to tell
oversubscription from a busy machine); "CPU-bound speed-up" = the tasks' CPU seconds over the largest task's
(or over CPU / workers): what the chunks allow on otherwise idle cores;
the breakdown splits the tasks' CPU seconds into reading sweeps, whole-sweep ground (once per sweep), the
tracker's steps, refinement (fixed-lag / offline), writing the outputs and the rest (overhead).
The sweeps are read through the sweep cache (:mod:`sot_apps.io.sweep_cache`), converted (with their ground
masks) once before the first configuration, as after a first run.
"""

from __future__ import annotations

import argparse
import os
import tempfile
import time
from pathlib import Path

__all__ = ["register", "measure", "format_table"]


EXECUTOR_NAMES = {"inline": "in process", "local": "local processes", "dask": "Dask LocalCluster"}
PARTS = ("read", "ground", "step", "refine", "write", "overhead")


def _warm(sequences: list[str]) -> int:
    import sot_apps.pipeline.stages  # noqa: F401 - the import is the warm-up
    import tracker  # noqa: F401
    from sot_apps.pipeline.plan import open_cached

    for sequence in sequences:
        open_cached(sequence, None)   # as the planner already did in this process
    time.sleep(0.2)   # keep this worker busy so the others get warm-up tasks too
    return os.getpid()


def _convert_sweeps(config) -> None:
    """Fill the sweep cache for the planned frames, sweeps and ground masks (what a first run leaves)."""
    from tracker import get_preset

    from ..io import open_sequence
    from ..tracking import sweep_ground_once

    tracker_config = get_preset(config.stages.track.preset, **dict(config.stages.track.overrides or {}))
    ground = tracker_config.ground.remover == "sweep"
    for s in config.sequences:
        seq = open_sequence(s.path, s.format, cache=True)
        first, last = s.frames if s.frames is not None else (0, len(seq) - 1)
        for k in range(first, last + 1):
            frame = seq.lidar_frame(k)
            if ground and frame.has_sweep and len(frame.points_ego):
                sweep_ground_once(seq, frame, tracker_config.ground.sweep_args())


def tracking_only(config, out: str):
    """``config`` with only its tracking stage enabled, writing into ``out``."""
    import dataclasses

    from ..pipeline.config import Stages

    stages = Stages(track=dataclasses.replace(config.stages.track, enabled=True), apps=())
    return dataclasses.replace(config, out=out, stages=stages)


def measure(config, configs: list[tuple[str, int, str | None]], progress: bool = False) -> list[dict]:
    """One row per (executor kind, workers, Dask address) of ``configs``: ``config``'s tracking stage into a
    fresh temporary output."""
    from ..pipeline.accounting import format_accounting, main_accounting, schedule_balance, worker_accounting
    from ..pipeline.executors import ExecutorSession, ExecutorSpec, Task
    from ..pipeline.runner import WORKER_MODULES, run_pipeline

    _convert_sweeps(config)
    sequences = [s.path for s in config.sequences]
    rows = []
    for kind, workers, address in configs:
        spec = ExecutorSpec(kind, workers=workers, address=address)
        with tempfile.TemporaryDirectory(prefix="sot_bench_pipeline_") as tmp:
            run_config = tracking_only(config, str(Path(tmp) / "out"))
            start = time.perf_counter()
            with ExecutorSession(spec) as session:
                session.prestart(WORKER_MODULES)   # as sot-apps run: workers start with the toolkit loaded
                if kind == "dask":
                    session.on_every_worker(_warm, sequences)
                elif kind != "inline" and not (kind == "local" and workers <= 1):
                    session.run([Task(f"warm/{i}", _warm, (sequences,)) for i in range(2 * workers)], "warm-up",
                                False)
                count = session.worker_count()
                startup = time.perf_counter() - start
                result = run_pipeline(run_config, spec, progress=progress, session=session)
            seconds = result.stage_seconds["track"]
            frames = result.tracked_frames()
            busy = sum(u.seconds for u in result.by_stage("track"))
            times = result.track_times
            cpu = float(times.get("cpu_s", 0.0))
            rate = frames / seconds if seconds else 0.0
            accounting = {"workers": worker_accounting(result.track_schedule),
                          "balance": schedule_balance(result.track_schedule, count),
                          "main": main_accounting(result.phases, startup=False)}
            accounting_text = format_accounting(result.track_schedule, result.phases, count, startup=False)
            rows.append({"executor": f"Dask {address}" if address else EXECUTOR_NAMES[kind],
                         "workers": count, "objects": len(result.by_stage("track")),
                         "failed": len(result.failed), "object_frames": frames, "startup_s": round(startup, 2),
                         "tracking_s": round(seconds, 2), "task_s": round(busy, 2),
                         "concurrency": round(busy / seconds, 2) if seconds else 0.0,
                         "object_frames_per_s": round(rate, 2), "per_worker": round(rate / count, 2),
                         "cpu_s": round(cpu, 2), "cpu_ms_per_object_frame": round(1e3 * cpu / frames, 2) if frames else 0.0,
                         "sweeps_read": int(times.get("sweeps", 0)),
                         # the speed-up the tasks' CPU times allow with this many workers on otherwise idle cores
                         "cpu_bound_speedup": round(cpu / max(float(times.get("max_task_cpu_s", 0.0)), cpu / count), 2)
                         if cpu else None,
                         "cpu_breakdown_s": {p: round(float(times.get(f"{p}_s", 0.0)), 2) for p in PARTS},
                         "accounting": accounting, "accounting_text": accounting_text})
    base = {r["executor"]: r["object_frames_per_s"] for r in rows if r["workers"] == 1}
    for r in rows:
        b = base.get(r["executor"])
        r["speedup"] = round(r["object_frames_per_s"] / b, 2) if b else None
    return rows


def format_table(rows: list[dict]) -> str:
    lines = ["| executor | workers | objects | object-frames | start-up s | tracking s (wall) | task s (sum) "
             "| concurrency | object-frames/s | per worker | speed-up | CPU ms/obj-frame | CPU-bound speed-up "
             "| sweeps read |",
             "|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|"]
    for r in rows:
        speedup = "–" if r["speedup"] is None else f"{r['speedup']:.2f}x"
        lines.append(f"| {r['executor']} | {r['workers']} | {r['objects']} | {r['object_frames']} | "
                     f"{r['startup_s']:.1f} | {r['tracking_s']:.1f} | {r['task_s']:.1f} | {r['concurrency']:.2f} | "
                     f"{r['object_frames_per_s']:.1f} | {r['per_worker']:.1f} | {speedup} | "
                     f"{r['cpu_ms_per_object_frame']:.1f} | {r['cpu_bound_speedup'] or 0:.2f}x | {r['sweeps_read']} |")
    lines += ["", "Where the tasks' CPU time goes (seconds; ms per object-frame in brackets):", "",
              "| executor | workers | " + " | ".join(PARTS) + " |", "|---|---:|" + "---:|" * len(PARTS)]
    for r in rows:
        n = max(1, r["object_frames"])
        cells = [f"{r['cpu_breakdown_s'][p]:.2f} ({1e3 * r['cpu_breakdown_s'][p] / n:.1f})" for p in PARTS]
        lines.append(f"| {r['executor']} | {r['workers']} | " + " | ".join(cells) + " |")
    for r in rows:
        if r.get("accounting_text"):
            lines += ["", f"Per worker, {r['executor']}, {r['workers']} worker{'s' if r['workers'] != 1 else ''} "
                          "(seconds; wait = busy - the process's CPU; pipeline.accounting):", "", r["accounting_text"]]
    return "\n".join(lines)


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("sequence", metavar="SEQUENCE", nargs="?", default=None,
                        help="sequence with annotations (objects = its moving vehicles); default: a synthetic world "
                             "(12 frames, 4 vehicles, 64-beam LiDAR) generated in a temporary directory")
    parser.add_argument("--pipeline", metavar="PIPELINE.json",
                        help="take the sequences, objects and tracking stage from this pipeline file instead "
                             "(its other stages are not run; e.g. examples/pipeline_dev_tracking.json)")
    parser.add_argument("--workers", type=int, nargs="+", default=[1, 2], metavar="N", help="worker counts (default 1 2)")
    parser.add_argument("--executors", nargs="+", choices=("local", "dask"), default=["local", "dask"],
                        help="executors to measure (default: local dask)")
    parser.add_argument("--dask", metavar="tcp://HOST:PORT",
                        help="also measure on this Dask scheduler (with the workers it has)")
    parser.add_argument("--objects", type=int, default=8, help="track at most this many objects (default 8)")
    parser.add_argument("--max-frames", type=int, default=30, help="frames tracked per object after its start (default 30)")
    parser.add_argument("--mode", choices=("online", "lag", "offline"), default=None,
                        help="tracking mode (default: the tracking stage's, offline)")
    parser.add_argument("--json", metavar="FILE", help="also write the rows and the machine description as JSON")
    parser.set_defaults(bench_inputs=("pipeline",))   # --json never overwrites the pipeline file


def run(args: argparse.Namespace) -> int:
    import dataclasses

    from ..errors import InputError
    from ..io.atomic import write_json
    from ..pipeline.config import ObjectSource, PipelineConfig, SequenceConfig, Stages, TrackStage, load_config
    from . import format_machine, machine_description

    if min(args.workers) < 1 or args.objects < 1 or args.max_frames < 1:
        raise InputError(None, "--workers, --objects and --max-frames must be >= 1")
    if args.pipeline and args.sequence:
        raise InputError(None, "give a SEQUENCE or --pipeline, not both")
    configs = [(kind, w, None) for kind in args.executors for w in args.workers]
    if args.dask:
        configs.append(("dask", 1, args.dask))
    with tempfile.TemporaryDirectory(prefix="sot_bench_world_") as tmp:
        if args.pipeline:
            config = load_config(args.pipeline, out=Path(tmp) / "out")
            source = f"{args.pipeline} (tracking stage)"
        else:
            sequence = Path(args.sequence) if args.sequence else None
            if sequence is None:
                from ..synth import write_world

                sequence = write_world(Path(tmp) / "world", frames=12, vehicles=4, sensor="pandar64", seed=3)
            config = PipelineConfig(str(Path(tmp) / "out"), (SequenceConfig(str(sequence), objects=ObjectSource(
                "annotations", max_objects=args.objects)),), Stages(track=TrackStage(max_frames=args.max_frames)))
            source = args.sequence or "synthetic world (12 frames, 4 vehicles, pandar64, seed 3)"
        if args.mode:
            config = dataclasses.replace(config, stages=dataclasses.replace(
                config.stages, track=dataclasses.replace(config.stages.track, mode=args.mode)))
        rows = measure(config, configs)
    machine = machine_description()
    mode = config.stages.track.mode
    print(f"Pipeline tracking stage: {source}, mode {mode}")
    print(format_table(rows))
    print("\nmachine:\n" + format_machine(machine))
    if args.json:
        write_json(args.json, {"sequence": source, "mode": mode, "machine": machine,
                               "rows": [{k: v for k, v in r.items() if k != "accounting_text"} for r in rows]})
    return 0


def register(registry) -> None:
    """Hook for the ``sot-apps bench`` registry (sot_apps/cli/bench.py)."""
    registry.add("pipeline", help="pipeline tracking throughput (object-frames/s) vs workers, local and Dask, "
                                             "and where the time goes",
                 add_arguments=add_arguments, run=run, description=__doc__)
