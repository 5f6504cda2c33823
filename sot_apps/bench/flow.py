"""``sot-apps bench flow`` (speed) and ``sot-apps bench flow-quality`` (accuracy) of the flow annotation.

- flow: dense flow time per 1920x1080 PandaSet front-camera pair and object, on ONE core (the
  process is pinned with sched_setaffinity). Each visible object is timed alone (ray casting in
  image k, motion, projection, k+1 visibility, LiDAR depth tests); the per-pair overhead (loading
  and projecting the LiDAR occluders) and the file writing are reported separately: the writing's headline figure
  is the wall per pair on the writer pool, pairs handed over one after another as `sot-apps flow` does.
- flow-quality: (a) synthetic world with rendered camera pairs against exact flow (EPE, Fl,
  coverage, wrongly claimed pixels) for our annotation from GT boxes and from tracker states, DIS
  and Farneback; (b) PandaSet photometric error of warping image k+1 into k over object pixels.
"""

from __future__ import annotations

import argparse
import os
import tempfile
import time
from pathlib import Path

from ..errors import InputError
from ..evaluation import DEV_TRACKS

__all__ = ["register", "time_dense_flow", "format_speed_table", "format_quality_tables"]


def _pin_one_core() -> str:
    if hasattr(os, "sched_setaffinity"):
        cpu = sorted(os.sched_getaffinity(0))[0]
        os.sched_setaffinity(0, {cpu})
        return f"pinned to cpu {cpu}"
    return "not pinned (no sched_setaffinity)"


def time_dense_flow(seq, camera_name: str, objects, pairs: range, repeats: int = 3) -> dict:
    """Per object and pair: best-of-``repeats`` dense-flow time (ms) and its pixel count; per pair: the overhead
    (LiDAR occluders), the writing of its files synchronously (wall, CPU), on the writer pool as ``sot-apps flow``
    runs it (up to 10 pairs in a row: wall and CPU per pair) and the optional vis/ pictures."""
    from collections import deque

    import numpy as np

    from ..flow.annotate import FlowOptions, PairWriter, build_pair, compute_pair, pair_output_jobs, write_pair_outputs
    from ..flow.dense import RayCache

    camera = seq.cameras[camera_name]
    options = FlowOptions()
    cache, lidar_cache = RayCache(), {}
    rows, overhead, writing, writing_cpu, vis = [], [], [], [], []
    held: deque = deque(maxlen=10)   # the last pairs' results (~25 MB each at 1080p), written again on the pool
    for k in pairs:
        start = time.perf_counter()
        setup, flow_objects = build_pair(seq, camera, k, objects, options, lidar_cache)
        overhead.append((time.perf_counter() - start) * 1e3)
        for obj in flow_objects:
            best, best_wall, result = np.inf, np.inf, None
            for _ in range(repeats):
                t0, c0 = time.perf_counter(), time.process_time()
                result = compute_pair(setup, [obj], "dense", cache)
                best = min(best, (time.process_time() - c0) * 1e3)
                best_wall = min(best_wall, (time.perf_counter() - t0) * 1e3)
            pixels = result.objects[0].pixels if result.objects else 0
            if pixels:
                rows.append({"pair": k, "object_id": obj.object_id, "pixels": pixels, "ms": best, "wall_ms": best_wall})
        whole = compute_pair(setup, flow_objects, "dense", cache)
        with tempfile.TemporaryDirectory() as tmp:
            # the default outputs, synchronously on this one core (sot-apps flow writes them on a thread pool
            # while it computes the next pair), then the optional vis/ pictures on top
            t0, c0 = time.perf_counter(), time.process_time()
            write_pair_outputs(Path(tmp) / "a", k, whole, camera.frames[k].image_path, False)
            writing.append((time.perf_counter() - t0) * 1e3)
            writing_cpu.append((time.process_time() - c0) * 1e3)
            held.append((k, whole))
            t0 = time.perf_counter()
            write_pair_outputs(Path(tmp) / "b", k, whole, camera.frames[k].image_path, True)
            vis.append((time.perf_counter() - t0) * 1e3 - writing[-1])
    # the same files as sot-apps flow writes them: pair after pair handed to its writer pool (the jobs of a pair in
    # parallel, at most two pairs waiting; no file syncs, as there), until the last file is in place
    pool_ms = pool_cpu_ms = 0.0
    if held:
        with tempfile.TemporaryDirectory() as tmp:
            t0, c0 = time.perf_counter(), time.process_time()
            with PairWriter(workers=options.writer_threads) as writer:
                for k, whole in held:
                    writer.submit(pair_output_jobs(Path(tmp), k, whole, camera.frames[k].image_path, False),
                                  lambda: None)
            pool_ms = (time.perf_counter() - t0) * 1e3 / len(held)
            pool_cpu_ms = (time.process_time() - c0) * 1e3 / len(held)
    return {"camera": camera_name, "width": camera.width, "height": camera.height, "rows": rows,
            "pair_overhead_ms": float(np.mean(overhead)) if overhead else 0.0,
            "writing_ms": float(np.mean(writing)) if writing else 0.0,
            "writing_median_ms": float(np.median(writing)) if writing else 0.0,
            "writing_cpu_median_ms": float(np.median(writing_cpu)) if writing_cpu else 0.0,
            "writing_pool_ms_per_pair": pool_ms, "writing_pool_cpu_ms_per_pair": pool_cpu_ms,
            "writing_pool_pairs": len(held), "writer_threads": options.writer_threads,
            "vis_ms": float(np.mean(vis)) if vis else 0.0}


def format_speed_table(result: dict) -> str:
    import numpy as np

    rows = result["rows"]
    lines = [f"Dense flow, {result['camera']} {result['width']}x{result['height']}, one core; "
             f"CPU time per pair per object (best of repeats; wall-clock in the last column)", "",
             "| object pixels in image k | object-pairs | mean ms | median ms | max ms | mean wall ms |",
             "|---|---|---|---|---|---|"]
    bins = [(0, 5_000), (5_000, 20_000), (20_000, 60_000), (60_000, 10**9)]
    for lo, hi in bins:
        sel = [r["ms"] for r in rows if lo <= r["pixels"] < hi]
        wall = [r["wall_ms"] for r in rows if lo <= r["pixels"] < hi]
        if sel:
            label = f"{lo:,}–{hi:,}" if hi < 10**9 else f"≥ {lo:,}"
            lines.append(f"| {label} | {len(sel)} | {np.mean(sel):.1f} | {np.median(sel):.1f} | {np.max(sel):.1f} "
                         f"| {np.mean(wall):.1f} |")
    if rows:
        all_ms = [r["ms"] for r in rows]
        wall = [r["wall_ms"] for r in rows]
        lines.append(f"| all | {len(all_ms)} | {np.mean(all_ms):.1f} | {np.median(all_ms):.1f} | {np.max(all_ms):.1f} "
                     f"| {np.mean(wall):.1f} |")
    lines += ["", f"per-pair overhead (LiDAR occluders of k and k+1, cached across pairs): "
                  f"{result['pair_overhead_ms']:.0f} ms",
              f"writing a pair's outputs (2 KITTI PNGs, .flo, instance PNG) as sot-apps flow does, on its writer pool "
              f"({result['writer_threads']} threads on this one core, {result['writing_pool_pairs']} pairs in a row): "
              f"{result['writing_pool_ms_per_pair']:.0f} ms wall per pair (target <= 60), CPU "
              f"{result['writing_pool_cpu_ms_per_pair']:.0f} ms per pair",
              f"the same files one after another, nothing overlapped: median {result['writing_median_ms']:.0f} ms "
              f"wall (mean {result['writing_ms']:.0f}), CPU median {result['writing_cpu_median_ms']:.0f} ms; "
              f"optional vis/ pictures (--vis): +{result['vis_ms']:.0f} ms"]
    return "\n".join(lines)


def _speed_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("sequence", metavar="SEQUENCE", help="PandaSet sequence (1920x1080 front camera)")
    parser.add_argument("--camera", default="front_camera")
    parser.add_argument("--pairs", default="0:10", metavar="A:B", help="pairs k -> k+1, A <= k < B (default 0:10)")
    parser.add_argument("--ids", nargs="+", default=list(DEV_TRACKS), metavar="ID",
                        help="annotated track ids (default: the 9 moving PandaSet dev vehicles)")
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--json", metavar="FILE", help="also write the figures as JSON")


def _parse_pairs(text: str) -> range:
    try:
        a, b = (int(v) for v in text.split(":"))
    except ValueError:
        raise InputError(None, f"--pairs expects A:B, got {text!r}") from None
    return range(a, b)


def _run_speed(args: argparse.Namespace) -> int:
    from ..flow.objects import objects_from_annotations
    from ..io import open_sequence
    from ..io.atomic import write_json

    pinned = _pin_one_core()
    seq = open_sequence(args.sequence, cache=True)   # sweeps as sot-apps flow reads them (the conversion cache)
    pairs = _parse_pairs(args.pairs)
    objects = objects_from_annotations(seq, args.ids, frames=range(max(pairs.start - 10, 0),
                                                                    min(pairs.stop + 11, len(seq.frames))))
    result = time_dense_flow(seq, args.camera, objects, pairs, args.repeats)
    print(format_speed_table(result))
    print(f"({pinned}; {len(objects)} annotated objects, pairs {args.pairs}; target <= 150 ms per pair per object)")
    if args.json:
        write_json(args.json, result)
    return 0


def format_quality_tables(synthetic: dict | None, photometric: dict | None) -> str:
    lines = []
    if synthetic:
        lines += [f"(a) Synthetic world: {synthetic['pairs']} rendered pairs {synthetic['camera_size'][0]}x"
                  f"{synthetic['camera_size'][1]}, {synthetic['vehicles']} moving vehicles + parked, seed {synthetic['seed']}; "
                  "vehicle pixels visible in both images", ""]
        for key, title in (("all_vehicles", "all vehicles"), ("moving_vehicles", "moving vehicles")):
            lines += [f"{title}:", "| method | EPE (px) | Fl (%) | coverage (%) | wrongly claimed (%) |",
                      "|---|---|---|---|---|"]
            for r in synthetic[key]:
                wrong = "–" if r.get("wrong_percent") is None else f"{r['wrong_percent']:.1f}"
                lines.append(f"| {r['method']} | {r['epe']:.3f} | {r['fl_percent']:.2f} | {r['coverage_percent']:.1f} | {wrong} |")
            lines.append("")
    if photometric:
        m, mi = photometric["mean_abs_error"], photometric["mean_abs_error_interior"]
        lines += [f"(b) PandaSet {photometric['camera']}: {photometric['pairs']} pairs, {photometric['pixels']} object "
                  f"pixels (flow_noc; {photometric['interior_pixels']} of them >= 5 px inside the mask), states from "
                  f"{photometric.get('source', '?')}; mean |I_k - warp(I_k+1)| (grey levels 0-255)", "",
                  "| flow | all object pixels | interior pixels |", "|---|---|---|"]
        for name in m:
            lines.append(f"| {name} | {m[name]:.2f} | {mi[name]:.2f} |")
    return "\n".join(lines)


def _quality_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--world", metavar="DIR", help="synthetic world directory (created if missing; default: a temp dir)")
    parser.add_argument("--frames", type=int, default=8)
    parser.add_argument("--vehicles", type=int, default=4)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--camera-size", default="960x540", metavar="WxH")
    parser.add_argument("--no-tracker", action="store_true", help="skip the tracker-states row")
    parser.add_argument("--no-synthetic", action="store_true", help="skip (a)")
    parser.add_argument("--pandaset", metavar="SEQUENCE", help="also run (b) on this PandaSet sequence")
    parser.add_argument("--pandaset-pairs", default="0:10", metavar="A:B")
    parser.add_argument("--pandaset-ids", nargs="+", default=list(DEV_TRACKS), metavar="ID")
    parser.add_argument("--pandaset-states", choices=("tracker", "annotations"), default="tracker",
                        help="object states for (b): SOTracker run from the first GT box (default) or the GT boxes")
    parser.add_argument("--smooth", action="store_true", help="(b): smooth the states (as sot-apps flow --smooth)")
    parser.add_argument("--json", metavar="FILE", help="also write all figures as JSON")


def _run_quality(args: argparse.Namespace) -> int:
    from ..flow.objects import objects_from_annotations
    from ..io import open_sequence
    from ..io.atomic import write_json
    from .flow_quality import photometric_quality, synthetic_quality, tracker_objects

    try:
        w, h = (int(v) for v in args.camera_size.lower().split("x"))
    except ValueError:
        raise InputError(None, f"--camera-size expects WxH, got {args.camera_size!r}") from None
    synthetic = None
    if not args.no_synthetic:
        with tempfile.TemporaryDirectory() as tmp:
            world = Path(args.world) if args.world else Path(tmp) / "world"
            synthetic = synthetic_quality(world, args.frames, args.vehicles, args.seed, (w, h),
                                          with_tracker=not args.no_tracker)
    photometric = None
    if args.pandaset:
        seq = open_sequence(args.pandaset)
        pairs = _parse_pairs(args.pandaset_pairs)
        frames = range(max(pairs.start - 10, 0), min(pairs.stop + 11, len(seq.frames)))
        if args.pandaset_states == "tracker":
            objects = tracker_objects(seq, [seq.resolve_track_id(i) for i in args.pandaset_ids], frames)
            source = "SOTracker (started from the first GT box of each track)"
        else:
            objects = objects_from_annotations(seq, args.pandaset_ids, frames=frames)
            source = "ground-truth boxes"
        if args.smooth:
            from ..flow.objects import smoothed

            objects = smoothed(objects, "tracks" if args.pandaset_states == "tracker" else "annotations")
            source += ", smoothed (CTRV EKF + RTS)"
        photometric = photometric_quality(seq, "front_camera", objects, pairs)
        photometric["source"] = source
    print(format_quality_tables(synthetic, photometric))
    if args.json:
        write_json(args.json, {"synthetic": synthetic, "photometric": photometric})
    return 0


def register(registry) -> None:
    """Hook for the ``sot-apps bench`` registry (sot_apps/cli/bench.py)."""
    registry.add("flow", help="dense optical-flow annotation time per 1920x1080 pair per object (one core)",
                 add_arguments=_speed_arguments, run=_run_speed)
    registry.add("flow-quality", help="flow annotation accuracy: synthetic EPE/Fl vs DIS/Farneback, PandaSet photometric",
                 add_arguments=_quality_arguments, run=_run_quality)
