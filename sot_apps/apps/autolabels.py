"""The ``autolabels`` app: the tracked objects as label files (AV2 feather with scores, KITTI tracking labels
when the sequence has a camera) in ``OUT/<seq>/labels/`` — the pipeline's auto-labels (docs/pipeline.md).

Each tracked object becomes one label track: its box at every tracked frame (the tracker's state with the
track's size), its score the mean frame quality. The writers are those of ``sot-apps convert --labels``.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from pathlib import Path

from . import AppBase, RunContext, UnitOutput, track_dir


@dataclass(frozen=True)
class AutoLabelsConfig:
    formats: tuple[str, ...] = ("av2", "kitti")   # "kitti" needs a camera; skipped (noted) without one
    category: str = "Car"
    min_quality: float = 0.0                      # frames of lower quality are left out of the labels


class AutoLabelsApp(AppBase):
    name = "autolabels"
    config_type = AutoLabelsConfig
    description = "the tracked objects as AV2 / KITTI label files (auto-labels with scores)"
    outputs = ("<sequence>/labels/av2/{annotations,submission}.feather", "<sequence>/labels/kitti/{label_02,calib}/*.txt")

    def plan(self, config: AutoLabelsConfig, run: RunContext) -> list:
        return self.per_sequence(run, lambda s: [self.sequence_unit(s)])

    def run(self, config: AutoLabelsConfig, out: Path, sequence: str, path: str, format: str | None,
            object_ids: list[str]) -> UnitOutput:
        import numpy as np

        from ..errors import InputError
        from ..io.label_export import export_labels, label_paths
        from ..io.labels import kitti_camera
        from ..io.opened import open_cached
        from ..io.tracks import read_track

        unknown = sorted(set(config.formats) - {"av2", "kitti"})
        if unknown:
            raise InputError(None, f"stages.autolabels.formats: unknown format {unknown[0]!r} (av2, kitti)")
        seq = open_cached(path, format)
        labels = []
        for object_id in object_ids:
            track = read_track(track_dir(out, sequence, object_id))[1]
            kept = track.select(np.asarray(track.scores) >= config.min_quality)   # scores: the tracker's quality
            if not len(kept):
                continue
            labels.append(dataclasses.replace(kept, object_id=object_id, label=config.category,
                                              scores=np.full(len(kept), float(np.mean(np.asarray(kept.scores))))))
        root = Path(out) / sequence / "labels"
        files: list[Path] = []
        notes = []
        for fmt in config.formats:
            if fmt == "kitti" and kitti_camera(seq) is None:
                notes.append("kitti: not written (the sequence has no camera, and KITTI's 2D boxes need one)")
                continue
            if labels:
                export_labels(seq, fmt, root / fmt, labels, submission=fmt == "av2")
                files += label_paths(seq, fmt, root / fmt, submission=fmt == "av2")
        return UnitOutput(files, {"sequence": sequence, "labels": len(labels),
                                  "boxes": sum(len(lbl.boxes) for lbl in labels), "notes": notes})
