"""``sot-apps bench keyframes SOURCE ...``: keyframe-assisted tracks against interpolation and single-box tracking.

Every track of every SOURCE (a benchmark list: ``benchmark.json`` of ``sot-apps benchmark make`` or its folder;
or an annotated sequence: its moving vehicle tracks, the rule of ``sot-apps eval --all-moving``) gets keyframes
from its own ground truth every N frames (``--every``): frames start, start + N, ... and always its last frame
(an annotator closes a track with a keyframe; with N >= the track's length only the first and the last frame are
keyframes, e.g. 0 and 39 on the benchmark's 40-frame tracklets at N = 40). Rows:

- ``linear``, ``ctrv``: interpolation between the keyframes (:func:`tracker.keyframes.interpolate_linear`,
  :func:`~tracker.keyframes.interpolate_ctrv`);
- ``keyframes no-solve``: the CTRV interpolation as the default candidate, a tracked state (the passes forward
  and backward between keyframes, closure-corrected and blended) replacing it only where it explains clearly
  more points;
- ``keyframes``: then the solve (:func:`tracker.keyframes.track_keyframes`, what ``sot-apps track
  --keyframes`` runs);
- ``single box``, ``single box + offline``: the tracker from the first box only (no keyframe), online and
  refined offline; the same in every column.

With ``--ablations`` also: ``keyframes fwd`` (the online tracker restarted at every keyframe, forward passes
only), ``keyframes fwd+bwd`` (+ the backward passes, blended, chosen per frame by the points they explain, no
CTRV candidate) and ``keyframes no-ctrv`` (fwd+bwd, then the solve).

Acc = mean 3D IoU pooled over the frames 1..n-1 of all tracks (the eval protocol; keyframes count, with IoU 1 for
every keyframe row); in brackets the Acc over the frames that are not keyframes. With ``--seeds N`` (tracker seeds
``--seed`` .. ``--seed`` + N - 1) every figure is the mean over seeds and Acc ± its standard deviation over seeds.
One table per SOURCE, one for all SOURCEs pooled, and, for benchmark lists with motion profiles, the Acc of
linear / CTRV / keyframes per profile.
"""

from __future__ import annotations

import argparse
import sys
from collections import defaultdict
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:   # numpy loads when a benchmark runs (`sot-apps --help` imports this module)
    import numpy as np

__all__ = ["register", "add_arguments", "run", "KeyframeBenchTrack", "KEYFRAME_ROWS", "ABLATION_ROWS"]

KEYFRAME_ROWS = ("linear", "ctrv", "keyframes fwd", "keyframes fwd+bwd", "keyframes no-ctrv", "keyframes no-solve",
                 "keyframes")
ABLATION_ROWS = ("keyframes fwd", "keyframes fwd+bwd", "keyframes no-ctrv")
SINGLE_ROWS = ("single box", "single box + offline")


@dataclass(frozen=True)
class KeyframeBenchTrack:
    """One evaluated track: where it comes from and ``truth``, its annotated rows over its span (every frame; an
    :class:`~sot_apps.io.object_track.ObjectTrack`)."""

    source: str
    key: str
    profile: str | None
    sequence: Any
    truth: Any


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("sources", nargs="+", metavar="SOURCE",
                        help="benchmark list (benchmark.json or its folder) or annotated sequence directory")
    parser.set_defaults(bench_inputs=("sources",))   # --json never overwrites one
    parser.add_argument("--every", type=int, nargs="+", default=[5, 10, 20, 40], metavar="N",
                        help="keyframe intervals (default: 5 10 20 40)")
    parser.add_argument("--preset", default="full", help="tracker preset (default: full)")
    parser.add_argument("--seed", type=int, default=0, help="tracker seed (default 0)")
    parser.add_argument("--seeds", type=int, default=1, metavar="N",
                        help="tracker seeds SEED..SEED+N-1: means and Acc ± std over seeds (default 1)")
    parser.add_argument("--ablations", action="store_true",
                        help="also the rows keyframes fwd, keyframes fwd+bwd, keyframes no-ctrv")
    parser.add_argument("--first", type=int, metavar="N", help="only each list's first N tracklets")
    parser.add_argument("--tracks", metavar="ID,...", help="sequences: these track ids instead of the moving vehicles")
    parser.add_argument("--json", metavar="FILE", help="also write the per-track IoUs and the tables as JSON")
    parser.add_argument("--quiet", action="store_true", help="no progress bar")


def _is_list(path: Path) -> bool:
    return (path.is_file() and path.suffix == ".json") or (path.is_dir() and (path / "benchmark.json").is_file())


def _tracks(source: str, first: int | None, track_ids: list[str] | None) -> list[KeyframeBenchTrack]:
    from ..benchmark.lists import default_resolver, read_lists
    from ..errors import InputError
    from ..evaluation.tracker import prepare_tracks, select_moving_vehicle_tracks
    from ..io import open_sequence
    from ..io.cached_source import CachedSource

    path = Path(source)
    if not path.exists():
        raise InputError(path, "no such benchmark list or sequence")
    out = []
    if _is_list(path):
        list_file = path / "benchmark.json" if path.is_dir() else path
        tracklets = read_lists(list_file)[:first]
        resolve = default_resolver(list_file.parent, None)
        opened: dict[str, Any] = {}
        for t in tracklets:
            where = str(resolve(t))
            if where not in opened:
                opened[where] = open_sequence(where)
            seq = opened[where]
            tracks = seq.tracks()
            if t.id not in tracks:
                raise InputError(seq.root, f"tracklet {t.id}: no annotated object with this id")
            first, last = t.frame_range
            truth = tracks[t.id].between(first, last)
            if len(truth) != last - first + 1:
                raise InputError(seq.root, f"tracklet {t.id}: a frame of {first}..{last} has no box")
            out.append(KeyframeBenchTrack(source, t.key, t.profile, seq, truth))
        return out
    seq = open_sequence(path)
    ids = track_ids or select_moving_vehicle_tracks(seq, source=CachedSource(seq))
    for spec in prepare_tracks(seq, ids, CachedSource(seq), with_shape=False):
        out.append(KeyframeBenchTrack(source, spec.track_id, None, seq, spec.truth))
    return out


def _ious(result_boxes: dict[int, Any], track: KeyframeBenchTrack) -> np.ndarray:

    from tracker import score_tracklet

    truth = track.truth.boxes_by_frame()
    predicted = [result_boxes[k] for k in truth]
    return score_tracklet(track.key, predicted, list(truth.values())).ious


def evaluate_track(track: KeyframeBenchTrack, source, every: list[int], config, ablations: bool = False
                   ) -> dict[str, Any]:
    """IoUs (frames 1..n-1) of every row and interval, and which scored frames are keyframes (``ablations``: also
    the rows of ``ABLATION_ROWS``)."""
    import numpy as np

    from tracker import (
        KeyframeParams,
        interpolate_ctrv,
        interpolate_linear,
        keyframe_passes,
        keyframe_schedule,
        refine_offline,
        track_keyframes,
    )
    from tracker import track as track_online

    boxes = track.truth.boxes_by_frame()
    frames = list(boxes)
    online = track_online(source, boxes[frames[0]], frames[0], frames[-1], config)
    refined = refine_offline(source, online, config)
    record: dict[str, Any] = {"single": {"single box": _ious({e.frame: e.box for e in online.estimates}, track),
                                         "single box + offline": _ious({e.frame: e.box for e in refined.estimates},
                                                                       track)},
                              "every": {}}
    variants = (("keyframes fwd", KeyframeParams(backward=False, refine=False, interpolation=False)),
                ("keyframes fwd+bwd", KeyframeParams(refine=False, interpolation=False)),
                ("keyframes no-ctrv", KeyframeParams(interpolation=False)),
                ("keyframes no-solve", KeyframeParams(refine=False)), ("keyframes", KeyframeParams()))
    for n in every:
        keys = keyframe_schedule(frames[0], frames[-1], n)
        keyframes = {k: boxes[k] for k in keys}
        passes = keyframe_passes(source, keyframes, frames[0], frames[-1], config)
        rows = {"linear": interpolate_linear(frames, keyframes), "ctrv": interpolate_ctrv(frames, keyframes)}
        for name, params in variants:
            if ablations or name not in ABLATION_ROWS:
                result = track_keyframes(source, keyframes, frames[0], frames[-1], config, params, passes)
                rows[name] = {e.frame: e.box for e in result.estimates}
        record["every"][n] = {"keys": keys, "ious": {name: _ious(b, track) for name, b in rows.items()},
                              "is_key": np.isin(frames[1:], keys)}
    return record


Records = list[tuple[KeyframeBenchTrack, int, dict[str, Any]]]   # (track, tracker seed, evaluate_track's record)


def _acc(parts: list[np.ndarray], masks: list[np.ndarray] | None = None) -> float:
    import numpy as np

    if masks is not None:
        parts = [p[m] for p, m in zip(parts, masks, strict=True)]
    values = np.concatenate(parts) if parts else np.zeros(0)
    return float(100.0 * values.mean()) if values.size else float("nan")


def _rows(records: Records) -> tuple[str, ...]:
    present = set(records[0][2]["every"][next(iter(records[0][2]["every"]))]["ious"]) if records else set()
    return tuple(r for r in KEYFRAME_ROWS if r in present) + SINGLE_ROWS


def summarise(records: Records, every: list[int]) -> dict[str, dict]:
    """{row: {N: (Acc, Acc's std over seeds, Acc between keyframes)}} pooled over ``records`` per seed, then the
    mean over seeds (std 0 with one seed)."""
    import numpy as np

    seeds = sorted({seed for _, seed, _ in records})
    out: dict[str, dict] = {}
    for name in _rows(records):
        out[name] = {}
        for n in every:
            per_seed = []
            for seed in seeds:
                mine = [r for _, s, r in records if s == seed]
                if name in SINGLE_ROWS:
                    parts = [r["single"][name] for r in mine]
                else:
                    parts = [r["every"][n]["ious"][name] for r in mine]
                per_seed.append((_acc(parts), _acc(parts, [~r["every"][n]["is_key"] for r in mine])))
            values = np.array(per_seed)
            out[name][n] = (float(values[:, 0].mean()), float(values[:, 0].std()), float(values[:, 1].mean()))
    return out


def format_summary(title: str, summary: dict[str, dict], every: list[int], n_tracks: int, n_frames: int,
                 n_seeds: int = 1) -> str:
    from ..text_table import format_table

    header = ["row"] + [f"every {n}" for n in every]
    spread = (lambda c: f" ± {c[1]:.1f}") if n_seeds > 1 else (lambda c: "")  # noqa: E731
    rows = [[name] + [f"{summary[name][n][0]:.1f}{spread(summary[name][n])} ({summary[name][n][2]:.1f})"
                      for n in every] for name in summary]
    seeds = f", mean over {n_seeds} seeds, Acc ± std over seeds" if n_seeds > 1 else ""
    return "\n".join([f"{title}: {n_tracks} tracks, {n_frames} scored frames; Acc (Acc between keyframes){seeds}",
                      format_table(header, rows)])


def format_profiles(records: Records, every: list[int]) -> str:
    by_profile: dict[str, Records] = defaultdict(list)
    for track, seed, record in records:
        if track.profile:
            by_profile[track.profile].append((track, seed, record))
    if not by_profile:
        return ""
    from ..text_table import format_table

    header = ["profile", "n"] + [f"every {n}: lin/ctrv/kf" for n in every]
    rows = []
    for profile in sorted(by_profile):
        summary = summarise(by_profile[profile], every)
        n_tracks = len({id(t) for t, _, _ in by_profile[profile]})
        rows.append([profile, str(n_tracks)]
                    + ["/".join(f"{summary[r][n][0]:.1f}" for r in ("linear", "ctrv", "keyframes")) for n in every])
    return "\n".join(["Acc by motion profile (all SOURCEs, mean over seeds)", format_table(header, rows)])


def run(args: argparse.Namespace) -> int:
    from tqdm import tqdm

    from tracker import get_preset

    from ..errors import InputError
    from ..io.atomic import write_json
    from ..io.cached_source import CachedSource
    from ..io.jsonable import json_safe

    every = sorted(set(args.every))
    if min(every) < 1:
        raise InputError(None, f"--every: intervals must be at least 1, not {min(every)}")
    if args.seeds < 1:
        raise InputError(None, f"--seeds: at least 1, not {args.seeds}")
    seeds = list(range(args.seed, args.seed + args.seeds))
    ids = [t.strip() for t in args.tracks.split(",") if t.strip()] if args.tracks else None
    tracks = [t for source in args.sources for t in _tracks(source, args.first, ids)]
    records: Records = []
    sources: dict[int, CachedSource] = {}
    jobs = [(track, seed) for track in tracks for seed in seeds]   # a track's seeds together: one sweep cache
    for track, seed in (jobs if args.quiet else tqdm(jobs, desc="keyframes", unit="run", file=sys.stderr)):
        source = sources.setdefault(id(track.sequence), CachedSource(track.sequence))
        config = get_preset(args.preset, seed=seed)
        records.append((track, seed, evaluate_track(track, source, every, config, args.ablations)))
        if len(sources) > 1:   # one sweep cache at a time: the tracks of a sequence come together
            sources = {id(track.sequence): source}
    seed_text = f"seed {args.seed}" if len(seeds) == 1 else f"seeds {seeds[0]}..{seeds[-1]}"
    out = [f"sot-apps bench keyframes, preset {args.preset}, {seed_text}; keyframes every N frames and at each "
           "track's last frame"]
    tables: dict[str, Any] = {}
    groups = [(s, [(t, seed, r) for t, seed, r in records if t.source == s]) for s in args.sources]
    if len(groups) > 1:
        groups.append(("all sources pooled", records))
    for name, group in groups:
        summary = summarise(group, every)
        tables[name] = {row: {str(n): list(v) for n, v in cells.items()} for row, cells in summary.items()}
        n_tracks = len({id(t) for t, _, _ in group})
        n_frames = sum(len(t.truth) - 1 for t in {id(t): t for t, _, _ in group}.values())
        out += ["", format_summary(name, summary, every, n_tracks, n_frames, len(seeds))]
    profiles = format_profiles(records, every)
    if profiles:
        out += ["", profiles]
    print("\n".join(out))
    if args.json:
        write_json(args.json, json_safe({
            "preset": args.preset, "seeds": seeds, "every": every, "tables": tables,
            "table_columns": ["acc", "acc_std_over_seeds", "acc_between_keyframes"],
            "tracks": [{"source": t.source, "key": t.key, "profile": t.profile, "seed": seed,
                        "frames": [int(t.truth.frames[0]), int(t.truth.frames[-1])],
                        "single": {k: v.tolist() for k, v in r["single"].items()},
                        "every": {str(n): {"keys": e["keys"], "ious": {k: v.tolist() for k, v in e["ious"].items()}}
                                  for n, e in r["every"].items()}} for t, seed, r in records]}))
    return 0


def register(registry) -> None:
    """Hook for the ``sot-apps bench`` registry."""
    registry.add("keyframes", help="keyframe-assisted tracks vs linear / CTRV interpolation and single-box tracking",
                 add_arguments=add_arguments, run=run, description=__doc__)
