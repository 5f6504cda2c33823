"""Realism of a generated benchmark: points in the ground-truth box versus range, inserted against real vehicles.

Real: every annotated vehicle box (:mod:`sot_apps.objects.selection`'s vehicle rule) of the background over the benchmark's
frames, in the background's own sweeps. Inserted: every inserted vehicle's box in the copies' sweeps (the first
``max_copies`` copies). Both count the sweep points inside the box (the LiDAR-SOT difficulty statistic), against
the box centre's horizontal distance from the sensor. Occlusion is part of both (real cars hide behind real
cars; inserted ones behind real and inserted ones).
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from itertools import pairwise
from pathlib import Path

import numpy as np

from tracker import points_in_box

from ..errors import InputError
from ..io import open_sequence
from ..objects.selection import DEFAULT_SELECTION

__all__ = ["RangeCurves", "points_versus_range", "format_realism", "write_plot", "RANGE_BINS_M", "ReplicaTrack",
           "replica_counts", "format_replicas"]

RANGE_BINS_M = (0.0, 5.0, 10.0, 15.0, 20.0, 30.0, 40.0, 50.0, 60.0, 80.0)


@dataclass(frozen=True)
class RangeCurves:
    real: np.ndarray       # (N, 2) range m, points
    inserted: np.ndarray   # (M, 2)

    def binned(self, which: np.ndarray) -> list[dict]:
        rows = []
        for lo, hi in pairwise(RANGE_BINS_M):
            sel = which[(which[:, 0] >= lo) & (which[:, 0] < hi), 1]
            rows.append({"range_m": [lo, hi], "n": int(sel.size),
                         "median": float(np.median(sel)) if sel.size else None,
                         "p25": float(np.percentile(sel, 25)) if sel.size else None,
                         "p75": float(np.percentile(sel, 75)) if sel.size else None})
        return rows

    def to_dict(self) -> dict:
        return {"bins_m": list(RANGE_BINS_M), "real": self.binned(self.real), "inserted": self.binned(self.inserted)}


def _box_samples(seq, frames, ids=None) -> list[tuple[float, int]]:
    out = []
    for k in frames:
        anns = [a for a in seq.annotations[k]
                if (a.track_id in ids if ids is not None else DEFAULT_SELECTION.is_vehicle(a.label))]
        if not anns:
            continue
        pts = seq.points_world(k)
        sensor = (seq.frames[k].world_from_ego @ seq.ego_from_lidar)[:2, 3]
        for a in anns:
            out.append((float(np.hypot(*(a.box.center[:2] - sensor))), int(points_in_box(pts, a.box).sum())))
    return out


def points_versus_range(benchmark_dir: Path, max_copies: int = 5) -> RangeCurves:
    make = benchmark_dir / "make.json"
    if not make.is_file():
        raise InputError(make, "not a `benchmark make` output (make.json is missing)")
    config = json.loads(make.read_text())["config"]
    a, b = config["frames"]
    real = _box_samples(open_sequence(config["background"]), range(a, b))
    copies = sorted(p.parent for p in benchmark_dir.glob("*/inserted.json"))[:max_copies]
    inserted = []
    for copy in copies:
        ids = {v["id"] for v in json.loads((copy / "inserted.json").read_text())["vehicles"]}
        seq = open_sequence(copy)
        inserted += _box_samples(seq, range(len(seq)), ids)
    return RangeCurves(np.array(real, dtype=np.float64).reshape(-1, 2), np.array(inserted, dtype=np.float64).reshape(-1, 2))


@dataclass(frozen=True)
class ReplicaTrack:
    """A real track and its simulated copy (``benchmark make --replicas``), frame by frame."""

    track: str             # the real track id
    range_m: np.ndarray    # (F,) box centre's horizontal distance from the sensor, real box
    real: np.ndarray       # (F,) points in the real box, real sweep
    copy: np.ndarray       # (F,) points in the copy's box, the copy's sweep


def replica_counts(benchmark_dir: Path) -> list[ReplicaTrack]:
    """Real against copy point counts of a replica benchmark, over each listed tracklet's frames ([] when the
    benchmark has no replicas)."""
    config = json.loads((benchmark_dir / "make.json").read_text())["config"]
    if not config.get("replicas"):
        return []
    first = int(config["frames"][0])
    background = open_sequence(config["background"])
    real_tracks = background.tracks()
    out = []
    for copy_dir in sorted(p.parent for p in benchmark_dir.glob("*/inserted.json")):
        copy = open_sequence(copy_dir)
        copy_tracks = copy.tracks()
        for entry in json.loads((benchmark_dir / "benchmark.json").read_text()):
            if entry["segment_name"] != copy.id or entry["id"] not in copy_tracks:
                continue
            tid = background.resolve_track_id(entry["id"].removeprefix("rep_"))
            rows = []
            for i in range(entry["frame_range"][0], entry["frame_range"][1] + 1):
                k = first + i
                real_box, copy_box = real_tracks[tid].box_at(k), copy_tracks[entry["id"]].box_at(i)
                if real_box is None or copy_box is None:
                    continue
                sensor = (background.frames[k].world_from_ego @ background.ego_from_lidar)[:2, 3]
                rows.append((float(np.hypot(*(real_box.center[:2] - sensor))),
                             int(points_in_box(background.points_world(k), real_box).sum()),
                             int(points_in_box(copy.points_world(i), copy_box).sum())))
            a = np.array(rows, dtype=np.float64).reshape(-1, 3)
            out.append(ReplicaTrack(tid, a[:, 0], a[:, 1], a[:, 2]))
    return out


def format_replicas(tracks: list[ReplicaTrack], first_frames: int = 10) -> str:
    """Per track (first ``first_frames`` frames, as LiDAR-SOT's difficulty) and per range band (all frames)."""
    lines = [f"replicas: real track against its simulated copy; points in the box, mean over the first {first_frames} "
             "frames and summed over all frames", "",
             "| track | range at start (m) | real (first 10) | copy (first 10) | copy / real | all frames copy / real |",
             "|---|---:|---:|---:|---:|---:|"]
    ratio = lambda c, r: f"{c / r:.2f}" if r else "—"  # noqa: E731
    for t in sorted(tracks, key=lambda t: t.range_m[0] if len(t.range_m) else np.inf):
        if not len(t.real):
            continue
        r10, c10 = float(t.real[:first_frames].mean()), float(t.copy[:first_frames].mean())
        lines.append(f"| {t.track[:8]} | {t.range_m[0]:.1f} | {r10:.0f} | {c10:.1f} | {ratio(c10, r10)} | "
                     f"{ratio(t.copy.sum(), t.real.sum())} |")
    rng = np.concatenate([t.range_m for t in tracks]) if tracks else np.zeros(0)
    real = np.concatenate([t.real for t in tracks]) if tracks else np.zeros(0)
    copy = np.concatenate([t.copy for t in tracks]) if tracks else np.zeros(0)
    lines += ["", "| range (m) | frames | real median | copy median | copy / real (sums) |", "|---|---:|---:|---:|---:|"]
    for lo, hi in pairwise(RANGE_BINS_M):
        sel = (rng >= lo) & (rng < hi)
        if sel.any():
            lines.append(f"| {lo:.0f}-{hi:.0f} | {int(sel.sum())} | {np.median(real[sel]):.0f} | {np.median(copy[sel]):.0f} | "
                         f"{ratio(copy[sel].sum(), real[sel].sum())} |")
    sel = rng >= RANGE_BINS_M[-1]
    if sel.any():
        lines.append(f"| {RANGE_BINS_M[-1]:.0f}+ | {int(sel.sum())} | {np.median(real[sel]):.0f} | {np.median(copy[sel]):.0f} | "
                     f"{ratio(copy[sel].sum(), real[sel].sum())} |")
    return "\n".join(lines)


def format_realism(curves: RangeCurves) -> str:
    lines = ["points in the ground-truth box versus range: median [p25, p75] (n boxes)", "",
             "| range (m) | real vehicles | inserted vehicles | inserted / real (median) |", "|---|---:|---:|---:|"]
    for r, s in zip(curves.binned(curves.real), curves.binned(curves.inserted), strict=True):
        cell = lambda x: "—" if x["n"] == 0 else f"{x['median']:.0f} [{x['p25']:.0f}, {x['p75']:.0f}] ({x['n']})"  # noqa: E731
        ratio = (f"{s['median'] / r['median']:.2f}" if r["n"] and s["n"] and r["median"] else "—")
        lines.append(f"| {r['range_m'][0]:.0f}-{r['range_m'][1]:.0f} | {cell(r)} | {cell(s)} | {ratio} |")
    return "\n".join(lines)


def write_plot(curves: RangeCurves, path: Path, width: int = 900, height: int = 560) -> None:
    """Scatter (log points, +1) and binned medians of real and inserted vehicles; metre axis, legend."""
    import cv2

    from ..io.atomic import write_bytes

    img = np.full((height, width, 3), 255, np.uint8)
    left, right, top, bottom = 80, 20, 40, 60
    x_max, y_max = RANGE_BINS_M[-1], 4.0  # log10(points + 1) up to 10^4
    px = lambda r: int(left + (width - left - right) * min(r, x_max) / x_max)  # noqa: E731
    py = lambda n: int(height - bottom - (height - top - bottom) * min(np.log10(n + 1.0), y_max) / y_max)  # noqa: E731
    font = cv2.FONT_HERSHEY_SIMPLEX
    for r in range(0, int(x_max) + 1, 10):
        cv2.line(img, (px(r), top), (px(r), height - bottom), (230, 230, 230), 1)
        cv2.putText(img, str(r), (px(r) - 8, height - bottom + 20), font, 0.45, (0, 0, 0), 1, cv2.LINE_AA)
    for e in range(0, int(y_max) + 1):
        n = 10 ** e - 1
        cv2.line(img, (left, py(n)), (width - right, py(n)), (230, 230, 230), 1)
        cv2.putText(img, f"{10 ** e}", (left - 55, py(n) + 5), font, 0.45, (0, 0, 0), 1, cv2.LINE_AA)
    cv2.rectangle(img, (left, top), (width - right, height - bottom), (0, 0, 0), 1)
    cv2.putText(img, "range from the sensor (m)", (width // 2 - 100, height - 15), font, 0.55, (0, 0, 0), 1, cv2.LINE_AA)
    cv2.putText(img, "points in box + 1 (log)", (5, top - 12), font, 0.5, (0, 0, 0), 1, cv2.LINE_AA)
    styles = [("real vehicles (annotated)", curves.real, (200, 90, 20)), ("inserted vehicles", curves.inserted, (40, 110, 230))]
    for _, data, colour in styles:
        light = tuple(int(c + (255 - c) * 0.6) for c in colour)
        for r, n in data:
            cv2.circle(img, (px(r), py(n)), 2, light, -1, cv2.LINE_AA)
    for _, data, colour in styles:
        pts = [(px((row["range_m"][0] + row["range_m"][1]) / 2), py(row["median"])) for row in curves.binned(data)
               if row["n"]]
        for p, q in pairwise(pts):
            cv2.line(img, p, q, colour, 2, cv2.LINE_AA)
        for p in pts:
            cv2.circle(img, p, 4, colour, -1, cv2.LINE_AA)
    for i, (name, data, colour) in enumerate(styles):
        y = top + 20 + 22 * i
        cv2.line(img, (width - 410, y - 5), (width - 380, y - 5), colour, 2)
        cv2.putText(img, f"{name}: median per bin ({len(data)} boxes)", (width - 372, y), font, 0.45, (0, 0, 0), 1,
                    cv2.LINE_AA)
    ok, data = cv2.imencode(".png", img)
    if not ok:
        raise InputError(path, "could not encode the PNG")
    write_bytes(path, data.tobytes())
