"""Detection evaluation: BEV / 3D average precision by range band, and identity coverage of tracks.

AP follows the usual protocol (KITTI / Waymo style): detections of all frames sorted by score; each is a
true positive when it overlaps a not yet matched ground-truth box of its frame with IoU >= the threshold
(the best such box), else a false positive; AP = area under the interpolated precision-recall curve,
sampled at 40 recall points (KITTI's R40). Range bands use the distance from the ego (BEV) of the ground
truth box for ground truth and of the detection for detections, so a band is scored like a separate
dataset. Ground-truth boxes with fewer than ``min_points`` sweep points are ignored (neither counted
nor penalised when detected), as Waymo does with empty boxes.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Mapping, Sequence

import numpy as np

from tracker import FrameDetections, iou_3d_batch, iou_bev_batch

from ..objects.box_points import count_points_in_boxes

__all__ = ["APConfig", "OperatingPoint", "GroundTruthFrame", "ground_truth_frames", "average_precision", "ap_table",
           "identity_coverage", "operating_point"]


@dataclass(frozen=True)
class APConfig:
    iou_thresholds: tuple[float, ...] = (0.5, 0.7)
    range_bands: tuple[tuple[float, float], ...] = ((0.0, 20.0), (20.0, 40.0), (40.0, 60.0), (0.0, 60.0))
    min_points: int = 1
    recall_points: int = 40


@dataclass(frozen=True)
class OperatingPoint:
    """The criteria of the recall / precision operating point (issue 27's target): detections scored
    >= ``min_score``; a ground-truth box COUNTS when it is within ``max_range`` (BEV, from the ego), holds >=
    ``min_points`` sweep points and its label is one of ``labels`` (None: every box of the truth). Matching
    at IoU >= ``iou_threshold`` (``kind`` "bev" or "3d")."""

    min_score: float = 0.5
    iou_threshold: float = 0.5
    max_range: float = 40.0
    min_points: int = 50
    kind: str = "bev"
    labels: tuple[str, ...] | None = None


@dataclass(frozen=True)
class GroundTruthFrame:
    """One frame's ground-truth boxes (M, 7), their point counts, track ids, labels, and the ego position."""

    boxes: np.ndarray
    points: np.ndarray
    ego_xy: np.ndarray
    track_ids: tuple[str, ...] = field(default=())
    labels: tuple[str, ...] = field(default=())


def ground_truth_frames(sequence, labels: Sequence[str] | None = None, frames: Sequence[int] | None = None
                        ) -> dict[int, GroundTruthFrame]:
    """Ground truth of a :class:`~sot_apps.io.Sequence` per frame: boxes of ``labels`` (case-insensitive;
    None = all) with their point counts and the ego position."""
    wanted = None if labels is None else {lbl.lower() for lbl in labels}
    out = {}
    for k in (range(len(sequence)) if frames is None else frames):
        anns = [a for a in (sequence.annotations[k] if sequence.annotations else [])
                if wanted is None or a.label.lower() in wanted]
        boxes = np.array([[*a.box.to_array(), a.box.roll, a.box.pitch] for a in anns]).reshape(-1, 9)
        out[k] = GroundTruthFrame(boxes, count_points_in_boxes(sequence.points_world(k), boxes),
                                  np.asarray(sequence.frames[k].world_from_ego)[:2, 3], tuple(a.track_id for a in anns),
                                  tuple(a.label for a in anns))
    return out


def _pairwise_iou(dets: np.ndarray, gts: np.ndarray, kind: str) -> np.ndarray:
    """(len(dets), len(gts)) IoU; boxes (N, 7) or (N, 9) with roll and pitch. BEV: the footprints; 3D: the
    tilted boxes' exact IoU, computed only for pairs whose footprints overlap (the others are 0)."""
    if len(dets) == 0 or len(gts) == 0:
        return np.zeros((len(dets), len(gts)))
    a9, b9 = _with_tilt(dets), _with_tilt(gts)
    a = np.repeat(a9, len(gts), axis=0)
    b = np.tile(b9, (len(dets), 1))
    iou = iou_bev_batch(a[:, :7], b[:, :7])
    if kind != "bev":
        overlap = iou > 0.0
        iou = np.zeros(len(a))
        iou[overlap] = iou_3d_batch(a[overlap], b[overlap])
    return iou.reshape(len(dets), len(gts))


def _with_tilt(boxes: np.ndarray) -> np.ndarray:
    """(N, 9) boxes: (N, 7) level ones with roll = pitch = 0."""
    boxes = np.asarray(boxes, dtype=np.float64)
    return boxes if boxes.shape[1] == 9 else np.hstack([boxes, np.zeros((len(boxes), 2))])


def average_precision(detections: Mapping[int, FrameDetections], truth: Mapping[int, GroundTruthFrame],
                      iou_threshold: float, kind: str = "bev", band: tuple[float, float] = (0.0, np.inf),
                      min_points: int = 1, recall_points: int = 40) -> dict[str, float]:
    """AP (in [0, 1]) of ``detections`` against ``truth`` over the frames of ``truth``; also the number of
    ground-truth boxes, detections, and the recall at the end of the curve."""
    scores, hits = [], []
    n_gt = 0
    for k, gt in truth.items():
        det = detections.get(k, FrameDetections.empty())
        gd = np.hypot(gt.boxes[:, 0] - gt.ego_xy[0], gt.boxes[:, 1] - gt.ego_xy[1])
        counted = (gt.points >= min_points) & (gd >= band[0]) & (gd < band[1])
        dd = np.hypot(det.boxes[:, 0] - gt.ego_xy[0], det.boxes[:, 1] - gt.ego_xy[1])
        in_band = (dd >= band[0]) & (dd < band[1])
        n_gt += int(counted.sum())
        iou = _pairwise_iou(det.boxes, gt.boxes, kind)
        taken = np.zeros(len(gt.boxes), dtype=bool)
        for i in np.argsort(-det.scores, kind="stable"):
            candidates = np.where(~taken & (iou[i] >= iou_threshold), iou[i], -1.0)
            j = int(np.argmax(candidates)) if len(candidates) else -1
            if j >= 0 and candidates[j] >= 0:
                taken[j] = True
                if counted[j]:
                    scores.append(det.scores[i])
                    hits.append(True)
                # a match to an ignored box (empty, or outside the band) is neither TP nor FP
            elif in_band[i]:
                scores.append(det.scores[i])
                hits.append(False)
    if n_gt == 0:
        return {"ap": float("nan"), "n_gt": 0, "n_det": len(scores), "recall": float("nan")}
    order = np.argsort(-np.asarray(scores), kind="stable")
    tp = np.cumsum(np.asarray(hits, dtype=np.float64)[order])
    fp = np.cumsum(~np.asarray(hits, dtype=bool)[order])
    recall = tp / n_gt
    precision = tp / np.maximum(tp + fp, 1e-12)
    # interpolated precision: the best precision at any recall >= r
    interp = np.maximum.accumulate(precision[::-1])[::-1] if len(precision) else precision
    samples = np.linspace(1.0 / recall_points, 1.0, recall_points)
    ap = 0.0
    for r in samples:
        ok = recall >= r - 1e-12
        ap += float(interp[ok][0]) if ok.any() else 0.0
    return {"ap": ap / recall_points, "n_gt": n_gt, "n_det": len(scores),
            "recall": float(recall[-1]) if len(recall) else 0.0}


def ap_table(detections: Mapping[int, FrameDetections], truth: Mapping[int, GroundTruthFrame],
             config: APConfig = APConfig(), kinds: Sequence[str] = ("bev",)) -> list[dict]:
    """One row per (kind, IoU threshold, range band)."""
    rows = []
    for kind in kinds:
        for thr in config.iou_thresholds:
            for band in config.range_bands:
                r = average_precision(detections, truth, thr, kind, band, config.min_points, config.recall_points)
                rows.append({"kind": kind, "iou": thr, "band": f"{band[0]:g}-{band[1]:g} m", **r})
    return rows


def operating_point(detections: Mapping[int, FrameDetections], truth: Mapping[int, GroundTruthFrame],
                    criteria: OperatingPoint = OperatingPoint()) -> dict[str, float]:
    """Recall and precision of the detections scored >= ``criteria.min_score``, KITTI's rule for boxes that
    do not count. Per frame, detections best score first, each is matched to the not yet matched
    ground-truth box (ANY box of ``truth``: every label, range and point count) it overlaps most at IoU >=
    the threshold. Matched to a box that counts (``OperatingPoint``): a true positive; matched to one that
    does not (too far, too few points, another class): ignored, neither true nor false (a don't-care
    region); unmatched: a false positive if within ``max_range`` of the ego (farther ones are not scored).
    Recall: the counting boxes matched over all counting boxes; precision: true over true + false."""
    c = criteria
    wanted_labels = None if c.labels is None else {lbl.lower() for lbl in c.labels}
    found = wanted = false = 0
    for k, gt in truth.items():
        det = detections.get(k, FrameDetections.empty())
        confident = det.scores >= c.min_score
        boxes, scores = det.boxes[confident], det.scores[confident]
        iou = _pairwise_iou(boxes, gt.boxes, c.kind)
        gd = np.hypot(gt.boxes[:, 0] - gt.ego_xy[0], gt.boxes[:, 1] - gt.ego_xy[1])
        dd = np.hypot(boxes[:, 0] - gt.ego_xy[0], boxes[:, 1] - gt.ego_xy[1])
        want = (gd < c.max_range) & (gt.points >= c.min_points)
        if wanted_labels is not None:
            if len(gt.labels) != len(gt.boxes):
                raise ValueError(f"frame {k}: OperatingPoint.labels needs the ground truth's labels")
            want &= np.array([lbl.lower() in wanted_labels for lbl in gt.labels], dtype=bool).reshape(-1)
        wanted += int(want.sum())
        taken = np.zeros(len(gt.boxes), dtype=bool)
        for i in np.argsort(-scores, kind="stable"):
            candidates = np.where(~taken & (iou[i] >= c.iou_threshold), iou[i], -1.0)
            if len(candidates) and candidates.max() >= 0:
                j = int(np.argmax(candidates))
                taken[j] = True
                found += int(want[j])           # a match to a box that does not count is ignored
            elif dd[i] < c.max_range:
                false += 1
    kept = found + false
    return {"recall": found / wanted if wanted else float("nan"), "precision": found / kept if kept else float("nan"),
            "n_gt": wanted, "n_det": kept}


def identity_coverage(tracks: Mapping[str, Mapping[int, np.ndarray]], truth: Mapping[int, GroundTruthFrame],
                      iou_threshold: float = 0.5, min_points: int = 1, max_range: float = np.inf) -> dict[str, float]:
    """Share of ground-truth frames covered by ONE track: for every ground-truth object, the predicted track
    that overlaps it (BEV IoU >= threshold) in the most frames is its track; the measure is the number of
    frames that track covers over all ground-truth frames (with >= ``min_points`` points, within ``max_range``
    of the ego). 1 = every object
    is followed by a single track in every frame; fragmentation and misses lower it."""
    names = list(tracks)
    hits: dict[str, dict[str, int]] = {}    # ground-truth id -> track name -> frames covered
    counts: dict[str, int] = {}
    for k, gt in truth.items():
        near = np.hypot(gt.boxes[:, 0] - gt.ego_xy[0], gt.boxes[:, 1] - gt.ego_xy[1]) < max_range
        keep = np.flatnonzero((gt.points >= min_points) & near)
        if len(keep) == 0:
            continue
        present = [n for n in names if k in tracks[n]]
        boxes = np.array([tracks[n][k] for n in present]).reshape(-1, 7)
        iou = _pairwise_iou(gt.boxes[keep], boxes, "bev")      # (ground truth, tracks)
        for row, j in enumerate(keep):
            tid = gt.track_ids[j]
            counts[tid] = counts.get(tid, 0) + 1
            per = hits.setdefault(tid, {})
            for col in np.flatnonzero(iou[row] >= iou_threshold):
                per[present[col]] = per.get(present[col], 0) + 1
    total = sum(counts.values())
    if total == 0:
        return {"coverage": float("nan"), "gt_frames": 0, "objects": 0}
    covered = sum(max(per.values(), default=0) for per in hits.values())
    return {"coverage": covered / total, "gt_frames": total, "objects": len(counts)}


def format_ap_table(rows: list[dict]) -> str:
    """Markdown table: one row per (kind, IoU), one column per range band (AP in %, recall in brackets)."""
    bands = list(dict.fromkeys(r["band"] for r in rows))
    lines = ["| AP (recall) | " + " | ".join(bands) + " |", "|---|" + "---|" * len(bands)]
    for kind, thr in dict.fromkeys((r["kind"], r["iou"]) for r in rows):
        cells = []
        for band in bands:
            r = next(x for x in rows if x["kind"] == kind and x["iou"] == thr and x["band"] == band)
            cells.append("—" if not np.isfinite(r["ap"]) else f"{100 * r['ap']:.1f} ({100 * r['recall']:.0f} %)")
        lines.append(f"| {kind.upper()} @ {thr:g} | " + " | ".join(cells) + " |")
    n_gt = {r["band"]: r["n_gt"] for r in rows}
    lines.append("| GT boxes | " + " | ".join(str(n_gt[b]) for b in bands) + " |")
    return "\n".join(lines)


def _subset(gt: GroundTruthFrame, keep: np.ndarray) -> GroundTruthFrame:
    keep = np.asarray(keep, dtype=bool).reshape(-1)
    return GroundTruthFrame(gt.boxes[keep], gt.points[keep], gt.ego_xy,
                            tuple(t for t, kept in zip(gt.track_ids, keep, strict=True) if kept),
                            tuple(lbl for lbl, kept in zip(gt.labels, keep, strict=True) if kept) if gt.labels else ())


def only_objects(truth: Mapping[int, GroundTruthFrame], track_ids) -> dict[int, GroundTruthFrame]:
    """``truth`` restricted to the ground-truth objects ``track_ids`` (e.g. the moving vehicles)."""
    wanted = set(track_ids)
    return {k: _subset(gt, np.array([tid in wanted for tid in gt.track_ids], dtype=bool)) for k, gt in truth.items()}


def only_labels(truth: Mapping[int, GroundTruthFrame], labels) -> dict[int, GroundTruthFrame]:
    """``truth`` restricted to the boxes whose label is one of ``labels`` (case-insensitive)."""
    wanted = {lbl.lower() for lbl in labels}
    return {k: _subset(gt, np.array([lbl.lower() in wanted for lbl in gt.labels], dtype=bool)) for k, gt in truth.items()}


def autolabel_quality(candidates: Mapping[str, tuple[Mapping[int, FrameDetections], Mapping | None]],
                      truth: Mapping[int, GroundTruthFrame], config: APConfig = APConfig(),
                      moving: Sequence[str] | None = None) -> list[dict]:
    """Per candidate (name -> (boxes per frame, tracks or None)): BEV and 3D AP at each IoU threshold over all
    ranges up to the last band's end, and the identity coverage of its tracks (IoU 0.5), over all objects and,
    with ``moving`` (ground-truth ids), over those objects only (``coverage_moving``)."""
    band = (0.0, max(b[1] for b in config.range_bands))
    moving_truth = None if moving is None else only_objects(truth, moving)
    rows = []
    for name, (boxes, tracks) in candidates.items():
        row: dict = {"name": name}
        for kind in ("bev", "3d"):
            for thr in config.iou_thresholds:
                row[f"{kind}_ap_{thr:g}"] = average_precision(boxes, truth, thr, kind, band, config.min_points,
                                                              config.recall_points)["ap"]
        row["coverage"] = (identity_coverage(tracks, truth, 0.5, config.min_points, band[1])["coverage"]
                           if tracks is not None else float("nan"))
        if moving_truth is not None:
            row["coverage_moving"] = (identity_coverage(tracks, moving_truth, 0.5, config.min_points,
                                                        band[1])["coverage"] if tracks is not None else float("nan"))
        rows.append(row)
    return rows


def format_quality_table(rows: list[dict]) -> str:
    keys = [k for k in rows[0] if k.endswith(("_0.5", "_0.7"))]
    coverages = [k for k in ("coverage", "coverage_moving") if k in rows[0]]
    names = {"coverage": "one-track coverage", "coverage_moving": "one-track coverage (moving)"}
    head = "| labels | " + " | ".join(k.replace("_ap_", " AP@").upper().replace("AP@", "AP@") for k in keys) \
        + " | " + " | ".join(names[k] for k in coverages) + " |"
    lines = [head, "|---|" + "---|" * (len(keys) + len(coverages))]
    for r in rows:
        cov = " | ".join("—" if not np.isfinite(r[k]) else f"{100 * r[k]:.1f} %" for k in coverages)
        lines.append(f"| {r['name']} | " + " | ".join(f"{100 * r[k]:.1f}" for k in keys) + f" | {cov} |")
    return "\n".join(lines)


def rows_for_json(rows: list[dict]) -> list[dict]:
    """``rows`` with NaN (no ground truth, no tracks) as None, for JSON."""
    return [{k: (None if isinstance(v, float) and not np.isfinite(v) else v) for k, v in r.items()} for r in rows]
