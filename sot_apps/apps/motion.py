"""The ``motion`` app: the tracked motion as MCAP (+ Parquet, NPZ) per sequence (docs/motion-export.md)."""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from pathlib import Path

from . import AppBase, RunContext, UnitOutput, track_dir


@dataclass(frozen=True)
class MotionConfig:
    parquet: bool = True
    npz: bool = True
    with_points: bool = False


class MotionApp(AppBase):
    name = "motion"
    config_type = MotionConfig
    description = "smoothed motion of the tracked objects (states, velocities, accelerations) for Foxglove and training"
    outputs = ("<sequence>/motion.mcap", "<sequence>/motion.parquet", "<sequence>/motion.npz")

    def plan(self, config: MotionConfig, run: RunContext) -> list:
        return self.per_sequence(run, lambda s: [self.sequence_unit(s)])

    def run(self, config: MotionConfig, out: Path, sequence: str, path: str, format: str | None,
            object_ids: list[str]) -> UnitOutput:
        from ..io.opened import open_cached
        from ..motion_export.export import export_motion
        from ..motion_export.sources import tracks_from_dirs

        out = Path(out)
        seq = open_cached(path, format)
        root = out / sequence
        tracks = tracks_from_dirs([track_dir(out, sequence, o) for o in object_ids], seq)
        # relative sources keep the MCAP independent of where OUT lives
        tracks = [dataclasses.replace(t, source=str(Path(t.source).relative_to(out))) for t in tracks]
        files = {"mcap": root / "motion.mcap"}
        if config.parquet:
            files["parquet"] = root / "motion.parquet"
        if config.npz:
            files["npz"] = root / "motion.npz"
        result = export_motion(seq, tracks, files["mcap"], parquet=files.get("parquet"), npz=files.get("npz"),
                               with_points=config.with_points, progress=False)
        return UnitOutput(list(files.values()), {
            "sequence": sequence, "objects": len(tracks), "messages": result.mcap.messages if result.mcap else 0,
            "outputs": {k: str(v.relative_to(out)) for k, v in files.items()}})
