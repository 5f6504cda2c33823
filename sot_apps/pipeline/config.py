"""The pipeline configuration: sequences, object sources, the tracking stage and the apps that run after it
(data_schema/pipeline.schema.json; the apps are the installed ones, :mod:`sot_apps.apps`)."""

from __future__ import annotations

import dataclasses
import json
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from ..apps import V1_APPS, build_config, get_app
from ..errors import InputError
from ..io.jsonable import json_safe

__all__ = ["ObjectSource", "SequenceConfig", "TrackStage", "Stages", "PipelineConfig", "load_config", "V1_APPS"]


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


@dataclass(frozen=True, init=False)
class Stages:
    """The tracking stage (the core) and the enabled apps in run order, each with its config section.

    ``Stages(track=TrackStage(), flow=FlowConfig(max_pairs=4), scans=None)``: the version-1 apps (bank,
    motion, flow, scans) take their default config unless given (``None`` disables one); other apps run when
    given. ``Stages(track, apps=((name, config), ...))`` lists the apps exactly."""

    track: TrackStage
    apps: tuple[tuple[str, Any], ...]

    def __init__(self, track: TrackStage | None = None, apps: tuple[tuple[str, Any], ...] | None = None,
                 **sections: Any) -> None:
        if apps is None:
            chosen: dict[str, Any] = {}
            for name in V1_APPS:
                config = sections.pop(name) if name in sections else get_app(name).config_type()
                if config is not None:
                    chosen[name] = config
            chosen.update({name: config for name, config in sections.items() if config is not None})
            apps = tuple(chosen.items())
        elif sections:
            raise TypeError("Stages: give either apps=... or app sections by name, not both")
        object.__setattr__(self, "track", track if track is not None else TrackStage())
        object.__setattr__(self, "apps", tuple(apps))

    def app(self, name: str) -> Any:
        """The config of the enabled app ``name``, or None when it does not run."""
        return dict(self.apps).get(name)

    def enabled(self) -> list[str]:
        return (["track"] if self.track.enabled else []) + [name for name, _ in self.apps]

    def to_json(self) -> dict:
        out: dict[str, Any] = {"track": _section_json(self.track)}
        out.update({name: {"enabled": False} for name in V1_APPS if self.app(name) is None})
        out.update({name: _section_json(config) for name, config in self.apps})
        return out

    @classmethod
    def from_json(cls, doc: dict, path: Any = None) -> "Stages":
        track_doc = dict(doc.get("track") or {})
        track = dataclasses.replace(build_config(TrackStage, track_doc, "stages.track", path),
                                    enabled=bool(track_doc.get("enabled", True)))
        names = list(V1_APPS) + [n for n in doc if n != "track" and n not in V1_APPS]
        apps = []
        for name in names:
            section = doc.get(name) or {}
            if not section.get("enabled", True):
                continue
            try:
                app = get_app(name)
            except InputError as exc:
                raise InputError(path, f"stages.{name}: {exc.problem}") from exc
            apps.append((name, build_config(app.config_type, section, f"stages.{name}", path)))
        return cls(track, apps=tuple(apps))


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
        stages = Stages.from_json(doc.get("stages", {}), path)
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
        return {"version": 1, "description": self.description, "out": self.out,
                "sequences": [s.to_json() for s in self.sequences], "stages": self.stages.to_json()}

    def replace(self, **changes: Any) -> "PipelineConfig":
        return dataclasses.replace(self, **changes)


def _section_json(config: Any) -> dict:
    """A stage's section as the pipeline file writes it: a field left at its default None is left out (the file
    has no null)."""
    defaults = {f.name: f.default for f in dataclasses.fields(config)}
    return {k: json_safe(v) for k, v in dataclasses.asdict(config).items() if not (v is None and defaults[k] is None)}


def _check_objects(objects: ObjectSource, path) -> None:
    if objects.kind == "detections" and not objects.path:
        raise InputError(path, "objects: 'from: detections' needs 'path' (the detections file)")
    if objects.kind == "boxes" and not objects.boxes:
        raise InputError(path, "objects: 'from: boxes' needs a non-empty 'boxes' list")
    if not objects.boxes:
        return   # (sot_apps.tracking, the tracker and scipy are imported only when there are boxes to check)
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
