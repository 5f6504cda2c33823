"""From a :class:`PipelineConfig` to the list of objects to track (one tracking task each).

Object rules (docs/pipeline.md):

- ``annotations``: the listed ``track_ids`` (unique prefixes), or every annotated VEHICLE whose box moves
  (``sot_apps.objects.selection``; ``moving_only: false`` takes parked ones too), in id order. Each is
  tracked from its first to its last annotated frame inside the sequence's ``frames`` range, starting
  from its annotated box.
- ``detections``: every box of the seed frame (``frame``, default the file's first frame) with
  ``score >= min_score`` (a box without a score counts as 1), highest score first, starts a track that
  runs to the end of the range. Ids are the box ``id`` or ``det<frame>_<index>``.
- ``boxes``: each explicit box starts a track at its ``frame`` and runs to ``end_frame`` (default: the
  end of the range).

``max_objects`` keeps the first N after ordering. The tracking stage may move an annotated object's start to
its first annotated frame with enough points and caps the length (``stages.track``: ``start``, ``max_frames``).
"""

from __future__ import annotations

import math
import os
import re
from dataclasses import dataclass
from pathlib import Path
from typing import Callable

from tracker import Box

from ..errors import InputError
from ..io.opened import open_cached
from ..io.sequence import Sequence
from .config import ObjectSource, PipelineConfig, SequenceConfig

__all__ = ["ObjectPlan", "SequencePlan", "Plan", "make_plan", "open_cached", "open_sequences", "worker_cache_info",
           "safe_name", "track_chunks", "MAX_OBJECTS_PER_TASK"]


def safe_name(text: str) -> str:
    return re.sub(r"[^A-Za-z0-9_.-]+", "_", str(text)).strip("_")[:100] or "unnamed"


def open_sequences(sources: list[tuple[str, str | None]]) -> int:
    """Open ``(path, format)`` sequences into this worker's cache (run on every worker); returns how many opened.
    A sequence that does not open is left to the tasks, which report the error with their key."""
    opened = 0
    for path, format in sources:
        try:
            open_cached(path, format)
            opened += 1
        except Exception:  # noqa: BLE001 - reported by the tasks that need it
            pass
    return opened


def worker_cache_info() -> dict[str, int]:
    """This worker's process id, how many sequences it has opened and how often a task reused one."""
    info = open_cached.cache_info()
    return {"pid": os.getpid(), "opened": info.misses, "reused": info.hits}


@dataclass(frozen=True)
class ObjectPlan:
    sequence: str            # output name of the sequence
    sequence_path: str
    format: str | None
    object_id: str
    label: str | None
    start: int
    end: int
    init_box: Box
    # annotations only: the annotated (frame, box) pairs from ``start`` to ``end``, so the tracking stage can
    # start at the first of them with enough LiDAR points (stages.track.start = "first_with_points")
    annotated: tuple[tuple[int, Box], ...] = ()
    detections: str | None = None   # the sequence's detections file (Detection term / Det baseline)
    # the tracking stage's estimated cost (relative units; :func:`estimate_costs`), 0 = not estimated: chunking only
    cost: float = 0.0

    @property
    def key(self) -> str:
        return f"{self.sequence}/{self.object_id}"

    def to_json(self) -> dict:
        b = self.init_box
        return {"sequence": self.sequence, "object_id": self.object_id, "label": self.label, "start": self.start,
                "end": self.end, "init_box": [b.x, b.y, b.z, b.heading, b.length, b.width, b.height]} | (
                    {"detections": self.detections} if self.detections else {})


@dataclass(frozen=True)
class SequencePlan:
    name: str
    path: str
    format: str | None
    id: str
    frames: tuple[int, int]
    cameras: tuple[str, ...]
    objects: tuple[ObjectPlan, ...]


@dataclass(frozen=True)
class Plan:
    sequences: tuple[SequencePlan, ...]

    @property
    def objects(self) -> list[ObjectPlan]:
        return [o for s in self.sequences for o in s.objects]


def _annotation_objects(seq: Sequence, src: ObjectSource, first: int, last: int) -> list[tuple]:
    from ..objects.selection import DEFAULT_SELECTION

    tracks = seq.tracks()
    if not tracks:
        raise InputError(seq.root, "objects from annotations: the sequence has no annotations")
    if src.track_ids is not None:
        ids = [seq.resolve_track_id(t) for t in src.track_ids]
    else:
        ids = DEFAULT_SELECTION.moving_vehicles(seq) if src.moving_only else DEFAULT_SELECTION.vehicles(seq)
    out = []
    for tid in ids:
        t = tracks[tid]
        frames = [int(k) for k in t.frames if first <= k <= last]
        if len(frames) < 2:
            continue
        out.append((tid, t.label, frames[0], frames[-1], t.box_at(frames[0]),
                    tuple((k, t.box_at(k)) for k in frames)))
    return out


def _detection_objects(seq: Sequence, src: ObjectSource, first: int, last: int) -> list[tuple[str, str | None, int, int, Box]]:
    from ..schemas import load_json_validated

    doc = load_json_validated(Path(src.path), "detections")
    frames = sorted(doc["frames"], key=lambda f: f["frame"])
    frames = [f for f in frames if first <= f["frame"] <= last]
    if not frames:
        raise InputError(src.path, f"no detections in frames {first}..{last}")
    seed = frames[0] if src.frame is None else next((f for f in frames if f["frame"] == src.frame), None)
    if seed is None:
        raise InputError(src.path, f"no detections listed for seed frame {src.frame}")
    k = int(seed["frame"])
    if k >= last:
        raise InputError(src.path, f"seed frame {k} leaves nothing to track (last frame {last})")
    ranked = sorted(enumerate(seed["boxes"]), key=lambda ib: (-float(ib[1].get("score", 1.0)), ib[0]))
    out = []
    for i, b in ranked:
        if float(b.get("score", 1.0)) < src.min_score:
            continue
        box = Box(*(float(b[f]) for f in ("x", "y", "z", "heading", "length", "width", "height")))
        out.append((b.get("id") or f"det{k:04d}_{i:02d}", b.get("label"), k, last, box, ()))
    return out


def _box_objects(src: ObjectSource, first: int, last: int, root) -> list[tuple[str, str | None, int, int, Box]]:
    out = []
    for b in src.boxes:
        k = int(b["frame"])
        end = min(int(b.get("end_frame", last)), last)
        if not first <= k < end:
            raise InputError(root, f"object {b['id']!r}: frame {k} must lie in {first}..{last - 1} and before end_frame")
        box = Box(*(float(b["box"][f]) for f in ("x", "y", "z", "heading", "length", "width", "height")))
        out.append((str(b["id"]), b.get("label"), k, end, box, ()))
    return out


def plan_sequence(cfg: SequenceConfig) -> SequencePlan:
    seq = open_cached(cfg.path, cfg.format)
    n = len(seq.frames)
    first, last = cfg.frames if cfg.frames is not None else (0, n - 1)
    if not 0 <= first < last <= n - 1:
        raise InputError(cfg.path, f"frames [{first}, {last}] outside 0..{n - 1} (need first < last)")
    name = cfg.name or safe_name(seq.id)
    src = cfg.objects
    if src.kind == "annotations":
        found = _annotation_objects(seq, src, first, last)
    elif src.kind == "detections":
        found = _detection_objects(seq, src, first, last)
    else:
        found = _box_objects(src, first, last, cfg.path)
    if src.max_objects is not None:
        found = found[: src.max_objects]
    objects, seen = [], set()
    for object_id, label, start, end, box, annotated in found:
        oid = safe_name(object_id)
        if oid in seen:
            raise InputError(cfg.path, f"object id {object_id!r} appears twice")
        seen.add(oid)
        objects.append(ObjectPlan(name, cfg.path, cfg.format, oid, label, start, end, box, annotated, cfg.detections))
    return SequencePlan(name, cfg.path, cfg.format, seq.id, (first, last), tuple(sorted(seq.cameras)), tuple(objects))


def make_plan(config: PipelineConfig) -> Plan:
    plans = [plan_sequence(s) for s in config.sequences]
    names = [p.name for p in plans]
    dup = sorted({n for n in names if names.count(n) > 1})
    if dup:
        raise InputError(None, f"two sequences are both named {dup[0]!r}; give each a unique 'name'")
    return Plan(tuple(plans))


# a tracking task holds at most this many live objects (each keeps its track and, offline, its region points)
MAX_OBJECTS_PER_TASK = 32
# fewer sequences than workers: chunks per worker. Each chunk reads the sequence's sweeps once more (~2-3 ms a sweep
# from the sweep cache); two per worker leave the dynamic scheduling room to even out errors of the cost estimate.
SPLIT_PER_WORKER = 2


def track_chunks(objects: list[ObjectPlan], workers: int, max_objects: int = MAX_OBJECTS_PER_TASK,
                 estimate: Callable[[list[ObjectPlan]], list[ObjectPlan]] | None = None) -> list[list[ObjectPlan]]:
    """The tracking stage's work units: each a chunk of ONE sequence's objects, tracked in one pass over its
    sweeps. A sequence is one chunk unless it has more than ``max_objects`` objects or there are fewer sequences
    than ``workers``: then it is split into up to ``SPLIT_PER_WORKER`` chunks per worker of about equal estimated
    cost, ``estimate(objects)``, asked only then (it reads a few sweeps of each such sequence in this process; the
    objects with ``ObjectPlan.cost`` set, :func:`sot_apps.pipeline.costs.
    estimate_costs`: objects of a sequence cost very differently, a dense near vehicle 4-5x a far one per frame;
    without an estimate, a cost not set counts the object's frames). Objects go to the chunk with the least cost
    so far, costliest first (longest processing time first), and keep plan order inside a chunk. Chunks come
    costliest first (the executors start them in that order), so the cheap ones fill the workers' ends."""
    by_sequence: dict[str, list[ObjectPlan]] = {}
    for o in objects:
        by_sequence.setdefault(o.sequence, []).append(o)
    if not by_sequence:
        return []
    workers = max(1, workers)
    per_sequence = 1 if len(by_sequence) >= workers else math.ceil(SPLIT_PER_WORKER * workers / len(by_sequence))
    chunks: list[tuple[float, list[ObjectPlan]]] = []
    for objs in by_sequence.values():
        n = min(len(objs), max(per_sequence, math.ceil(len(objs) / max_objects)))
        if n > 1 and per_sequence > 1 and estimate is not None:   # few sequences: their sweeps are read here
            objs = estimate(objs)
        cost = [o.cost or float(o.end - o.start) for o in objs]
        loads, members = [0.0] * n, [[] for _ in range(n)]
        for i in sorted(range(len(objs)), key=lambda i: -cost[i]):
            j = min((j for j in range(n) if len(members[j]) < max_objects), key=lambda j: loads[j])
            members[j].append(i)
            loads[j] += cost[i]
        chunks += [(load, [objs[i] for i in sorted(m)]) for load, m in zip(loads, members, strict=True) if m]
    return [c for _, c in sorted(chunks, key=lambda lc: -lc[0])]
