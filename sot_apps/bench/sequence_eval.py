"""Tracker presets on a sequence's annotated tracks (``sot-apps eval SEQUENCE``): run here, scored by
:mod:`sot_apps.evaluation.tracker`.

Every selected track is tracked from its first ground-truth box over its annotated span with each preset and
seed (plus fixed-lag and offline-refined rows when asked); :mod:`sot_apps.evaluation.tracker` scores the results
and pools them into the report's rows. Also the command-line policy both ``eval`` runs share: which presets a
list of names means (:func:`resolve_presets`) and which ``--set`` overrides every preset accepts
(:func:`checked_overrides`).
"""

from __future__ import annotations

import time
from typing import TYPE_CHECKING, Any, Callable, Iterable, Mapping, Sequence

import numpy as np

from ..errors import InputError

if TYPE_CHECKING:   # imported by `sot-apps bench --help` (module discovery): the libraries load when a run starts
    from tracker import Detections, TrackerConfig, TrackResult

    from ..evaluation.tracker import EvalConfig, EvalReport, TrackSpec
    from ..io.cached_source import CachedSource
    from ..io.sequence import Sequence as LidarSequence

__all__ = ["resolve_presets", "checked_overrides", "refined_modes", "track_all", "evaluate"]


def resolve_presets(names: Sequence[str] | None, with_detections: bool = False) -> list[str]:
    """Preset names, with ``all`` expanded (the detection presets only ``with_detections``); unknown names,
    and a detection preset without detections, raise InputError."""
    from tracker import DETECTION_PRESETS, preset_names

    names = list(names or ["full"])
    out: list[str] = []
    for name in names:
        expanded = ([p for p in preset_names() if with_detections or p not in DETECTION_PRESETS] if name == "all"
                    else [name])
        for n in expanded:
            if n not in preset_names():
                raise InputError(None, f"unknown preset {n!r}; known: {', '.join(preset_names())}, all")
            if n in DETECTION_PRESETS and not with_detections:
                raise InputError(None, f"preset {n!r} needs detections (--detections FILE or --simulate-detections)")
            if n not in out:
                out.append(n)
    return out


def checked_overrides(items: Sequence[str], presets: Sequence[str]) -> dict[str, Any]:
    """``PATH=VALUE`` strings as {dotted TrackerConfig path: typed value} (:func:`tracker.parse_overrides`); an
    unknown path, a bad value, or a result a preset rejects is an InputError."""
    from tracker import get_preset, parse_overrides

    try:
        out = parse_overrides(items)
    except ValueError as exc:
        raise InputError(None, f"--set {exc} (settings: docs/tracker.md)") from None
    for preset in presets:
        try:
            get_preset(preset, **out)
        except ValueError as exc:
            raise InputError(None, f"--set: preset {preset}: {exc}") from None
    return out


def refined_modes(source, result: TrackResult, config: TrackerConfig, lags: Sequence[int] = (),
                  offline: bool = False, refine: Callable[..., TrackResult] | None = None
                  ) -> list[tuple[str, TrackResult, np.ndarray]]:
    """The fixed-lag and offline results of one online ``result``: (row suffix ``+lagN`` / ``+offline``, result,
    ms per frame k >= 1). Fixed lag: the online step plus the window solve; offline: the online step plus the
    refinement's time spread over the frames. ``refine`` overrides :func:`tracker.offline.refine_offline`."""
    from tracker import refine_fixed_lag

    online_ms = np.array([e.time_ms for e in result.estimates[1:]], dtype=np.float64)
    out = []
    for n in lags:
        smoothed = refine_fixed_lag(source, result, int(n), config)
        out.append((f"+lag{n}", smoothed, np.array([e.time_ms for e in smoothed.estimates[1:]], dtype=np.float64)))
    if offline:
        if refine is None:
            from tracker import refine_offline as refine
        t0 = time.perf_counter()
        better = refine(source, result, config)
        extra = (time.perf_counter() - t0) * 1e3 / max(len(online_ms), 1)
        out.append(("+offline", better, online_ms + extra))
    return out


def track_all(source: CachedSource, specs: Sequence[TrackSpec], config: TrackerConfig,
              detections: Detections | None) -> list[TrackResult]:
    """Every spec's online track from its first annotated box, all in one pass over the sweeps
    (:func:`sot_apps.tracking.track_objects`: the results of :func:`tracker.track` per object, bit for bit,
    each sweep read and grounded once). A track whose tracking raised raises here."""
    from ..tracking import ObjectRequest, track_objects

    requests = [ObjectRequest(spec.track_id, spec.boxes[0], int(spec.frames[0]), int(spec.frames[-1]))
                for spec in specs]
    outcomes, _ = track_objects(source, requests, config, mode="online", detections=detections, min_points=None)
    for outcome in outcomes:
        if outcome.result is None:
            raise RuntimeError(f"track {outcome.object_id}: {outcome.error}")
    return [outcome.result for outcome in outcomes]


def evaluate(sequence: LidarSequence, track_ids: Sequence[str] | None = None, presets: Sequence[str] = ("full",),
             offline: bool = False, seeds: Sequence[int] = (0,), config: EvalConfig | None = None,
             end_frame: int | None = None, progress: Callable[[Iterable], Iterable] | None = None,
             refine: Callable[..., TrackResult] | None = None, with_shape: bool = True,
             detections: Detections | Callable[[int], Detections] | None = None,
             lags: Sequence[int] = (), overrides: Mapping[str, Any] | None = None) -> EvalReport:
    """Evaluate ``presets`` (online, plus fixed-lag rows ``preset+lagN`` for each N in ``lags`` (ms/frame: the
    online step plus the window solve) and offline-refined rows when ``offline``) on ``track_ids``
    (default: all moving vehicle tracks). ``refine(source, result, config) -> TrackResult`` overrides the
    offline refinement (default: :func:`tracker.offline.refine_offline`). ``detections``: per-frame
    detections for the Det / Det+SOT presets, or a function seed -> detections (e.g. simulated per seed).
    ``overrides``: TrackerConfig fields replaced in every preset (``sot-apps eval --set``). ``config``: the
    evaluation's parameters (default ``EvalConfig()``)."""
    from tracker import get_preset

    from ..evaluation.tracker import (
        EvalConfig,
        EvalReport,
        RunRecord,
        flag_counts,
        prepare_tracks,
        score_result,
        select_moving_vehicle_tracks,
        summarise_row,
    )
    from ..io.cached_source import CachedSource

    config = config if config is not None else EvalConfig()
    overrides = dict(overrides or {})
    per_seed: dict[int, Detections | None] = {}

    def detections_for(seed: int) -> Detections | None:
        if seed not in per_seed:
            per_seed[seed] = detections(seed) if callable(detections) else detections
        return per_seed[seed]

    source = CachedSource(sequence)
    ids = list(track_ids) if track_ids else select_moving_vehicle_tracks(sequence, config, source)
    if not ids:
        raise InputError(sequence.root, "no track to evaluate (no moving vehicle track matches the selection)")
    specs = prepare_tracks(sequence, ids, source, config, end_frame, with_shape)
    jobs = [(p, s) for p in presets for s in seeds]
    online: dict[str, list[RunRecord]] = {p: [] for p in presets}
    moded: dict[str, list[RunRecord]] = {}  # row name (PRESET+lagN, PRESET+offline) -> records
    tracker_configs: dict[str, dict[str, Any]] = {}
    for preset, seed in (progress(jobs) if progress else jobs):
        tconfig = get_preset(preset, seed=int(seed), **overrides)
        tracker_configs[preset] = get_preset(preset, **overrides).to_dict()
        for spec, result in zip(specs, track_all(source, specs, tconfig, detections_for(int(seed))), strict=True):
            ms = np.array([e.time_ms for e in result.estimates[1:]], dtype=np.float64)
            online[preset].append(RunRecord(preset, int(seed), spec.track_id, score_result(spec, result, config),
                                            ms, flag_counts(result)))
            for suffix, refined, refined_ms in refined_modes(source, result, tconfig, lags, offline, refine):
                moded.setdefault(preset + suffix, []).append(RunRecord(
                    preset + suffix, int(seed), spec.track_id, score_result(spec, refined, config), refined_ms,
                    flag_counts(refined)))
    rows = []
    for preset in presets:
        rows.append(summarise_row(preset, preset, False, seeds, online[preset], specs))
        for n in lags:
            rows.append(summarise_row(f"{preset}+lag{n}", preset, False, seeds, moded[f"{preset}+lag{n}"], specs))
        if offline:
            rows.append(summarise_row(f"{preset}+offline", preset, True, seeds, moded[f"{preset}+offline"], specs))
    return EvalReport(str(sequence.root), config, specs, rows, tracker_configs)
