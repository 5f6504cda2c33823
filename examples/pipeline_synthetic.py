"""Two synthetic sequences (LiDAR + a front camera) through the whole pipeline, built in code, then the report.

    python examples/pipeline_synthetic.py [OUT] [--workers N]

Writes OUT/worlds/* (the sequences), the pipeline outputs under OUT/run (docs/pipeline.md) and
OUT/run/report/index.html. Rerunning resumes: finished units are skipped.
"""

from __future__ import annotations

import argparse
from pathlib import Path

from sot_apps.apps.flow import FlowConfig
from sot_apps.apps.scans import ScanConfig
from sot_apps.pipeline.config import ObjectSource, PipelineConfig, SequenceConfig, Stages, TrackStage
from sot_apps.pipeline.executors import ExecutorSpec
from sot_apps.pipeline.runner import run_pipeline
from sot_apps.report import build_report
from sot_apps.synth import write_world


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("out", nargs="?", default="out/pipeline_synthetic")
    parser.add_argument("--workers", type=int, default=2)
    args = parser.parse_args()
    out = Path(args.out).resolve()

    sequences = []
    for seed in (4, 5):   # 8 frames, a 16-beam LiDAR and a 320x240 camera: a few seconds each
        world = write_world(out / "worlds" / f"seed{seed}", frames=8, vehicles=3, sensor="vlp16", seed=seed,
                            cameras=True, camera_size=(320, 240))
        sequences.append(SequenceConfig(str(world), objects=ObjectSource("annotations")))   # moving vehicles

    config = PipelineConfig(str(out / "run"), tuple(sequences),
                            Stages(track=TrackStage(preset="full"), flow=FlowConfig(max_pairs=4),
                                   scans=ScanConfig(sensor="pandar64", max_entries=1)))
    result = run_pipeline(config, ExecutorSpec("local", workers=args.workers))
    print(result.summary())
    for unit in result.failed:
        print("FAILED", unit.key, unit.error)
    report = build_report(result, "Synthetic pipeline example")
    print(f"report: {report}")


if __name__ == "__main__":   # needed: local worker processes are spawned and re-import this file
    main()
