"""The ``flow`` app: optical flow of the tracked objects per camera (``OUT/<seq>/flow/<camera>/``; docs/flow.md)."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

from . import AppBase, RunContext, SequenceTracks, Skip, Unit, UnitOutput, track_dir


@dataclass(frozen=True)
class FlowConfig:
    cameras: tuple[str, ...] | None = None   # None = every camera of the sequence
    mode: str = "dense"
    max_pairs: int | None = None             # pairs 0..max_pairs (None = all)
    use_lidar: bool = True
    vis: bool = False                        # also write vis/ pictures (colour wheel PNG, overlay JPEG)


class FlowApp(AppBase):
    name = "flow"
    config_type = FlowConfig
    description = "dense optical flow, occlusion and instance masks of the tracked objects, per camera"
    outputs = ("<sequence>/flow/<camera>/...",)

    def plan(self, config: FlowConfig, run: RunContext) -> list:
        def units(s: SequenceTracks) -> list[Unit | Skip]:
            wanted = s.cameras if config.cameras is None else [c for c in config.cameras if c in s.cameras]
            if not wanted:
                return [Skip(f"flow/{s.name}", "the sequence has no (selected) camera", s.name)]
            return [Unit(f"flow/{s.name}/{camera}", {"tracks": s.checksums, "seq": s.path, "camera": camera},
                         {"sequence": s.name, "path": s.path, "format": s.format, "camera": camera,
                          "object_ids": list(s.objects)}, s.name) for camera in wanted]
        return self.per_sequence(run, units)

    def run(self, config: FlowConfig, out: Path, sequence: str, path: str, format: str | None, camera: str,
            object_ids: list[str]) -> UnitOutput:
        import dataclasses
        import json
        import shutil

        from ..flow.annotate import FlowOptions, annotate_camera
        from ..flow.objects import objects_for_pairs
        from ..io.opened import open_cached

        seq = open_cached(path, format)
        flow_root = Path(out) / sequence / "flow"
        cam_root = flow_root / camera
        last = len(seq.cameras[camera].frames) - 1
        pairs = (0, last if config.max_pairs is None else min(last, int(config.max_pairs)))
        objects = objects_for_pairs(seq, [track_dir(out, sequence, o) for o in object_ids], pairs)
        objects = [dataclasses.replace(o, track=dataclasses.replace(o.track, source=f"track:{sequence}/tracks/{o.object_id}"))
                   for o in objects]
        stats_path = cam_root / "stats.json"
        if stats_path.is_file():   # a previous run with another set of objects: its pairs are stale
            try:
                previous = [i["object_id"] for i in json.loads(stats_path.read_text()).get("instances", [])]
            except (OSError, json.JSONDecodeError):
                previous = None
            if previous != [o.object_id for o in objects]:
                shutil.rmtree(cam_root)
        options = FlowOptions(mode=config.mode, use_lidar=config.use_lidar, write_vis=config.vis)
        doc = annotate_camera(seq, camera, objects, flow_root, pairs=pairs, options=options, progress=False,
                              source="pipeline tracks")
        files = sorted(p for p in cam_root.rglob("*") if p.is_file())
        return UnitOutput(files, {"sequence": sequence, "camera": camera, "pairs": len(doc["pairs"]),
                                  "objects": len(objects)})
