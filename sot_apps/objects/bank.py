"""The vehicle bank: meshes of real (or any) vehicles to insert into simulated scans.

Layout::

    BANK/index.json                 {"version": 1, "entries": [...]} (schema ``bank``)
    BANK/entries/<id>/mesh.ply      triangle mesh, OBJECT frame (origin = box centre, x forward)
    BANK/entries/<id>/points.ply    the object-frame points it was meshed from

Entry sources:

- a tracker output directory (``track.json`` + ``shape.ply``; the shape is already in the object frame);
- an annotated track of a sequence: the points inside its ground-truth box in every frame (optionally all
  frames but some), transformed into the object frame and aggregated. Ground removal: points lower than
  ``ground_clearance`` (0.15 m) above the box bottom are dropped (annotated boxes sit on the road);
- any mesh file trimesh reads (``.ply``, ``.obj``, ``.stl``, ``.glb``, ...): re-centred on its bounding box.

Point entries are meshed with surfel disks (:mod:`.meshing`), optionally mirror-completed. ``quality`` is
the tracker's mean frame quality for tracker outputs, ``min(1, points / 1000)`` for annotation entries,
and 1 for mesh files.

**Choosing and confirming parts** (:func:`bank_split`): every entry belongs to exactly one part, decided by
its source alone (no file, no state: the same entry is in the same part in every bank). Entries built from a
PandaSet sequence (``source.sequence`` starting with ``pandaset``: the dev tracks the tracker was tuned on and
the generated benchmark's own background) are *choose*. Every other entry goes by its vehicle (source
sequence + track, so the mirrored or re-built copies of one vehicle stay together; mesh files by path):
*choose* when the first 8 bytes of the SHA-256 of that key, as an integer, are divisible by 3, else
*confirm*, so about two thirds of the other sources confirm. ``benchmark make --split`` draws from one part.
"""

from __future__ import annotations

import hashlib
import re
import time
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Iterable

import numpy as np

from tracker import Box

from ..errors import InputError
from ..interrupts import import_trimesh
from ..io.atomic import write_json
from ..io.object_track import ObjectTrack
from ..io.ply import read_ply_mesh, write_ply_mesh, write_ply_points
from ..io.sequence import Sequence
from ..schemas import load_json_validated, validate
from .meshes import SurfelParams, surfel_mesh
from .shapes import BoxMargin, ShapeParams, object_points_by_frame

__all__ = ["BankEntry", "Bank", "SPLITS", "bank_split", "split_entries", "read_bank", "write_bank_index",
           "entry_from_points", "entry_from_track_dir",
           "entries_from_annotations", "entry_from_mesh_file", "aggregate_track_points", "aggregate_tracks_points",
           "track_points_by_frame"]

GROUND_CLEARANCE = 0.15
SPLITS: tuple[str, ...] = ("choose", "confirm")
TUNING_SEQUENCE_PREFIXES: tuple[str, ...] = ("pandaset",)   # tuned on: always in the choosing part


@dataclass
class BankEntry:
    id: str
    mesh: str                      # path relative to the bank root
    points: str | None
    source: dict
    size: dict                     # length, width, height (object-frame bounds of the mesh)
    point_count: int
    quality: float
    label: str | None = None
    mirrored: bool = False
    build_seconds: float | None = None

    def to_json(self) -> dict:
        out = asdict(self)
        return {k: v for k, v in out.items() if v is not None}

    @classmethod
    def from_json(cls, data: dict) -> "BankEntry":
        return cls(**{k: data.get(k) for k in ("id", "mesh", "points", "source", "size", "point_count", "quality",
                                               "label", "mirrored", "build_seconds")})

    def box_size(self) -> tuple[float, float, float]:
        return float(self.size["length"]), float(self.size["width"]), float(self.size["height"])


@dataclass
class Bank:
    root: Path
    entries: list[BankEntry] = field(default_factory=list)

    def get(self, entry_id: str) -> BankEntry:
        for e in self.entries:
            if e.id == entry_id:
                return e
        raise InputError(self.root / "index.json", f"no bank entry {entry_id!r}; entries: "
                                                   f"{', '.join(e.id for e in self.entries[:8]) or '(none)'}")

    def mesh(self, entry_id: str) -> tuple[np.ndarray, np.ndarray]:
        return read_ply_mesh(self.root / self.get(entry_id).mesh)

    def upsert(self, entry: BankEntry) -> None:
        self.entries = [e for e in self.entries if e.id != entry.id] + [entry]


def _vehicle_key(entry: "BankEntry") -> str:
    source = entry.source or {}
    if source.get("track") is not None:
        return f"{source.get('sequence', '')}/{source['track']}"
    return str(source.get("path") or entry.id)


def bank_split(entry: "BankEntry") -> str:
    """``"choose"`` or ``"confirm"``: the part of the bank an entry belongs to (module docstring)."""
    if str((entry.source or {}).get("sequence", "")).lower().startswith(TUNING_SEQUENCE_PREFIXES):
        return "choose"
    digest = hashlib.sha256(_vehicle_key(entry).encode()).digest()
    return "choose" if int.from_bytes(digest[:8], "big") % 3 == 0 else "confirm"


def split_entries(entries: Iterable["BankEntry"], split: str | None) -> list["BankEntry"]:
    """The entries of one part (``None`` or ``"all"``: every entry)."""
    if split in (None, "all"):
        return list(entries)
    if split not in SPLITS:
        raise ValueError(f"unknown bank split {split!r}; known: {', '.join(SPLITS)}, all")
    return [e for e in entries if bank_split(e) == split]


def _safe_id(text: str) -> str:
    return re.sub(r"[^A-Za-z0-9_.-]+", "_", text).strip("_")[:80] or "entry"


def read_bank(root: str | Path, must_exist: bool = True) -> Bank:
    root = Path(root)
    path = root / "index.json"
    if not path.is_file():
        if must_exist:
            raise InputError(path, "not a vehicle bank (index.json is missing); build one with `sot-apps bank build`")
        return Bank(root, [])
    doc = load_json_validated(path, "bank")
    bank = Bank(root, [BankEntry.from_json(e) for e in doc["entries"]])
    for e in bank.entries:
        if not (root / e.mesh).is_file():
            raise InputError(path, f"entry {e.id!r}: mesh file {e.mesh!r} does not exist")
    return bank


def write_bank_index(bank: Bank) -> Path:
    doc = {"version": 1, "entries": [e.to_json() for e in sorted(bank.entries, key=lambda e: e.id)]}
    path = bank.root / "index.json"
    validate("bank", doc, path)
    write_json(path, doc)
    return path


def entry_from_points(bank_root: Path, entry_id: str, points_object: np.ndarray, source: dict, quality: float,
                      label: str | None = None, mirror: bool = False, params: SurfelParams = SurfelParams(),
                      size: tuple[float, float, float] | None = None) -> BankEntry:
    """Mesh object-frame points with surfels and store them as an entry (files written, index not)."""
    start = time.perf_counter()
    entry_id = _safe_id(entry_id)
    vertices, faces, used = surfel_mesh(points_object, params, mirror=mirror)
    directory = bank_root / "entries" / entry_id
    write_ply_mesh(directory / "mesh.ply", vertices, faces)
    write_ply_points(directory / "points.ply", np.asarray(points_object, dtype=np.float64))
    if size is None:
        extent = used.max(axis=0) - used.min(axis=0)
        size = (float(extent[0]), float(extent[1]), float(extent[2]))
    return BankEntry(entry_id, f"entries/{entry_id}/mesh.ply", f"entries/{entry_id}/points.ply", source,
                     {"length": float(size[0]), "width": float(size[1]), "height": float(size[2])},
                     int(len(points_object)), float(np.clip(quality, 0.0, 1.0)), label, mirror,
                     round(time.perf_counter() - start, 4))


def entry_from_track_dir(bank_root: Path, track_dir: str | Path, mirror: bool = False,
                         params: SurfelParams = SurfelParams()) -> BankEntry:
    from ..io.tracks import read_track

    header, track = read_track(track_dir)
    shape = track.shape_points
    if len(shape) < 3:
        raise InputError(track_dir, f"shape has only {len(shape)} points; cannot build a bank entry")
    quality = track.mean_score if len(track) else 0.0
    source = {"kind": "track", "sequence": header.sequence, "track": track.object_id, "path": str(track_dir),
              "tracker_mode": header.mode}
    return entry_from_points(bank_root, f"{header.sequence}_{track.object_id}", shape, source, quality,
                             track.label or None, mirror, params, size=track.size)


def track_points_by_frame(seq: Sequence, track_ids: list[str], exclude_frames: Iterable[int] = (),
                          ground_clearance: float = GROUND_CLEARANCE, progress: bool = False
                          ) -> dict[str, dict[int, np.ndarray]]:
    """Per track and frame, the object-frame points of the track's box (each sweep read once).

    Annotated boxes describe an object when the LiDAR saw it (PandaSet's do, and so do the synthetic
    world's), so each box is stamped with the median capture time of the points near it. Each point is
    then put into the object frame of the box interpolated to ITS OWN capture time, which undoes the
    rolling-scan smear of moving vehicles. Points below ``ground_clearance`` above the box bottom are dropped.
    """
    tracks = seq.tracks()
    missing = [t for t in track_ids if t not in tracks]
    if missing:
        raise InputError(seq.root, f"no annotated track {missing[0]!r}")
    excluded = set(int(k) for k in exclude_frames)
    boxes = {tid: ObjectTrack.from_boxes(tid, tracks[tid].label,
                                         tracks[tid].boxes_by_frame())
             for tid in track_ids}
    params = ShapeParams(near=BoxMargin(scale=(1.3, 1.3, 1.05)), stamp=BoxMargin(), min_stamp_points=1,
                         keep=BoxMargin(scale=(1.02, 1.02, 1.02)), ground_clearance=ground_clearance, end="hold")
    points, _ = object_points_by_frame(seq, boxes, params, [k for k in range(len(seq.frames)) if k not in excluded],
                                       progress)
    return points


def aggregate_tracks_points(seq: Sequence, track_ids: list[str], exclude_frames: Iterable[int] = (),
                            ground_clearance: float = GROUND_CLEARANCE, progress: bool = False
                            ) -> dict[str, tuple[np.ndarray, list[int]]]:
    """Object-frame points of annotated tracks aggregated over their frames (see track_points_by_frame)."""
    per = track_points_by_frame(seq, track_ids, exclude_frames, ground_clearance, progress)
    return {tid: (np.vstack([per[tid][k] for k in sorted(per[tid])]) if per[tid] else np.zeros((0, 3)),
                  sorted(per[tid])) for tid in track_ids}


def aggregate_track_points(seq: Sequence, track_id: str, exclude_frames: Iterable[int] = ()
                           ) -> tuple[np.ndarray, list[int], Box]:
    """One track's aggregated object-frame points, the frames used and its first box."""
    points, used = aggregate_tracks_points(seq, [track_id], exclude_frames)[track_id]
    return points, used, seq.tracks()[track_id].box(0)


def entries_from_annotations(bank_root: Path, seq: Sequence, track_ids: list[str], mirror: bool = False,
                             params: SurfelParams = SurfelParams(), min_points: int = 50,
                             progress: bool = False) -> tuple[list[BankEntry], list[str]]:
    """Entries for annotated tracks; returns (entries, messages about skipped tracks)."""
    entries, skipped = [], []
    tracks = seq.tracks()
    start = time.perf_counter()
    aggregated = aggregate_tracks_points(seq, track_ids, progress=progress)
    read_seconds = (time.perf_counter() - start) / max(1, len(track_ids))
    for tid in track_ids:
        start = time.perf_counter()
        points, frames = aggregated[tid]
        box = tracks[tid].box(0)
        if len(points) < min_points:
            skipped.append(f"{tid}: only {len(points)} points (< {min_points})")
            continue
        source = {"kind": "annotations", "sequence": seq.id, "track": tid, "frames": len(frames)}
        entry = entry_from_points(bank_root, f"{seq.id}_{tid[:8]}", points, source,
                                  quality=min(1.0, len(points) / 1000.0), label=tracks[tid].label, mirror=mirror,
                                  params=params, size=(box.length, box.width, box.height))
        entry.build_seconds = round(time.perf_counter() - start + read_seconds, 4)
        entries.append(entry)
    return entries, skipped


def entry_from_mesh_file(bank_root: Path, path: str | Path, entry_id: str | None = None,
                         label: str | None = None) -> BankEntry:
    trimesh = import_trimesh()

    path = Path(path)
    start = time.perf_counter()
    try:
        mesh = trimesh.load(path, force="mesh", process=False)
    except Exception as exc:  # noqa: BLE001 - trimesh raises many types on bad files
        raise InputError(path, f"cannot read mesh ({type(exc).__name__}: {exc})") from exc
    if len(getattr(mesh, "faces", [])) == 0:
        raise InputError(path, "mesh has no triangles")
    vertices = np.asarray(mesh.vertices, dtype=np.float64)
    lo, hi = vertices.min(axis=0), vertices.max(axis=0)
    vertices = vertices - (lo + hi) / 2.0
    entry_id = _safe_id(entry_id or path.stem)
    rel = f"entries/{entry_id}/mesh.ply"
    write_ply_mesh(bank_root / rel, vertices, np.asarray(mesh.faces))
    ext = hi - lo
    return BankEntry(entry_id, rel, None, {"kind": "mesh", "path": str(path)},
                     {"length": float(ext[0]), "width": float(ext[1]), "height": float(ext[2])},
                     int(len(vertices)), 1.0, label, False, round(time.perf_counter() - start, 4))


def is_track_dir(path: Path) -> bool:
    return (path / "track.json").is_file()


def bank_summary_rows(bank: Bank) -> list[list[str]]:
    rows = []
    for e in bank.entries:
        s = e.size
        rows.append([e.id, bank_split(e), e.label or "-", f"{s['length']:.2f}x{s['width']:.2f}x{s['height']:.2f}",
                     str(e.point_count), f"{e.quality:.2f}", str(e.source.get("kind", "")) + (f" ({e.source['tracker_mode']})" if e.source.get("tracker_mode") else ""),
                     str(e.source.get("sequence", e.source.get("path", ""))), str(e.source.get("track", "-"))])
    return rows
