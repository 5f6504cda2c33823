"""The pipeline configuration: sequences, object sources and stages (data_schema/pipeline.schema.json)."""

from __future__ import annotations

import dataclasses
import json
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from ..errors import InputError

__all__ = ["ObjectSource", "SequenceConfig", "TrackStage", "BankStage", "MotionStage", "FlowStage", "ScanStage",
           "Stages", "PipelineConfig", "load_config", "STAGE_NAMES"]

STAGE_NAMES = ("track", "bank", "motion", "flow", "scans")


@dataclass(frozen=True)
class ObjectSource:
    """Where a sequence's objects come from (see docs/pipeline.md for the rules)."""

    kind: str = "annotations"                 # "annotations" | "detections" | "boxes"
    track_ids: tuple[str, ...] | None = None  # annotations: id prefixes; None = every moving vehicle
    moving_only: bool = True
    max_objects: int | None = None
    path: str | None = None                   # detections file
    frame: int | None = None                  # detections seed frame
    min_score: float = 0.0
    boxes: tuple[dict, ...] = ()              # explicit: {id, frame, end_frame?, label?, box{...}}

    @classmethod
    def from_json(cls, doc: dict, base: Path) -> "ObjectSource":
        path = doc.get("path")
        if path is not None:
            path = str((base / path).resolve()) if not Path(path).is_absolute() else path
        ids = doc.get("track_ids")
        return cls(kind=doc["from"], track_ids=tuple(ids) if ids is not None else None,
                   moving_only=bool(doc.get("moving_only", True)), max_objects=doc.get("max_objects"),
                   path=path, frame=doc.get("frame"), min_score=float(doc.get("min_score", 0.0)),
                   boxes=tuple(doc.get("boxes", ())))

    def to_json(self) -> dict:
        out: dict[str, Any] = {"from": self.kind}
        if self.kind == "annotations":
            if self.track_ids is not None:
                out["track_ids"] = list(self.track_ids)
            out["moving_only"] = self.moving_only
        elif self.kind == "detections":
            out.update({"path": self.path, "min_score": self.min_score})
            if self.frame is not None:
                out["frame"] = self.frame
        else:
            out["boxes"] = [dict(b) for b in self.boxes]
        if self.max_objects is not None:
            out["max_objects"] = self.max_objects
        return out


@dataclass(frozen=True)
class SequenceConfig:
    path: str
    name: str | None = None
    format: str | None = None
    frames: tuple[int, int] | None = None
    objects: ObjectSource = field(default_factory=ObjectSource)
    detections: str | None = None   # per-frame detections for the det / det_sot presets

    def to_json(self) -> dict:
        out: dict[str, Any] = {"path": self.path, "objects": self.objects.to_json()}
        for key in ("name", "format", "detections"):
            if getattr(self, key) is not None:
                out[key] = getattr(self, key)
        if self.frames is not None:
            out["frames"] = list(self.frames)
        return out


@dataclass(frozen=True)
class TrackStage:
    enabled: bool = True
    preset: str = "full"
    overrides: dict = field(default_factory=dict)
    min_init_points: int = 5       # fewer points in the initial box: the object is reported as failed
    max_frames: int | None = None  # track at most this many frames after the start
    # annotated objects: "first_with_points" starts at the first annotated frame whose box holds at least
    # min_init_points non-ground points; "first_annotated" always starts at the first annotated frame
    start: str = "first_with_points"
    # data generation wants the best states: "offline" (default) refines every state with the whole sequence,
    # "lag" re-optimises each state over a sliding window of ``lag`` frames, "online" keeps the streaming states
    mode: str = "offline"
    lag: int = 10


@dataclass(frozen=True)
class BankStage:
    enabled: bool = True
    mirror: bool = False
    min_quality: float = 0.0
    min_points: int = 30           # shapes with fewer points are not put into the bank


@dataclass(frozen=True)
class MotionStage:
    enabled: bool = True
    parquet: bool = True
    npz: bool = True
    with_points: bool = False


@dataclass(frozen=True)
class FlowStage:
    enabled: bool = True
    cameras: tuple[str, ...] | None = None   # None = every camera of the sequence
    mode: str = "dense"
    max_pairs: int | None = None             # pairs 0..max_pairs (None = all)
    use_lidar: bool = True
    vis: bool = False                        # also write vis/ pictures (colour wheel PNG, overlay JPEG)


@dataclass(frozen=True)
class ScanStage:
    enabled: bool = True
    sensor: str = "pandar64"
    ranges_m: tuple[float, ...] = (20.0, 40.0)
    headings_deg: tuple[float, ...] = (0.0, 45.0, 90.0, 135.0)
    max_entries: int = 3


@dataclass(frozen=True)
class Stages:
    track: TrackStage = field(default_factory=TrackStage)
    bank: BankStage = field(default_factory=BankStage)
    motion: MotionStage = field(default_factory=MotionStage)
    flow: FlowStage = field(default_factory=FlowStage)
    scans: ScanStage = field(default_factory=ScanStage)

    def enabled(self) -> list[str]:
        return [name for name in STAGE_NAMES if getattr(self, name).enabled]


def _stage(cls, doc: dict | None):
    doc = dict(doc or {})
    for key, value in list(doc.items()):
        if isinstance(value, list):
            doc[key] = tuple(value)
    return cls(**doc)


@dataclass(frozen=True)
class PipelineConfig:
    """One pipeline run. Build it in code or load it with :func:`load_config` (validated JSON)."""

    out: str
    sequences: tuple[SequenceConfig, ...]
    stages: Stages = field(default_factory=Stages)
    description: str = ""

    @classmethod
    def from_json(cls, doc: dict, base: str | Path = ".", path: str | Path | None = None) -> "PipelineConfig":
        from ..schemas import validate

        validate("pipeline", doc, path)
        base = Path(base)
        default_objects = doc.get("objects", {"from": "annotations"})
        sequences = []
        for s in doc["sequences"]:
            seq_path = s["path"] if Path(s["path"]).is_absolute() else str((base / s["path"]).resolve())
            objects = ObjectSource.from_json(s.get("objects", default_objects), base)
            _check_objects(objects, path)
            dets = s.get("detections")
            if dets is not None and not Path(dets).is_absolute():
                dets = str((base / dets).resolve())
            sequences.append(SequenceConfig(seq_path, s.get("name"), s.get("format"),
                                            tuple(s["frames"]) if "frames" in s else None, objects, dets))
        stages_doc = doc.get("stages", {})
        stages = Stages(**{name: _stage(type(getattr(Stages(), name)), stages_doc.get(name)) for name in STAGE_NAMES})
        out = doc["out"] if Path(doc["out"]).is_absolute() else str((base / doc["out"]).resolve())
        config = cls(out, tuple(sequences), stages, doc.get("description", ""))
        from tracker import DETECTION_PRESETS

        if config.stages.track.enabled and config.stages.track.preset in DETECTION_PRESETS:
            missing = [s.path for s in config.sequences if s.detections is None]
            if missing:
                raise InputError(path, f"stages.track.preset {config.stages.track.preset!r} needs 'detections' for "
                                       f"every sequence (missing for {missing[0]})")
        names = [n for n in config.sequence_names() if n is not None]
        if len(set(names)) != len(names):
            raise InputError(path, "sequences: two sequences have the same name; give each a unique 'name'")
        return config

    def sequence_names(self) -> list[str | None]:
        return [s.name for s in self.sequences]

    def to_json(self) -> dict:
        stages = {name: _plain(dataclasses.asdict(getattr(self.stages, name))) for name in STAGE_NAMES}
        return {"version": 1, "description": self.description, "out": self.out,
                "sequences": [s.to_json() for s in self.sequences], "stages": stages}

    def replace(self, **changes: Any) -> "PipelineConfig":
        return dataclasses.replace(self, **changes)

    def with_stage(self, name: str, **changes: Any) -> "PipelineConfig":
        stage = dataclasses.replace(getattr(self.stages, name), **changes)
        return dataclasses.replace(self, stages=dataclasses.replace(self.stages, **{name: stage}))


def _plain(value: Any) -> Any:
    if isinstance(value, dict):
        return {k: _plain(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [_plain(v) for v in value]
    return value


def _check_objects(objects: ObjectSource, path) -> None:
    if objects.kind == "detections" and not objects.path:
        raise InputError(path, "objects: 'from: detections' needs 'path' (the detections file)")
    if objects.kind == "boxes" and not objects.boxes:
        raise InputError(path, "objects: 'from: boxes' needs a non-empty 'boxes' list")
    from tracker import Box

    from ..tracking import check_vehicle_size

    for b in objects.boxes:
        if not b.get("allow_any_size", False):
            box = Box(*(float(b["box"][f]) for f in ("x", "y", "z", "heading", "length", "width", "height")))
            check_vehicle_size(box, f"{path}: box {b['id']!r}", False, flag="\"allow_any_size\": true")


def load_config(path: str | Path, out: str | Path | None = None, detections: str | Path | None = None
                ) -> PipelineConfig:
    """Read and validate a pipeline JSON file; relative paths are resolved against its directory.
    ``detections``: the detections file of the pipeline's single sequence (overrides its 'detections')."""
    path = Path(path)
    if not path.is_file():
        raise InputError(path, "pipeline file is missing")
    try:
        doc = json.loads(path.read_text(encoding="utf-8"))
    except (json.JSONDecodeError, UnicodeDecodeError) as exc:
        raise InputError(path, f"not valid JSON ({exc})") from exc
    if not isinstance(doc, dict):
        raise InputError(path, "a pipeline file is a JSON object")
    if out is not None:
        doc["out"] = str(Path(out).resolve())
    if detections is not None:
        if not isinstance(doc.get("sequences"), list) or len(doc["sequences"]) != 1:
            raise InputError(path, "--detections needs a pipeline with exactly one sequence "
                                   "(give each sequence its own 'detections' in the file)")
        if isinstance(doc["sequences"][0], dict):
            doc["sequences"][0]["detections"] = str(Path(detections).resolve())
    return PipelineConfig.from_json(doc, path.parent, path)
