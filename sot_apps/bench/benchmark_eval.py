"""Tracker presets on a benchmark's tracklet list (``sot-apps eval --benchmark LIST``), run here and scored by
:mod:`sot_apps.evaluation.tracker`: paper-style tables per difficulty and per motion profile.

Each tracklet is tracked from its first frame's ground-truth box to its last frame (LiDAR-SOT's protocol) with
every preset and seed; scores are those of ``sot-apps eval`` (:mod:`tracker.metrics`: Acc, Rob, Success,
Precision over frames 1..n-1; Shape = Chamfer to the pseudo-ground-truth shape). A group's figures pool its
tracklets' frames; with several seeds each figure is the mean over seeds (± the spread of Acc).
Groups of the hard profiles add their own figures (:mod:`sot_apps.benchmark.profile_scores`): the share
re-locked within 3 frames of re-appearing (``hidden``), the share found at the first frame within 30 m
(``far_approach``) and the median heading error at the last frame (``oblique``).
"""

from __future__ import annotations

import dataclasses
from collections import defaultdict
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any, Callable, Iterable, Mapping

import numpy as np

from ..benchmark.profile_scores import pool_figures, tracklet_figures
from ..errors import InputError
from ..text_table import format_table
from ..text_table import format_value as _fmt

if TYPE_CHECKING:   # imported by `sot-apps bench --help` (module discovery): the libraries load when a run starts
    from ..benchmark.lists import SequenceResolver, Tracklet
    from ..evaluation.tracker import EvalConfig, TrackSpec
    from ..io.cached_source import CachedSource

__all__ = ["BenchmarkList", "open_benchmark", "BenchmarkRun", "evaluate_tracklets", "format_benchmark"]


@dataclass(frozen=True)
class BenchmarkList:
    """A benchmark's tracklets, where they were read from, and how a tracklet finds its sequence."""

    source: Path
    tracklets: list[Tracklet]
    resolve: SequenceResolver


def open_benchmark(benchmark: str, lists: str | Path | None = None, data_dir: str | Path | None = None,
                   first: int | None = None) -> BenchmarkList:
    """The tracklet list ``benchmark`` names: a list file (benchmark.json of ``benchmark make``, bench_list.json
    of ``benchmark build``) or folder, or ``"lidar-sot"`` with ``lists`` (LiDAR-SOT's list folder) and
    ``data_dir`` (the Waymo data directory). Sequences are found next to the list, else under ``data_dir``.
    ``first``: only the list's first N tracklets (a generated list is ordered copy by copy)."""
    from ..benchmark.lists import default_resolver, read_lists

    if benchmark == "lidar-sot":
        if not lists or data_dir is None:
            raise InputError(None, "--benchmark lidar-sot needs --lists DIR and the Waymo DATA_DIR as SEQUENCE")
        source = Path(lists)
    else:
        source = Path(benchmark)
    tracklets = read_lists(source)
    if first is not None:
        if first < 1:
            raise InputError(None, f"--first must be >= 1, not {first}")
        tracklets = tracklets[:first]
    list_dir = source if source.is_dir() else source.parent
    return BenchmarkList(source, tracklets, default_resolver(list_dir, Path(data_dir) if data_dir else None))


@dataclass(frozen=True)
class BenchmarkRun:
    """Per (preset, seed, tracklet key): scores and per-frame times; plus each tracklet's groups."""

    presets: tuple[str, ...]
    seeds: tuple[int, ...]
    records: dict[tuple[str, int, str], tuple[Any, np.ndarray]]
    difficulty: dict[str, str]
    profile: dict[str, str | None]
    figures: dict[tuple[str, int, str], dict[str, float]] = dataclasses.field(default_factory=dict)

    def groups(self) -> list[tuple[str, list[str]]]:
        from tracker import DIFFICULTIES

        keys = list(self.difficulty)
        out = [("all", keys)]
        out += [(d, [k for k in keys if self.difficulty[k] == d]) for d in DIFFICULTIES]
        profiles = sorted({p for p in self.profile.values() if p})
        out += [(f"profile {p}", [k for k in keys if self.profile[k] == p]) for p in profiles]
        return [(name, ks) for name, ks in out if ks]

    def summary(self, preset: str, keys: list[str]) -> dict[str, float]:
        from tracker import pool_metrics

        per_seed = []
        for seed in self.seeds:
            scores = [self.records[(preset, seed, k)][0] for k in keys]
            pooled = pool_metrics(scores)
            ms = np.concatenate([self.records[(preset, seed, k)][1] for k in keys])
            per_seed.append({"acc": pooled.acc, "rob": pooled.rob, "shape": pooled.shape, "success": pooled.success,
                             "precision": pooled.precision, "ms": float(np.mean(ms)) if ms.size else float("nan")})
        for seed, row in zip(self.seeds, per_seed, strict=True):
            row.update(pool_figures(self.figures.get((preset, seed, k), {}) for k in keys))
        mean = {k: _nan_mean([s.get(k, float("nan")) for s in per_seed]) for k in per_seed[0]}
        mean["acc_std"] = float(np.std([s["acc"] for s in per_seed]))
        mean["n"] = len(keys)
        return mean

    def to_dict(self) -> dict:
        """JSON-ready dict (non-finite numbers, e.g. the Det row's Shape, become null)."""
        from ..io.jsonable import json_safe

        return json_safe({
            "presets": list(self.presets), "seeds": list(self.seeds),
            "tables": {p: {name: self.summary(p, keys) for name, keys in self.groups()} for p in self.presets},
            "tracklets": {k: {"difficulty": self.difficulty[k], "profile": self.profile[k]} for k in self.difficulty}})


def _nan_mean(values: list[float]) -> float:
    """Mean of the finite values; NaN when there is none (the Det row has no shape), without a warning."""
    finite = [v for v in values if np.isfinite(v)]
    return float(np.mean(finite)) if finite else float("nan")


def _spec(seq, source: CachedSource, t: Tracklet, config: EvalConfig) -> TrackSpec:
    from tracker import DIFFICULTY_THRESHOLDS, difficulty, mean_points_in_boxes, pseudo_gt_shape

    from ..benchmark.deps import eval_ground_params
    from ..evaluation.tracker import TrackSpec

    tracks = seq.tracks()
    if t.id not in tracks:
        raise InputError(seq.root, f"tracklet {t.id}: no annotated object with this id")
    a, b = t.frame_range
    if b >= len(seq):
        raise InputError(seq.root, f"tracklet {t.id}: frame_range {a}..{b} beyond the sequence's {len(seq)} frames")
    truth = tracks[t.id].between(a, b)
    frames = tuple(range(a, b + 1))
    if len(truth) != len(frames):
        missing = sorted(set(frames) - set(truth.frames.tolist()))
        raise InputError(seq.root, f"tracklet {t.id}: no box at frame {missing[0]} of {a}..{b}")
    boxes = tuple(truth.box(i) for i in range(len(truth)))
    n = min(config.selection.difficulty_frames, len(frames))
    mean10 = mean_points_in_boxes(source, frames[:n], boxes[:n])
    level = t.difficulty or difficulty(mean10, DIFFICULTY_THRESHOLDS)
    pgt = pseudo_gt_shape(source, frames, boxes, eval_ground_params(), config.shape_voxel_m, config.pgt_ground_margin_m)
    return TrackSpec(truth, mean10, level, pgt)


def evaluate_tracklets(tracklets: list[Tracklet], resolve: SequenceResolver, presets: Iterable[str],
                       seeds: Iterable[int] = (0,), config: EvalConfig | None = None,
                       progress: Callable[[int], Callable[[], None]] | None = None,
                       detections: Callable[[Any, int], Any] | None = None,
                       overrides: Mapping[str, Any] | None = None, lags: Iterable[int] = (),
                       offline: bool = False) -> BenchmarkRun:
    """Track every tracklet with every preset and seed (sequence by sequence: one sweep cache at a time).

    ``progress(total)`` returns a callable ticked once per (tracklet, preset, seed) run. ``detections(sequence,
    seed)``: the per-frame detections of a sequence for the Det / Det+SOT presets (e.g. simulated from its
    ground truth with that seed). ``overrides``: TrackerConfig fields replaced in every preset. ``lags``: a
    row ``PRESET+lagN`` per N, the fixed-lag states of each online run (ms/frame: the online step plus the
    window solve); ``offline``: a row ``PRESET+offline``, each online run refined offline (ms/frame: the
    online step plus the refinement per frame), as ``sot-apps eval SEQUENCE`` does. ``config``: the evaluation's
    parameters (default ``EvalConfig()``)."""
    from tracker import get_preset, track

    from ..evaluation.tracker import EvalConfig, score_result
    from ..io import open_sequence
    from ..io.cached_source import CachedSource
    from .sequence_eval import refined_modes

    config = config if config is not None else EvalConfig()
    overrides = dict(overrides or {})
    presets, seeds, lags = tuple(presets), tuple(int(s) for s in seeds), tuple(int(n) for n in lags)
    rows = tuple(r for p in presets for r in (p, *(f"{p}+lag{n}" for n in lags), *((f"{p}+offline",) if offline else ())))
    if not tracklets:
        raise InputError(None, "the list has no tracklet")
    by_sequence: dict[str, list[Tracklet]] = defaultdict(list)
    for t in tracklets:
        by_sequence[str(resolve(t))].append(t)
    tick = progress(len(tracklets) * len(presets) * len(seeds)) if progress else (lambda: None)
    records: dict[tuple[str, int, str], tuple[Any, np.ndarray]] = {}
    figures: dict[tuple[str, int, str], dict[str, float]] = {}
    levels: dict[str, str] = {}
    profiles: dict[str, str | None] = {}
    for path, group in by_sequence.items():
        seq = open_sequence(path)
        source = CachedSource(seq)
        per_seed = {seed: detections(seq, seed) for seed in seeds} if detections else {}
        for t in group:
            spec = _spec(seq, source, t, config)
            levels[t.key], profiles[t.key] = spec.difficulty, t.profile
            for preset in presets:
                for seed in seeds:
                    result = track(source, spec.boxes[0], spec.frames[0], spec.frames[-1],
                                   get_preset(preset, seed=seed, **overrides), detections=per_seed.get(seed))
                    ms = np.array([e.time_ms for e in result.estimates[1:]], dtype=np.float64)
                    modes = [("", result, ms)] + refined_modes(source, result, result.config, lags, offline)
                    for suffix, mode_result, mode_ms in modes:
                        scores = dataclasses.replace(score_result(spec, mode_result, config), track_id=t.key)
                        records[(preset + suffix, seed, t.key)] = (scores, mode_ms)
                        figures[(preset + suffix, seed, t.key)] = tracklet_figures(
                            {**t.extra, "profile": t.profile}, scores.ious,
                            [b.heading for b in mode_result.boxes], [b.heading for b in spec.boxes])
                    tick()
    return BenchmarkRun(rows, seeds, records, levels, profiles, figures)


_EXTRA_COLUMNS = (("relock_share", "ReLock3", 100.0, ".0f"), ("relock_any_share", "ReLock3any", 100.0, ".0f"),
                  ("found_near_share", "Found30", 100.0, ".0f"),
                  ("heading_err_last_med_deg", "Hdg@last", 1.0, ".1f"))


def format_benchmark(run: BenchmarkRun, title: str = "") -> str:
    """One table per preset: rows = all / easy / medium / hard / each motion profile."""
    out = [title] if title else []
    n_seeds = len(run.seeds)
    for preset in run.presets:
        out.append(f"preset {preset} ({n_seeds} seed{'s' if n_seeds > 1 else ''}"
                   + (": mean, Acc ± std over seeds)" if n_seeds > 1 else ")"))
        header = ["group", "n", "Acc", "Rob", "Shape(m)", "Success", "Prec", "ms/frame"]
        rows = []
        summaries = [(name, run.summary(preset, keys)) for name, keys in run.groups()]
        extra = [(k, title, scale, spec) for k, title, scale, spec in _EXTRA_COLUMNS
                 if any(k in m for _, m in summaries)]
        header += [title for _, title, _, _ in extra]
        for name, m in summaries:
            acc = _fmt(100 * m["acc"], ".1f") + (f" ± {100 * m['acc_std']:.1f}" if n_seeds > 1 else "")
            rows.append([name, str(m["n"]), acc, _fmt(100 * m["rob"], ".1f"), _fmt(m["shape"], ".3f"),
                         _fmt(m["success"], ".1f"), _fmt(m["precision"], ".1f"), _fmt(m["ms"], ".1f")]
                        + [_fmt(scale * m[k], spec) if k in m else "" for k, _, scale, spec in extra])
        out += [format_table(header, rows), ""]
    out.append("Acc, Rob in %; Success, Precision: 100 x AUC; Shape: mean Chamfer to the pseudo-ground-truth shape; "
               "difficulty by mean GT-box points over the first 10 frames (hard < 38.2 <= medium < 808.3 <= easy).")
    if any(k in run.summary(p, keys) for p in run.presets for _, keys in run.groups() for k, *_ in _EXTRA_COLUMNS):
        out.append("ReLock3: % of hidden tracklets with IoU >= 0.3 from some frame within 3 frames of re-appearing to "
                   "the third frame after it (ReLock3any: at any one frame of those 4); Found30: % of "
                   "far approaches with IoU >= 0.3 at the first frame within 30 m; Hdg@last: median |heading error| "
                   "at the last frame (deg, oblique).")
    return "\n".join(out)
