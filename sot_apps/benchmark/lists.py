"""LiDAR-SOT tracklet lists: reading them (LiDAR-SOT's own, or ours), and building them from any dataset.

LiDAR-SOT ships ``benchmark/<class>/{bench_list,easy,medium,hard}.json``: JSON lists of ``{id, type,
segment_name, frame_range}`` (frame range inclusive; tracking starts from the first frame's box). Our
lists add optional fields (difficulty, profile, ...; schema ``benchmark``).

:func:`build_lists` applies the paper's selection to annotated sequences (thresholds are options: short
datasets need a shorter minimum length): the object's first contiguous annotated run has at least
``min_frames`` frames (LiDAR-SOT: 100), more than ``min_points`` (20) points in its box in each of the first
``first_frames`` (10) frames, and it is not static throughout (its centre moves more than
``min_displacement_m`` from the first position). Difficulty: mean points in the box over the first 10
frames, hard < 38.2 <= medium < 808.3 <= easy.
"""

from __future__ import annotations

import os
from dataclasses import dataclass, field
from pathlib import Path
from typing import Callable

import numpy as np

from tracker import DIFFICULTIES, DIFFICULTY_THRESHOLDS, difficulty, points_in_box

from ..errors import InputError
from ..io.sequence import Sequence
from ..objects.selection import DEFAULT_SELECTION, annotated_span
from ..schemas import load_json_validated

__all__ = ["Tracklet", "ListCriteria", "read_list", "read_lists", "build_lists", "SequenceResolver",
           "default_resolver", "write_lists", "LIST_FILES", "type_of_label"]

LIST_FILES = ("bench_list.json", "easy.json", "medium.json", "hard.json")
TYPE_VEHICLE, TYPE_PEDESTRIAN, TYPE_CYCLIST = 1, 2, 4
_PEDESTRIANS = ("pedestrian", "pedestrian with object")
_CYCLISTS = ("cyclist", "bicycle", "motorcyclist", "motorcycle")


def type_of_label(label: str) -> int | None:
    """Waymo Label.Type of a sequence label (None: not a tracked class)."""
    low = label.lower()
    if DEFAULT_SELECTION.is_vehicle(label):
        return TYPE_VEHICLE
    if low in _PEDESTRIANS:
        return TYPE_PEDESTRIAN
    if low in _CYCLISTS:
        return TYPE_CYCLIST
    return None


@dataclass(frozen=True)
class Tracklet:
    """One list entry."""

    id: str
    segment_name: str
    frame_range: tuple[int, int]
    type: int = TYPE_VEHICLE
    difficulty: str | None = None
    profile: str | None = None
    sequence: str | None = None        # a path relative to the list's folder (our lists), else None
    extra: dict = field(default_factory=dict, compare=False)

    @property
    def key(self) -> str:
        return f"{self.segment_name}/{self.id}"


def _tracklet(doc: dict) -> Tracklet:
    a, b = (int(v) for v in doc["frame_range"])
    known = {"id", "segment_name", "frame_range", "type", "difficulty", "profile", "sequence"}
    return Tracklet(str(doc["id"]), str(doc["segment_name"]), (a, b), int(doc["type"]), doc.get("difficulty"),
                    doc.get("profile"), doc.get("sequence"), {k: v for k, v in doc.items() if k not in known})


def read_list(path: str | Path) -> list[Tracklet]:
    """A list file, validated against the ``benchmark`` schema."""
    path = Path(path)
    entries = [_tracklet(d) for d in load_json_validated(path, "benchmark")]
    bad = [t for t in entries if t.frame_range[1] < t.frame_range[0]]
    if bad:
        raise InputError(path, f"tracklet {bad[0].id}: frame_range {list(bad[0].frame_range)} ends before it starts")
    return entries


def read_lists(path: str | Path) -> list[Tracklet]:
    """A list file, or a LiDAR-SOT folder (bench_list.json + easy/medium/hard.json: the difficulty of an entry
    is the file that lists it)."""
    path = Path(path)
    if path.is_file():
        return read_list(path)
    if not path.is_dir():
        raise InputError(path, "no such list file or folder")
    main = path / "bench_list.json"
    levels = {level: read_list(path / f"{level}.json") for level in DIFFICULTIES if (path / f"{level}.json").is_file()}
    if not main.is_file() and not levels:
        raise InputError(path, f"no list here: expected {', '.join(LIST_FILES)}")
    level_of = {t.key: level for level, ts in levels.items() for t in ts}
    entries = read_list(main) if main.is_file() else [t for ts in levels.values() for t in ts]
    return [t if t.difficulty or t.key not in level_of else
            Tracklet(t.id, t.segment_name, t.frame_range, t.type, level_of[t.key], t.profile, t.sequence, t.extra)
            for t in entries]


SequenceResolver = Callable[[Tracklet], Path]


def default_resolver(list_dir: Path, data_dir: Path | None) -> SequenceResolver:
    """Where a tracklet's sequence is: its ``sequence`` path or a folder named ``segment_name`` beside the list,
    else the Waymo segment in ``data_dir`` (``sot_apps.io.waymo.find_waymo_segment``)."""

    def resolve(t: Tracklet) -> Path:
        if t.sequence is not None:
            return list_dir / t.sequence
        beside = list_dir / t.segment_name
        if beside.exists():
            return beside
        if data_dir is None:
            raise InputError(list_dir, f"tracklet {t.id}: no sequence {t.segment_name!r} beside the list and no "
                                       "DATA_DIR to look for it in")
        from ..io.waymo import find_waymo_segment  # the Waymo reader (v1 tfrecords / v2 parquet)

        return Path(find_waymo_segment(data_dir, t.segment_name))

    return resolve


@dataclass(frozen=True)
class ListCriteria:
    """LiDAR-SOT's selection (defaults: the paper's numbers; ``min_frames`` 100 needs >= 10 s sequences)."""

    min_frames: int = 100
    max_frames: int | None = None
    min_points: int = 20
    first_frames: int = 10
    min_displacement_m: float = 2.0
    types: tuple[int, ...] = (TYPE_VEHICLE,)


def build_lists(sequences: list[tuple[Sequence, str]], criteria: ListCriteria = ListCriteria(),
                progress: Callable | None = None) -> list[dict]:
    """List entries for ``(sequence, path relative to the output folder)`` pairs, sorted by segment and id."""
    entries = []
    for seq, rel in sequences:
        tracks = seq.tracks()
        candidates = []
        for tid, trk in sorted(tracks.items()):
            kind = type_of_label(trk.label)
            if kind not in criteria.types:
                continue
            start, end = annotated_span(trk.frames)
            if criteria.max_frames is not None:
                end = min(end, start + criteria.max_frames - 1)
            if end - start + 1 < criteria.min_frames:
                continue
            centres = np.array([trk.box_at(k).center for k in range(start, end + 1)])
            if np.max(np.linalg.norm(centres - centres[0], axis=1)) <= criteria.min_displacement_m:
                continue
            candidates.append((tid, trk, kind, start, end))
        counts: dict[str, list[int]] = {tid: [] for tid, *_ in candidates}
        first = {k for *_, start, end in candidates for k in range(start, min(end, start + criteria.first_frames - 1) + 1)}
        for k in (progress(sorted(first)) if progress else sorted(first)):
            pts = seq.points_world(k)
            for tid, trk, _kind, start, _end in candidates:
                if start <= k < start + criteria.first_frames:
                    counts[tid].append(int(points_in_box(pts, trk.box_at(k)).sum()))
        for tid, trk, kind, start, end in candidates:
            if min(counts[tid]) <= criteria.min_points:
                continue
            mean10 = float(np.mean(counts[tid]))
            entries.append({"id": tid, "type": kind, "segment_name": seq.id, "frame_range": [start, end],
                            "difficulty": difficulty(mean10, DIFFICULTY_THRESHOLDS), "label": trk.label,
                            "mean_points_first10": round(mean10, 2), "sequence": rel})
    return entries


def write_lists(entries: list[dict], out: Path) -> list[Path]:
    """bench_list.json + easy/medium/hard.json in ``out`` (validated)."""
    from ..io.atomic import write_json
    from ..schemas import validate

    out.mkdir(parents=True, exist_ok=True)
    files = {"bench_list.json": entries} | {f"{d}.json": [e for e in entries if e["difficulty"] == d]
                                            for d in DIFFICULTIES}
    paths = []
    for name, doc in files.items():
        validate("benchmark", doc, out / name)
        write_json(out / name, doc)
        paths.append(out / name)
    return paths


def relative(path: Path, start: Path) -> str:
    return os.path.relpath(Path(path).resolve(), Path(start).resolve())
