"""Scaling of the pipeline's tracking stage: tracked frames per second against the number of workers,
with local processes and on a Dask LocalCluster (``sot-apps bench pipeline``).

Each configuration tracks the same objects into a fresh output directory (tracking stage only). The
pool is started and warmed up first (every worker imports the toolkit and opens the sequence, as the
planner does in the main process); that start-up time is reported
separately from the tracking time. Tracked frames = frames after each object's start frame.
"local processes" with 1 worker runs the tasks in this process (as ``sot-apps run`` does); a Dask
LocalCluster of 1 worker is one worker process. Speed-up is relative to 1 worker of the same executor.
"task s" sums the tasks' own durations; concurrency = task s / wall s (how many ran at once on average).
On a shared machine the tasks slow down when other processes compete for the cores: compare the task
seconds of 1 and 2 workers to see it.
"""

from __future__ import annotations

import argparse
import os
import tempfile
import time
from pathlib import Path

__all__ = ["register", "measure", "format_table"]


EXECUTOR_NAMES = {"inline": "in process", "local": "local processes", "dask": "Dask LocalCluster"}


def _warm(sequence: str) -> int:
    import sot_apps.pipeline.stages  # noqa: F401 - the import is the warm-up
    import tracker  # noqa: F401
    from sot_apps.pipeline.plan import open_cached

    open_cached(sequence, None)   # as the planner already did in this process
    time.sleep(0.2)   # keep this worker busy so the others get warm-up tasks too
    return os.getpid()


def measure(sequence: Path, configs: list[tuple[str, int]], objects: int | None, max_frames: int | None,
            progress: bool = False) -> list[dict]:
    from ..pipeline.config import ObjectSource, PipelineConfig, SequenceConfig, Stages, TrackStage
    from ..pipeline.executors import ExecutorSession, ExecutorSpec, Task
    from ..pipeline.runner import run_pipeline

    rows = []
    off = {"enabled": False}
    for kind, workers in configs:
        spec = ExecutorSpec(kind, workers=workers)
        with tempfile.TemporaryDirectory(prefix="sot_bench_pipeline_") as tmp:
            stages = Stages(track=TrackStage(max_frames=max_frames), **{
                name: type(getattr(Stages(), name))(**off) for name in ("bank", "motion", "flow", "scans")})
            config = PipelineConfig(str(Path(tmp) / "out"), (SequenceConfig(str(sequence), objects=ObjectSource(
                "annotations", max_objects=objects)),), stages)
            start = time.perf_counter()
            with ExecutorSession(spec) as session:
                if kind == "dask":
                    session.on_every_worker(_warm, str(sequence))
                elif kind != "inline" and not (kind == "local" and workers <= 1):
                    session.run([Task(f"warm/{i}", _warm, (str(sequence),)) for i in range(2 * workers)], "warm-up",
                                False)
                startup = time.perf_counter() - start
                result = run_pipeline(config, spec, progress=progress, session=session)
            seconds = result.stage_seconds["track"]
            frames = result.tracked_frames()
            busy = sum(u.seconds for u in result.by_stage("track"))
            rows.append({"executor": EXECUTOR_NAMES[kind],
                         "workers": workers, "objects": len(result.by_stage("track")),
                         "failed": len(result.failed), "tracked_frames": frames, "startup_s": round(startup, 2),
                         "tracking_s": round(seconds, 2), "task_s": round(busy, 2),
                         "concurrency": round(busy / seconds, 2) if seconds else 0.0,
                         "frames_per_s": round(frames / seconds, 2) if seconds else 0.0})
    base = {r["executor"]: r["frames_per_s"] for r in rows if r["workers"] == 1}
    for r in rows:
        b = base.get(r["executor"])
        r["speedup"] = round(r["frames_per_s"] / b, 2) if b else None
    return rows


def format_table(rows: list[dict]) -> str:
    lines = ["| executor | workers | objects | tracked frames | start-up s | tracking s (wall) | task s (sum) "
             "| concurrency | frames/s | speed-up |",
             "|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|"]
    for r in rows:
        speedup = "–" if r["speedup"] is None else f"{r['speedup']:.2f}x"
        lines.append(f"| {r['executor']} | {r['workers']} | {r['objects']} | {r['tracked_frames']} | "
                     f"{r['startup_s']:.1f} | {r['tracking_s']:.1f} | {r['task_s']:.1f} | {r['concurrency']:.2f} | "
                     f"{r['frames_per_s']:.1f} | {speedup} |")
    return "\n".join(lines)


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("sequence", metavar="SEQUENCE", nargs="?", default=None,
                        help="sequence with annotations (objects = its moving vehicles); default: a synthetic world "
                             "(12 frames, 4 vehicles, 64-beam LiDAR) generated in a temporary directory")
    parser.add_argument("--workers", type=int, nargs="+", default=[1, 2], metavar="N", help="worker counts (default 1 2)")
    parser.add_argument("--executors", nargs="+", choices=("local", "dask"), default=["local", "dask"],
                        help="executors to measure (default: local dask)")
    parser.add_argument("--objects", type=int, default=8, help="track at most this many objects (default 8)")
    parser.add_argument("--max-frames", type=int, default=30, help="frames tracked per object after its start (default 30)")
    parser.add_argument("--json", metavar="FILE", help="also write the rows and the machine description as JSON")


def run(args: argparse.Namespace) -> int:
    from ..errors import InputError
    from ..io.atomic import write_json
    from . import format_machine, machine_description

    if min(args.workers) < 1 or args.objects < 1 or args.max_frames < 1:
        raise InputError(None, "--workers, --objects and --max-frames must be >= 1")
    configs = [(kind, w) for kind in args.executors for w in args.workers]
    with tempfile.TemporaryDirectory(prefix="sot_bench_world_") as tmp:
        sequence = Path(args.sequence) if args.sequence else None
        if sequence is None:
            from ..synth import write_world

            sequence = write_world(Path(tmp) / "world", frames=12, vehicles=4, sensor="pandar64", seed=3)
        rows = measure(sequence, configs, args.objects, args.max_frames)
    machine = machine_description()
    source = args.sequence or "synthetic world (12 frames, 4 vehicles, pandar64, seed 3)"
    print(f"Pipeline tracking stage: {source}")
    print(format_table(rows))
    print("\nmachine:\n" + format_machine(machine))
    if args.json:
        write_json(args.json, {"sequence": source, "rows": rows, "machine": machine})
    return 0


def register(registry) -> None:
    """Hook for the ``sot-apps bench`` registry (sot_apps/cli/bench.py)."""
    registry.add("pipeline", help="pipeline tracking throughput (tracked frames/s) vs workers, local and Dask",
                 add_arguments=add_arguments, run=run, description=__doc__)
