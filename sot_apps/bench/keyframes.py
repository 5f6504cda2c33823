"""``sot-apps bench keyframes SOURCE ...``: keyframe-assisted tracks against interpolation and single-box tracking.

Every track of every SOURCE (a benchmark list: ``benchmark.json`` of ``sot-apps benchmark make`` or its folder;
or an annotated sequence: its moving vehicle tracks, the rule of ``sot-apps eval --all-moving``) gets keyframes
from its own ground truth every N frames (``--every``): frames start, start + N, ... and always its last frame
(an annotator closes a track with a keyframe; with N >= the track's length only the first and the last frame are
keyframes, e.g. 0 and 39 on the benchmark's 40-frame tracklets at N = 40). Rows:

- ``linear``, ``ctrv``: interpolation between the keyframes (:func:`tracker.keyframes.interpolate_linear`,
  :func:`~tracker.keyframes.interpolate_ctrv`);
- ``keyframes fwd``: the online tracker restarted at every keyframe (forward passes only);
- ``keyframes fwd+bwd``: + the backward pass from each next keyframe, blended (closure-corrected, a per-frame
  choice among the passes by the points they explain);
- ``keyframes no-ctrv``: + the offline solve with the keyframes held;
- ``keyframes no-solve``: fwd+bwd with the CTRV interpolation as the default candidate (a tracked state replaces
  it only where it explains clearly more points);
- ``keyframes``: both, then the solve (:func:`tracker.keyframes.track_keyframes`, what ``sot-apps track
  --keyframes`` runs);
- ``single box``, ``single box + offline``: the tracker from the first box only (no keyframe), online and
  refined offline; the same in every column.

Acc = mean 3D IoU pooled over the frames 1..n-1 of all tracks (the eval protocol; keyframes count, with IoU 1 for
every keyframe row); in brackets the Acc over the frames that are not keyframes. One table per SOURCE, one for all
SOURCEs pooled, and, for benchmark lists with motion profiles, the Acc of linear / CTRV / keyframes per profile.
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

__all__ = ["register", "add_arguments", "run", "KeyframeBenchTrack", "KEYFRAME_ROWS"]

KEYFRAME_ROWS = ("linear", "ctrv", "keyframes fwd", "keyframes fwd+bwd", "keyframes no-ctrv", "keyframes no-solve",
                 "keyframes")
SINGLE_ROWS = ("single box", "single box + offline")


@dataclass(frozen=True)
class KeyframeBenchTrack:
    """One evaluated track: where it comes from, its frames and ground-truth boxes."""

    source: str
    key: str
    profile: str | None
    sequence: Any
    frames: tuple[int, ...]
    boxes: tuple[Any, ...]


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("sources", nargs="+", metavar="SOURCE",
                        help="benchmark list (benchmark.json or its folder) or annotated sequence directory")
    parser.add_argument("--every", type=int, nargs="+", default=[5, 10, 20, 40], metavar="N",
                        help="keyframe intervals (default: 5 10 20 40)")
    parser.add_argument("--preset", default="full", help="tracker preset (default: full)")
    parser.add_argument("--seed", type=int, default=0, help="tracker seed (default 0)")
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
            frames = tuple(range(t.frame_range[0], t.frame_range[1] + 1))
            boxes = tuple(tracks[t.id].box_at(k) for k in frames)
            if any(b is None for b in boxes):
                raise InputError(seq.root, f"tracklet {t.id}: a frame of {frames[0]}..{frames[-1]} has no box")
            out.append(KeyframeBenchTrack(source, t.key, t.profile, seq, frames, boxes))
        return out
    seq = open_sequence(path)
    ids = track_ids or select_moving_vehicle_tracks(seq, source=CachedSource(seq))
    for spec in prepare_tracks(seq, ids, CachedSource(seq), with_shape=False):
        out.append(KeyframeBenchTrack(source, spec.track_id, None, seq, spec.frames, spec.boxes))
    return out


def _ious(result_boxes: dict[int, Any], track: KeyframeBenchTrack) -> np.ndarray:

    from tracker import score_tracklet

    predicted = [result_boxes[k] for k in track.frames]
    return score_tracklet(track.key, predicted, list(track.boxes)).ious


def evaluate_track(track: KeyframeBenchTrack, source, every: list[int], config) -> dict[str, Any]:
    """IoUs (frames 1..n-1) of every row and interval, and which scored frames are keyframes."""
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

    frames = list(track.frames)
    boxes = dict(zip(frames, track.boxes, strict=True))
    online = track_online(source, track.boxes[0], frames[0], frames[-1], config)
    refined = refine_offline(source, online, config)
    record: dict[str, Any] = {"single": {"single box": _ious({e.frame: e.box for e in online.estimates}, track),
                                         "single box + offline": _ious({e.frame: e.box for e in refined.estimates},
                                                                       track)},
                              "every": {}}
    for n in every:
        keys = keyframe_schedule(frames[0], frames[-1], n)
        keyframes = {k: boxes[k] for k in keys}
        passes = keyframe_passes(source, keyframes, frames[0], frames[-1], config)
        rows = {"linear": interpolate_linear(frames, keyframes), "ctrv": interpolate_ctrv(frames, keyframes)}
        for name, params in (("keyframes fwd", KeyframeParams(backward=False, refine=False, interpolation=False)),
                             ("keyframes fwd+bwd", KeyframeParams(refine=False, interpolation=False)),
                             ("keyframes no-ctrv", KeyframeParams(interpolation=False)),
                             ("keyframes no-solve", KeyframeParams(refine=False)), ("keyframes", KeyframeParams())):
            result = track_keyframes(source, keyframes, frames[0], frames[-1], config, params, passes)
            rows[name] = {e.frame: e.box for e in result.estimates}
        record["every"][n] = {"keys": keys, "ious": {name: _ious(b, track) for name, b in rows.items()},
                              "is_key": np.isin(frames[1:], keys)}
    return record


def _acc(parts: list[np.ndarray], masks: list[np.ndarray] | None = None) -> float:
    import numpy as np

    if masks is not None:
        parts = [p[m] for p, m in zip(parts, masks, strict=True)]
    values = np.concatenate(parts) if parts else np.zeros(0)
    return float(100.0 * values.mean()) if values.size else float("nan")


def summarise(records: list[tuple[KeyframeBenchTrack, dict[str, Any]]], every: list[int]) -> dict[str, dict]:
    """{row: {N: (Acc, Acc between keyframes)}} pooled over ``records``."""
    out: dict[str, dict] = {}
    for name in KEYFRAME_ROWS + SINGLE_ROWS:
        out[name] = {}
        for n in every:
            if name in SINGLE_ROWS:
                parts = [r["single"][name] for _, r in records]
            else:
                parts = [r["every"][n]["ious"][name] for _, r in records]
            between = [~r["every"][n]["is_key"] for _, r in records]
            out[name][n] = (_acc(parts), _acc(parts, between))
    return out


def format_table(title: str, summary: dict[str, dict], every: list[int], n_tracks: int, n_frames: int) -> str:
    header = ["row"] + [f"every {n}" for n in every]
    rows = [[name] + [f"{summary[name][n][0]:.1f} ({summary[name][n][1]:.1f})" for n in every]
            for name in KEYFRAME_ROWS + SINGLE_ROWS]
    return "\n".join([f"{title}: {n_tracks} tracks, {n_frames} scored frames; Acc (Acc between keyframes)",
                      _table(header, rows)])


def _table(header: list[str], rows: list[list[str]]) -> str:
    widths = [max(len(h), *(len(r[i]) for r in rows)) for i, h in enumerate(header)]
    line = lambda cells: "  ".join(c.ljust(w) if i == 0 else c.rjust(w)  # noqa: E731
                                   for i, (c, w) in enumerate(zip(cells, widths, strict=True)))
    return "\n".join([line(header), "  ".join("-" * w for w in widths)] + [line(r) for r in rows])


def format_profiles(records: list[tuple[KeyframeBenchTrack, dict[str, Any]]], every: list[int]) -> str:
    by_profile: dict[str, list] = defaultdict(list)
    for track, record in records:
        if track.profile:
            by_profile[track.profile].append((track, record))
    if not by_profile:
        return ""
    header = ["profile", "n"] + [f"every {n}: lin/ctrv/kf" for n in every]
    rows = []
    for profile in sorted(by_profile):
        summary = summarise(by_profile[profile], every)
        rows.append([profile, str(len(by_profile[profile]))]
                    + ["/".join(f"{summary[r][n][0]:.1f}" for r in ("linear", "ctrv", "keyframes")) for n in every])
    return "\n".join(["Acc by motion profile (all SOURCEs)", _table(header, rows)])


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
    config = get_preset(args.preset, seed=args.seed)
    ids = [t.strip() for t in args.tracks.split(",") if t.strip()] if args.tracks else None
    tracks = [t for source in args.sources for t in _tracks(source, args.first, ids)]
    records: list[tuple[KeyframeBenchTrack, dict[str, Any]]] = []
    sources: dict[int, CachedSource] = {}
    for track in (tracks if args.quiet else tqdm(tracks, desc="keyframes", unit="track", file=sys.stderr)):
        source = sources.setdefault(id(track.sequence), CachedSource(track.sequence))
        records.append((track, evaluate_track(track, source, every, config)))
        if len(sources) > 1:   # one sweep cache at a time: the tracks of a sequence come together
            sources = {id(track.sequence): source}
    out = [f"sot-apps bench keyframes, preset {args.preset}, seed {args.seed}; keyframes every N frames and at each "
           "track's last frame"]
    tables: dict[str, Any] = {}
    groups = [(s, [(t, r) for t, r in records if t.source == s]) for s in args.sources]
    if len(groups) > 1:
        groups.append(("all sources pooled", records))
    for name, group in groups:
        summary = summarise(group, every)
        tables[name] = {row: {str(n): list(v) for n, v in cells.items()} for row, cells in summary.items()}
        n_frames = sum(len(t.frames) - 1 for t, _ in group)
        out += ["", format_table(name, summary, every, len(group), n_frames)]
    profiles = format_profiles(records, every)
    if profiles:
        out += ["", profiles]
    print("\n".join(out))
    if args.json:
        write_json(args.json, json_safe({
            "preset": args.preset, "seed": args.seed, "every": every, "tables": tables,
            "tracks": [{"source": t.source, "key": t.key, "profile": t.profile, "frames": [t.frames[0], t.frames[-1]],
                        "single": {k: v.tolist() for k, v in r["single"].items()},
                        "every": {str(n): {"keys": e["keys"], "ious": {k: v.tolist() for k, v in e["ious"].items()}}
                                  for n, e in r["every"].items()}} for t, r in records]}))
    return 0


def register(registry) -> None:
    """Hook for the ``sot-apps bench`` registry."""
    registry.add("keyframes", help="keyframe-assisted tracks vs linear / CTRV interpolation and single-box tracking",
                 add_arguments=add_arguments, run=run, description=__doc__)
