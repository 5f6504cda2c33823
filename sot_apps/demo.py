"""The end-to-end demo as a library call: (synthetic world with a camera |) a sequence -> pipeline -> HTML report."""

from __future__ import annotations

import time
from dataclasses import dataclass
from pathlib import Path

from .apps.flow import FlowConfig
from .apps.scans import ScanConfig
from .pipeline.config import ObjectSource, PipelineConfig, SequenceConfig, Stages, TrackStage
from .pipeline.executors import ExecutorSpec
from .pipeline.runner import PipelineResult, run_pipeline

__all__ = ["DemoSize", "DEFAULT_SIZE", "QUICK_SIZE", "DemoResult", "make_world", "demo_config", "run_demo"]


@dataclass(frozen=True)
class DemoSize:
    frames: int = 20
    vehicles: int = 4
    sensor: str = "pandar64"
    camera_size: tuple[int, int] = (640, 360)
    seed: int = 3
    scan_sensor: str = "pandar64"


DEFAULT_SIZE = DemoSize()
QUICK_SIZE = DemoSize(frames=6, vehicles=3, sensor="vlp16", camera_size=(320, 240), seed=1, scan_sensor="vlp16")


@dataclass
class DemoResult:
    out: Path
    sequence: Path
    pipeline: PipelineResult
    report: Path
    seconds: dict[str, float]


def make_world(out: Path, size: DemoSize = DEFAULT_SIZE, progress: bool = True) -> Path:
    """The synthetic world (LiDAR, front camera, ground truth) as a canonical sequence in ``out``."""
    from .synth import write_world

    return write_world(out, frames=size.frames, vehicles=size.vehicles, sensor=size.sensor, seed=size.seed,
                       cameras=True, camera_size=size.camera_size, progress=progress)


def _world_once(out: Path, size: DemoSize, progress: bool) -> Path:
    """``out/world``, generated unless a previous run finished it (completion marker with checksums)."""
    import dataclasses

    from .pipeline.manifest import DoneMarker, code_digest, config_digest

    world = out / "world"
    marker = DoneMarker(out, "demo/world")
    digest = config_digest({"size": dataclasses.asdict(size), "code": code_digest()})
    if not marker.is_done(digest):
        make_world(world, size, progress)
        marker.mark(digest, sorted(p for p in world.rglob("*") if p.is_file()))
    return world


def demo_config(out: Path, sequence: Path, synthetic: bool, scan_sensor: str = "pandar64",
                flow_pairs: int | None = None, cameras: tuple[str, ...] | None = None) -> PipelineConfig:
    """Every stage over the moving vehicles of ``sequence``; real sequences get the front camera only and
    ``flow_pairs`` pairs (default 10) to stay reasonably quick."""
    if not synthetic:
        flow_pairs = 10 if flow_pairs is None else flow_pairs
        cameras = cameras or ("front_camera",)
    # the report shows the flow overlays (vis)
    stages = Stages(track=TrackStage(), flow=FlowConfig(cameras=cameras, max_pairs=flow_pairs, vis=True),
                    scans=ScanConfig(sensor=scan_sensor, max_entries=1))
    return PipelineConfig(str(out), (SequenceConfig(str(sequence), objects=ObjectSource("annotations")),),
                          stages, "sot-apps demo")


def run_demo(out: str | Path, sequence: str | Path | None = None, size: DemoSize = DEFAULT_SIZE,
             executor: ExecutorSpec = ExecutorSpec(), progress: bool = True, flow_pairs: int | None = None) -> DemoResult:
    """Run the demo into ``out``: ``out/world`` (the synthetic sequence, unless ``sequence`` is given), the
    pipeline outputs (``out/<sequence>/tracks``, ``motion.mcap``, ``flow``; ``out/bank``, ``out/scans``,
    ``out/manifest.json``) and ``out/report/index.html``."""
    from .report import build_report

    out = Path(out).resolve()
    seconds: dict[str, float] = {}
    t = time.perf_counter()
    synthetic = sequence is None
    if synthetic:
        sequence = _world_once(out, size, progress)
        seconds["world"] = time.perf_counter() - t
    sequence = Path(sequence).resolve()
    config = demo_config(out, sequence, synthetic, size.scan_sensor, flow_pairs)
    t = time.perf_counter()
    result = run_pipeline(config, executor, progress)
    seconds["pipeline"] = time.perf_counter() - t
    t = time.perf_counter()
    intro = [("Synthetic world " if synthetic else "Sequence ") + f"<code>{sequence}</code>: "
             f"{len(result.plan.objects)} moving vehicles tracked from their first annotated box; every stage of the "
             "pipeline (tracking, vehicle bank, motion export to MCAP, optical flow, simulated scans)."]
    report = build_report(result, "sot-apps demo", intro, max_sequences=1)
    seconds["report"] = time.perf_counter() - t
    return DemoResult(out, sequence, result, report, seconds)
