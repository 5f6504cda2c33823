"""LiDAR-SOT-style scoring of tracker results on a sequence's annotated tracks.

This module scores results it is given; it never runs the tracker (:mod:`sot_apps.bench.sequence_eval` runs the
presets for ``sot-apps eval`` and :mod:`sot_apps.bench.benchmark_eval` over a benchmark's tracklet list).
For every selected track, the evaluated span is the first contiguous run of annotated frames (:class:`TrackSpec`);
a result is scored with the metrics of :mod:`tracker.metrics` against the ground-truth boxes (frames 1..n-1 of
the span) and a pseudo-ground-truth shape (:mod:`tracker.pseudo_gt`). Results are pooled over tracks, per
difficulty (easy/medium/hard) and per track; with several seeds every figure is the mean over seeds.

The evaluation's own parameters are data (:class:`EvalConfig`, written into the JSON report), in the
spirit of nuscenes-devkit's ``DetectionConfig``.

Timing: ``ms/frame`` statistics are over the tracker's own per-frame time (``FrameEstimate.time_ms``:
cropping, ground removal, association and optimisation; reading the sweep is not included) for
every tracked frame k >= 1 of the span, *including* frame 1 with its wide ICP search; the start frame
(which only crops the init box) is excluded. Offline rows add the refinement's wall time divided by
the number of tracked frames to each frame.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field
from functools import cached_property
from typing import Any, Iterable, Sequence

import numpy as np

from tracker import (
    DIFFICULTIES,
    DIFFICULTY_THRESHOLDS,
    PRECISION_THRESHOLDS,
    ROB_THRESHOLDS,
    SUCCESS_THRESHOLDS,
    Box,
    PooledMetrics,
    TrackerConfig,
    TrackletScores,
    TrackResult,
    chamfer_distance,
    difficulty,
    mean_points_in_boxes,
    pool_metrics,
    pseudo_gt_shape,
    score_tracklet,
    tracklet_metrics,
)

from ..errors import InputError
from ..io.cached_source import CachedSource
from ..io.jsonable import json_safe
from ..io.object_track import ObjectTrack
from ..io.sequence import Sequence as LidarSequence
from ..objects.selection import DEFAULT_SELECTION, Selection, annotated_span
from ..text_table import format_table
from ..text_table import format_value as _fmt

__all__ = [
    "EvalConfig",
    "score_result",
    "TrackSpec",
    "RunRecord",
    "ResultRow",
    "EvalReport",
    "select_moving_vehicle_tracks",
    "prepare_tracks",
    "summarise_row",
    "flag_counts",
    "format_report",
]

@dataclass(frozen=True)
class EvalConfig:
    """Everything that defines the evaluation (stored in the JSON report).

    Track selection for ``--all-moving``: ``selection`` (:mod:`sot_apps.objects.selection`, the rule every
    command uses): moving vehicles that are evaluable (LiDAR-SOT's start criteria adapted to short
    sequences: span of at least ``min_frames`` frames, at least ``min_mean_points`` mean sweep points in
    the box over the first ``difficulty_frames`` frames). On pandaset_002 this selects exactly the 9 dev tracks.
    """

    selection: Selection = DEFAULT_SELECTION
    difficulty_thresholds: tuple[float, float] = DIFFICULTY_THRESHOLDS
    shape_voxel_m: float = 0.05
    pgt_ground_margin_m: float = 3.0
    rob_thresholds: tuple[float, ...] = tuple(float(t) for t in ROB_THRESHOLDS)
    success_thresholds: tuple[float, ...] = tuple(float(t) for t in SUCCESS_THRESHOLDS)
    precision_thresholds_m: tuple[float, ...] = tuple(float(t) for t in PRECISION_THRESHOLDS)
    scored_frames: str = "1..n-1 (the start frame's box is given, never scored)"

    def to_dict(self) -> dict[str, Any]:
        return dataclasses.asdict(self)


@dataclass(frozen=True)
class TrackSpec:
    """One evaluated ground-truth track: ``truth``, the annotated rows of its span (every frame of it, an
    :class:`ObjectTrack`; ``frames`` and ``boxes`` are views of it), its difficulty and pseudo-ground-truth shape."""

    truth: ObjectTrack = field(repr=False)
    mean_points_first10: float
    difficulty: str
    pgt_shape: np.ndarray = field(repr=False)

    @property
    def track_id(self) -> str:
        return self.truth.object_id

    @property
    def label(self) -> str:
        return self.truth.label

    @cached_property
    def frames(self) -> tuple[int, ...]:
        return tuple(int(k) for k in self.truth.frames)

    @cached_property
    def boxes(self) -> tuple[Box, ...]:
        return tuple(self.truth.box(i) for i in range(len(self.truth)))

    def summary(self) -> dict[str, Any]:
        return {"track_id": self.track_id, "label": self.label, "start_frame": self.frames[0],
                "end_frame": self.frames[-1], "n_frames": len(self.frames),
                "mean_points_first10": self.mean_points_first10, "difficulty": self.difficulty,
                "pgt_points": int(len(self.pgt_shape))}


def select_moving_vehicle_tracks(sequence: LidarSequence, config: EvalConfig = EvalConfig(),
                                 source: CachedSource | None = None) -> list[str]:
    """Ids of the moving vehicle tracks that are evaluable (``config.selection``), sorted by id."""
    rule = config.selection
    source = source or CachedSource(sequence)
    tracks = sequence.tracks()
    selected = []
    for tid in rule.moving_vehicles(sequence):
        trk = tracks[tid]
        start, end = annotated_span(trk.frames)
        n = min(rule.difficulty_frames, end - start + 1)
        boxes = [trk.box_at(k) for k in range(start, start + n)]
        if rule.evaluable(end - start + 1, mean_points_in_boxes(source, range(start, start + n), boxes)):
            selected.append(tid)
    return selected


def prepare_tracks(sequence: LidarSequence, track_ids: Iterable[str], source: CachedSource,
                   config: EvalConfig = EvalConfig(), end_frame: int | None = None,
                   with_shape: bool = True) -> list[TrackSpec]:
    """TrackSpecs for ``track_ids`` (unique prefixes allowed); spans are cut at ``end_frame``. Without
    ``with_shape`` no pseudo-ground-truth shape is built (Shape is then NaN)."""
    tracks = sequence.tracks()
    ground = TrackerConfig().ground.params()
    specs = []
    for prefix in track_ids:
        tid = sequence.resolve_track_id(prefix)
        trk = tracks[tid]
        start, end = annotated_span(trk.frames)
        if end_frame is not None:
            end = min(end, end_frame)
        if end <= start:
            raise InputError(sequence.root, f"track {tid} has no frame to evaluate after its start frame {start}"
                                            + (f" up to --end-frame {end_frame}" if end_frame is not None else ""))
        truth = trk.between(start, end)   # every frame: the span is a contiguous run of annotated frames
        frames, boxes = tuple(range(start, end + 1)), tuple(truth.box(i) for i in range(len(truth)))
        n = min(config.selection.difficulty_frames, len(frames))
        mean_pts = mean_points_in_boxes(source, frames[:n], boxes[:n])
        pgt = (pseudo_gt_shape(source, frames, boxes, ground, config.shape_voxel_m, config.pgt_ground_margin_m)
               if with_shape else np.zeros((0, 3)))
        specs.append(TrackSpec(truth, mean_pts, difficulty(mean_pts, config.difficulty_thresholds), pgt))
    return specs


@dataclass(frozen=True)
class RunRecord:
    """One (row, seed, track) run: its scores and timing."""

    row: str
    seed: int
    track_id: str
    scores: TrackletScores
    frame_ms: np.ndarray          # per tracked frame k >= 1 (offline rows include the amortised refinement)
    flags: dict[str, int]


@dataclass(frozen=True)
class ResultRow:
    """One table row: a preset, online or with offline refinement, averaged over seeds."""

    name: str
    preset: str
    offline: bool
    seeds: tuple[int, ...]
    pooled: dict[str, float]
    pooled_std: dict[str, float]
    by_difficulty: dict[str, dict[str, float]]
    by_track: dict[str, dict[str, Any]]
    timing: dict[str, float]
    # per difficulty, the standard deviation over the seeds of its pooled figures (as ``pooled_std`` for the whole)
    by_difficulty_std: dict[str, dict[str, float]] = field(default_factory=dict)

    def to_dict(self) -> dict[str, Any]:
        return dataclasses.asdict(self)


@dataclass(frozen=True)
class EvalReport:
    sequence: str
    eval_config: EvalConfig
    tracks: list[TrackSpec]
    rows: list[ResultRow]
    tracker_configs: dict[str, dict[str, Any]]

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready dict (non-finite numbers become null)."""
        return json_safe({
            "sequence": self.sequence,
            "eval_config": self.eval_config.to_dict(),
            "tracks": [t.summary() for t in self.tracks],
            "tracker_configs": self.tracker_configs,
            "rows": [r.to_dict() for r in self.rows],
        })


_METRIC_KEYS = ("acc", "rob", "shape", "success", "precision", "centre_error")


def _metrics_dict(p: PooledMetrics) -> dict[str, float]:
    return {k: float(getattr(p, k)) for k in _METRIC_KEYS} | {"n_tracklets": p.n_tracklets, "n_frames": p.n_frames}


def _mean_over_seeds(dicts: list[dict[str, float]]) -> tuple[dict[str, float], dict[str, float]]:
    mean, std = {}, {}
    for key in dicts[0]:
        vals = np.array([d[key] for d in dicts], dtype=np.float64)
        finite = vals[np.isfinite(vals)]
        mean[key] = float(finite.mean()) if finite.size else float("nan")
        if key.startswith("n_") and finite.size:
            mean[key] = int(round(mean[key]))
        std[key] = float(finite.std()) if finite.size else float("nan")
    return mean, std


def summarise_row(name: str, preset: str, offline: bool, seeds: Sequence[int], records: list[RunRecord],
                   specs: list[TrackSpec]) -> ResultRow:
    by_seed = {s: [r for r in records if r.seed == s] for s in seeds}
    pooled_runs = [_metrics_dict(pool_metrics([r.scores for r in by_seed[s]])) for s in seeds]
    pooled, pooled_std = _mean_over_seeds(pooled_runs)
    diff_of = {t.track_id: t.difficulty for t in specs}
    by_difficulty: dict[str, dict[str, float]] = {}
    by_difficulty_std: dict[str, dict[str, float]] = {}
    for level in DIFFICULTIES:
        runs = []
        for s in seeds:
            chosen = [r.scores for r in by_seed[s] if diff_of[r.track_id] == level]
            if chosen:
                runs.append(_metrics_dict(pool_metrics(chosen)))
        if runs:
            by_difficulty[level], by_difficulty_std[level] = _mean_over_seeds(runs)
    by_track: dict[str, dict[str, Any]] = {}
    for spec in specs:
        runs = [dataclasses.asdict(tracklet_metrics(r.scores)) for r in records if r.track_id == spec.track_id]
        numeric = [{k: v for k, v in run.items() if k in _METRIC_KEYS} for run in runs]
        entry: dict[str, Any] = _mean_over_seeds(numeric)[0]
        flags: dict[str, int] = {}
        for r in records:
            if r.track_id == spec.track_id:
                for f, c in r.flags.items():
                    flags[f] = flags.get(f, 0) + c
        entry.update({"difficulty": spec.difficulty, "n_frames": runs[0]["n_frames"],
                      "mean_points_first10": spec.mean_points_first10, "flags": flags})
        by_track[spec.track_id] = entry
    ms = np.concatenate([r.frame_ms for r in records]) if records else np.zeros(0)
    later = np.concatenate([r.frame_ms[1:] for r in records]) if records else np.zeros(0)
    first = np.array([r.frame_ms[0] for r in records if r.frame_ms.size])
    stat = lambda a, f: float(f(a)) if a.size else float("nan")  # noqa: E731
    timing = {"median_ms": stat(ms, np.median), "mean_ms": stat(ms, np.mean),
              "p90_ms": stat(ms, lambda a: np.percentile(a, 90)), "frames": int(ms.size),
              "median_ms_excl_frame1": stat(later, np.median), "mean_ms_excl_frame1": stat(later, np.mean),
              "frame1_mean_ms": stat(first, np.mean)}
    return ResultRow(name, preset, offline, tuple(seeds), pooled, pooled_std, by_difficulty, by_track, timing,
                     by_difficulty_std)


def flag_counts(result: TrackResult) -> dict[str, int]:
    counts: dict[str, int] = {}
    for est in result.estimates[1:]:
        for f in est.flags:
            counts[f] = counts.get(f, 0) + 1
    return counts


def score_result(spec: TrackSpec, result: TrackResult, config: EvalConfig) -> TrackletScores:
    """One tracklet's scores: boxes of frames 1..n-1 against the truth, Chamfer of the shape to the pseudo-GT."""
    predicted = np.array([b.to_array() for b in result.boxes])
    truth = np.array([b.to_array() for b in spec.boxes])
    scores = score_tracklet(spec.track_id, predicted, truth, mean_points_first10=spec.mean_points_first10)
    cd = (chamfer_distance(result.shape, spec.pgt_shape, voxel=config.shape_voxel_m) if len(spec.pgt_shape)
          else float("nan"))
    return dataclasses.replace(scores, shape_cd=cd)


# ---------------------------------------------------------------------------------------------------
# Tables
# ---------------------------------------------------------------------------------------------------

def _metric_cells(m: dict[str, float]) -> list[str]:
    return [_fmt(100 * m["acc"], ".1f"), _fmt(100 * m["rob"], ".1f"), _fmt(m["shape"], ".3f"),
            _fmt(m["success"], ".1f"), _fmt(m["precision"], ".1f"), _fmt(m["centre_error"], ".3f")]


def format_report(report: EvalReport, per_track: bool = True) -> str:
    """Paper-style tables: pooled rows per preset, per difficulty, per track (Acc and Rob in %)."""
    n_seeds = len(report.rows[0].seeds) if report.rows else 0
    diffs = {d: sum(1 for t in report.tracks if t.difficulty == d) for d in DIFFICULTIES}
    out = [f"sequence: {report.sequence}",
           f"tracks: {len(report.tracks)} ({', '.join(f'{d} {n}' for d, n in diffs.items())}), "
           f"frames scored: {report.rows[0].pooled['n_frames']:.0f}, seeds: {n_seeds}" if report.rows else "",
           ""]
    header = ["preset", "Acc", "Rob", "Shape(m)", "Success", "Prec", "CE(m)", "ms/f med", "ms/f mean", "ms/f p90"]
    rows = [[r.name] + _metric_cells(r.pooled) + [_fmt(r.timing["median_ms"], ".1f"), _fmt(r.timing["mean_ms"], ".1f"),
                                                  _fmt(r.timing["p90_ms"], ".1f")] for r in report.rows]
    out += ["All tracks (pooled over frames; Shape = mean Chamfer over tracks)", format_table(header, rows), ""]
    dheader = ["preset"] + [f"{d} {m}" for d in DIFFICULTIES if d in (report.rows[0].by_difficulty if report.rows else {})
                            for m in ("Acc", "Rob", "Shape")]
    drows = []
    for r in report.rows:
        cells = [r.name]
        for d in DIFFICULTIES:
            if d in r.by_difficulty:
                m = r.by_difficulty[d]
                cells += [_fmt(100 * m["acc"], ".1f"), _fmt(100 * m["rob"], ".1f"), _fmt(m["shape"], ".3f")]
        drows.append(cells)
    out += ["By difficulty (mean GT-box points over the first 10 frames: hard < 38.2 <= medium < 808.3 <= easy)",
            format_table(dheader, drows), ""]
    if per_track:
        theader = ["track", "diff", "pts10"] + [r.name for r in report.rows]
        trows = []
        for spec in report.tracks:
            cells = [spec.track_id[:8], spec.difficulty, _fmt(spec.mean_points_first10, ".0f")]
            for r in report.rows:
                m = r.by_track[spec.track_id]
                cells.append(f"{_fmt(100 * m['acc'], '.1f')}/{_fmt(100 * m['rob'], '.1f')}/{_fmt(m['centre_error'], '.2f')}")
            trows.append(cells)
        out += ["Per track: Acc / Rob / centre error (m)", format_table(theader, trows), ""]
    out.append("Acc, Rob in %; Success, Precision: 100 x AUC; CE: mean 3D centre error; ms/f: tracker time per frame "
               "(frames >= 1, frame 1's wide search included; offline rows add the refinement amortised per frame).")
    return "\n".join(out)
