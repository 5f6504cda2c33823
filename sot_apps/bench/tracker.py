"""``sot-apps bench tracker SEQUENCE``: SOTracker speed (ms per frame) and Acc/Rob per preset, one core.

The measurement runs in a child process started with ``OMP_NUM_THREADS=OPENBLAS_NUM_THREADS=
MKL_NUM_THREADS=1`` (set before numpy is imported) and pinned to one CPU with ``sched_setaffinity``, so
the figures are single-threaded. Per preset, every selected track is tracked from its first
ground-truth box over its annotated span (default: the moving vehicle tracks, i.e. the 9 PandaSet
dev tracks on pandaset_002) with the streaming API; frames are read and cached before timing. The
main figures are the CPU time of the tracking thread per ``Tracker.step`` (``time.thread_time``), which
other processes on a shared machine do not inflate; the step's wall-clock time is shown
too. Frame 1 (with the wide ICP search) is included in median/mean/p90 and also reported alone.
``--lag N``: rows for the streaming fixed-lag tracker (a step's time includes its window solve). The modes
are timed interleaved, track by track (online, lag N, ... on one track, then the next), so that a drift of a
shared machine's speed while the bench runs falls on every row alike; "x online" is the ratio of a fixed-lag
row's median to the online row's, per object step and per lone-object frame (the sweep's ground added to both).
``--offline``: a row with the offline refinement's CPU time divided by the tracked frames (the ms per
frame it adds to the online pass). The load average is printed with the table.
"""

from __future__ import annotations

import argparse
import os
import subprocess
import sys
import time
from typing import TYPE_CHECKING, Any

from .. import text_table
from . import format_machine, machine_description, pin_one_core

if TYPE_CHECKING:   # numpy loads when a benchmark runs (`sot-apps --help` imports this module)
    import numpy as np

__all__ = ["register", "add_arguments", "run", "run_benchmark", "format_table"]

_CHILD_ENV = "SOT_APPS_BENCH_CHILD"
_THREAD_VARS = ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS", "NUMEXPR_NUM_THREADS")


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("sequence", metavar="SEQUENCE", help="annotated sequence, e.g. ../shared/data/pandaset_002")
    parser.add_argument("--preset", nargs="+", default=["full"], metavar="NAME",
                        help="tracker presets (default: full; 'all' = every preset)")
    parser.add_argument("--tracks", metavar="ID,...", help="track id prefixes (default: all moving vehicle tracks)")
    parser.add_argument("--lag", type=int, nargs="+", default=[], metavar="N",
                        help="also time fixed-lag tracking (streaming, each state final N frames later) per preset")
    parser.add_argument("--offline", action="store_true",
                        help="also time the offline refinement per preset (CPU time of refine_offline on the online "
                             "result, divided by the track's frames: the ms it adds per frame)")
    parser.add_argument("--json", metavar="FILE", help="also write the figures as JSON")
    parser.add_argument("--in-process", action="store_true",
                        help="measure in this process (no single-threaded child; thread variables as they are)")


def _child_argv(args: argparse.Namespace) -> list[str]:
    argv = ["bench", "tracker", str(args.sequence), "--preset", *args.preset]
    if args.tracks:
        argv += ["--tracks", args.tracks]
    if args.lag:
        argv += ["--lag", *(str(n) for n in args.lag)]
    if args.offline:
        argv += ["--offline"]
    if args.json:
        argv += ["--json", str(args.json)]
    return argv


def _time_track(source, spec, config, lag: int = 0) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Run the streaming tracker over a track's span: boxes (n, 7), wall ms and CPU ms per frame k >= 1.

    ``lag`` > 0: the fixed-lag tracker (tracker.fixed_lag); a step's time includes its window solve."""
    import numpy as np

    from tracker import FixedLagTracker, Tracker

    start = spec.frames[0]
    previous = None
    if config.deskew and start > 0:
        before = source.lidar_frame(start - 1)
        previous = (int(before.timestamp_ns), np.asarray(before.world_from_ego, dtype=np.float64))
    tracker = FixedLagTracker(config, lag) if lag else Tracker(config)
    first = tracker.start(source.lidar_frame(start), spec.boxes[0], previous)
    boxes = [] if lag else [first.box.to_array()]
    wall, cpu = [], []
    for k in spec.frames[1:]:
        frame = source.lidar_frame(k)
        c0 = time.thread_time()
        w0 = time.perf_counter()
        estimate = tracker.step(frame)
        cpu.append((time.thread_time() - c0) * 1e3)
        wall.append((time.perf_counter() - w0) * 1e3)
        if not lag:
            boxes.append(estimate.box.to_array())
    if lag:
        tracker.finish()
        boxes = [e.box.to_array() for e in tracker.result().estimates]
    return np.array(boxes), np.array(wall), np.array(cpu)


class _FramesOnly:
    """A FrameSource view of a cached source without its ``points_world`` cache (as a user's source)."""

    def __init__(self, source) -> None:
        self.source = source

    def __len__(self) -> int:
        return len(self.source)

    def lidar_frame(self, index: int):
        return self.source.lidar_frame(index)


def _time_offline(source, spec, config) -> tuple[np.ndarray, float]:
    """Offline refinement of the online result over a track's span: boxes (n, 7) and the refinement's CPU ms
    (gathering each frame's points included; the online pass is not timed here)."""
    import numpy as np

    from tracker import refine_offline, track

    online = track(source, spec.boxes[0], spec.frames[0], spec.frames[-1], config)
    frames_only = _FramesOnly(source)  # no cached world points: the refinement moves what it needs itself
    c0 = time.thread_time()
    refined = refine_offline(frames_only, online, config)
    cpu_ms = (time.thread_time() - c0) * 1e3
    return np.array([e.box.to_array() for e in refined.estimates]), cpu_ms


def run_benchmark(sequence_path: str, presets: list[str], tracks: list[str] | None,
                  lags: list[int] | None = None, offline: bool = False) -> dict[str, Any]:
    from tracker import get_preset

    from ..evaluation.tracker import prepare_tracks, select_moving_vehicle_tracks
    from ..io import open_sequence
    from ..io.cached_source import CachedSource
    from .sequence_eval import resolve_presets

    pinned = pin_one_core()
    sequence = open_sequence(sequence_path)
    source = CachedSource(sequence)
    ids = tracks or select_moving_vehicle_tracks(sequence, source=source)
    specs = prepare_tracks(sequence, ids, source, with_shape=False)
    for spec in specs:  # read every sweep before timing
        for k in spec.frames:
            source.lidar_frame(k)
    frames = sorted({k for spec in specs for k in spec.frames})
    rows = []
    modes = [0, *(lags or [])]
    for preset in resolve_presets(presets):
        config = get_preset(preset)
        ground_ms = _time_sweep_ground(source, frames, config)
        timed: dict[int, list] = {lag: [] for lag in modes}
        for spec in specs:  # the modes interleaved, track by track
            for lag in modes:
                timed[lag].append(_time_track(source, spec, config, lag))
        mode_rows = [_timing_row(f"{preset}+lag{lag}" if lag else preset, specs, timed[lag], ground_ms)
                     for lag in modes]
        for row in mode_rows[1:]:
            row.update(_times_online(row, mode_rows[0]))
        rows += mode_rows
        if offline:  # after the preset's online and fixed-lag rows
            rows.append(_offline_row(source, specs, config, preset))
    machine = machine_description() | {"pinning": pinned}
    return {"sequence": str(sequence.root), "tracks": [t.track_id for t in specs],
            "frames_per_preset": rows[0]["frames"] if rows else 0, "machine": machine, "rows": rows}


def _timing_row(name: str, specs, timed: list, ground_ms: np.ndarray) -> dict[str, Any]:
    """A row from each track's (boxes, wall ms, CPU ms) of one preset and mode."""
    import numpy as np

    from tracker import pool_metrics, score_tracklet

    pooled = pool_metrics([score_tracklet(spec.track_id, boxes, np.array([b.to_array() for b in spec.boxes]))
                           for spec, (boxes, _, _) in zip(specs, timed, strict=True)])
    w_all, c_all = np.concatenate([w for _, w, _ in timed]), np.concatenate([c for _, _, c in timed])
    c_later = np.concatenate([c[1:] for _, _, c in timed])
    return {"row": name, "acc": pooled.acc, "rob": pooled.rob, "frames": int(c_all.size),
            "cpu_median_ms": float(np.median(c_all)), "cpu_mean_ms": float(c_all.mean()),
            "cpu_p90_ms": float(np.percentile(c_all, 90)), "cpu_frame1_mean_ms": float(np.mean([c[0] for _, _, c in timed])),
            "cpu_median_ms_k2": float(np.median(c_later)) if c_later.size else float("nan"),
            "wall_median_ms": float(np.median(w_all)), "wall_mean_ms": float(w_all.mean()),
            **({"sweep_ground_ms": float(np.median(ground_ms))} if ground_ms.size else {})}


def _times_online(row: dict[str, Any], online: dict[str, Any]) -> dict[str, float]:
    """A fixed-lag row's median against the online row's (timed interleaved with it): per object step, and per
    lone-object frame (the sweep's ground, when shared, added to both)."""
    ground = row.get("sweep_ground_ms", 0.0)
    step, base = row["cpu_median_ms"], online["cpu_median_ms"]
    return {"times_online": step / base if base > 0 else float("nan"),
            "times_online_lone_object": (step + ground) / (base + ground) if base + ground > 0 else float("nan")}


def _time_sweep_ground(source, frames: list[int], config) -> np.ndarray:
    """``ground.remover="sweep"``: CPU ms of the whole-sweep ground mask per sweep (one plane per sweep, shared by
    every object tracked in that sweep), measured once per sweep; the cache is then warm, so the step times
    that follow exclude it. Other presets: empty."""
    import numpy as np
    if config.ground.remover != "sweep":
        return np.zeros(0)
    from tracker import cached_sweep_ground_mask, sweep_ground_mask

    params = config.ground.sweep_args()
    ms = []
    for k in frames:
        points = source.lidar_frame(k).points_ego
        c0 = time.thread_time()
        sweep_ground_mask(points, *params)
        ms.append((time.thread_time() - c0) * 1e3)
        cached_sweep_ground_mask(points, *params)
    return np.array(ms)


def _offline_row(source, specs, config, preset: str) -> dict[str, Any]:
    """The ``PRESET+offline`` row: the refinement's CPU time per frame (k >= 1, as the other rows count),
    amortised over all tracks, and per track; Acc/Rob of the refined boxes."""
    import numpy as np

    from tracker import pool_metrics, score_tracklet

    scores, per_track = [], []
    for spec in specs:
        boxes, cpu_ms = _time_offline(source, spec, config)
        scores.append(score_tracklet(spec.track_id, boxes, np.array([b.to_array() for b in spec.boxes])))
        per_track.append((cpu_ms, len(spec.frames) - 1))
    pooled = pool_metrics(scores)
    frames = sum(n for _, n in per_track)
    track_ms = np.array([ms / max(n, 1) for ms, n in per_track])
    return {"row": f"{preset}+offline", "acc": pooled.acc, "rob": pooled.rob, "frames": int(frames),
            "offline_added_ms": float(sum(ms for ms, _ in per_track) / max(frames, 1)),
            "offline_added_ms_per_track": [float(x) for x in track_ms]}


def format_table(result: dict[str, Any]) -> str:
    header = ["preset", "median ms", "mean ms", "p90 ms", "frame-1 ms", "median k>=2", "wall median", "wall mean",
              "added ms", "sweep ground ms", "x online", "x online (lone)", "Acc", "Rob"]
    timing = ("cpu_median_ms", "cpu_mean_ms", "cpu_p90_ms", "cpu_frame1_mean_ms", "cpu_median_ms_k2", "wall_median_ms",
              "wall_mean_ms", "offline_added_ms", "sweep_ground_ms")
    ratios = ("times_online", "times_online_lone_object")
    body = [[r["row"], *(f"{r[key]:.1f}" if key in r else "-" for key in timing),
             *(f"{r[key]:.2f}" if key in r else "-" for key in ratios),
             f"{100 * r['acc']:.1f}", f"{100 * r['rob']:.1f}"] for r in result["rows"]]
    lines = [f"sequence: {result['sequence']}",
             f"tracks: {len(result['tracks'])} ({', '.join(t[:8] for t in result['tracks'])}); "
             f"{result['frames_per_preset']} tracked frames per preset (k >= 1)",
             "", text_table.format_table(header, body)]
    lines += ["", "ms per frame = CPU time of the tracking thread in Tracker.step (crop, ground removal, association,",
              "optimisation; sweeps are read before timing), frames k >= 1 with frame 1's wide search included;",
              "'wall' = wall-clock time of the step (inflated when other processes share the cores).",
              "'added ms' (PRESET+offline rows, --offline) = CPU time of the offline refinement of the online",
              "result (gathering each frame's points included), divided by the tracked frames: what it adds per frame.",
              "'sweep ground ms' (ground_scope 'sweep': full, faithful) = median CPU time of the whole-sweep ground mask",
              "per sweep, timed once per sweep before the steps and shared by every object of the sweep (the step",
              "times exclude it); a lone tracked object pays median ms + sweep ground ms per frame.",
              "'x online' (PRESET+lagN rows) = median ms / the online row's median ms (the modes are timed",
              "interleaved, track by track); 'x online (lone)' = the same with the sweep's ground added to both.",
              "Acc/Rob in % (pooled, frames 1..n-1).",
              "", "machine:", format_machine(result["machine"])]
    return "\n".join(lines)


def run(args: argparse.Namespace) -> int:
    if not args.in_process and os.environ.get(_CHILD_ENV) != "1":
        env = dict(os.environ)
        env.update({name: "1" for name in _THREAD_VARS})
        env[_CHILD_ENV] = "1"
        return subprocess.call([sys.executable, "-m", "sot_apps.cli.main", *_child_argv(args)], env=env)
    from ..io.atomic import write_json

    tracks = [t for t in args.tracks.split(",") if t] if args.tracks else None
    result = run_benchmark(args.sequence, args.preset, tracks, args.lag, args.offline)
    print(format_table(result))
    if args.json:
        write_json(args.json, result)
    return 0


def register(registry) -> None:
    """Hook for the ``sot-apps bench`` registry."""
    registry.add("tracker", help="SOTracker ms/frame (median/mean/p90, one core) and Acc/Rob per preset",
                 add_arguments=add_arguments, run=run, description=__doc__)
