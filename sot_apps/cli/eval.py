"""``sot-apps eval``: LiDAR-SOT metrics of tracker presets on a sequence's annotated tracks."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from ..io import FORMATS
from .common import (
    add_detections_arguments,
    add_subcommand,
    check_profile,
    declare_outputs,
    load_detections,
    load_sequence,
    nonnegative_int,
    positive_int,
    simulated_detections,
)


def register(subparsers) -> argparse.ArgumentParser:
    parser = add_subcommand(
        subparsers, "eval", help="evaluate tracker presets against annotations (Acc, Rob, Shape, Success, Precision)",
        description=("Track every selected annotated object from its first ground-truth box over its annotated span "
                     "with each preset, and print the paper-style tables (pooled, per difficulty, per track). "
                     "Metrics: docs/evaluation.md. --all-moving selects vehicles whose centre moves > 2 m and whose "
                     "box holds >= 15 points on average over its first 10 frames (the 9 dev tracks on pandaset_002)."),
        examples=["sot-apps eval ../shared/data/pandaset_002 --all-moving",
                  "sot-apps eval ../shared/data/pandaset_002 --all-moving --preset all --offline --json eval.json",
                  "sot-apps eval ../shared/data/pandaset_002 --tracks 20d13d1d,91aa5b5c --preset full icp_mp --seeds 3",
                  "sot-apps eval ../shared/data/pandaset_002 --all-moving --preset det full det_sot "
                  "--simulate-detections learned --seeds 3",
                  "sot-apps eval --benchmark out/bench/benchmark.json --preset full faithful --seeds 3",
                  "sot-apps eval --benchmark out/bench/benchmark.json --preset det_sot --simulate-detections learned "
                  "--set detection.weight=0.1 --seeds 3",
                  "sot-apps eval --benchmark lidar-sot --lists ../shared/data/readers/lidar_sot_benchmark/vehicle "
                  "WAYMO_DIR"])
    parser.add_argument("sequence", metavar="SEQUENCE", nargs="?", default=None,
                        help="sequence directory (canonical or PandaSet); with --benchmark lidar-sot: the Waymo data "
                             "directory")
    parser.add_argument("--format", choices=FORMATS, default=None, help="force the reader (default: auto-detect)")
    parser.add_argument("--benchmark", metavar="LIST",
                        help="evaluate a tracklet list instead: a list file (benchmark.json of `benchmark make`, "
                             "bench_list.json of `benchmark build`) or folder, or 'lidar-sot' with --lists and "
                             "SEQUENCE = the Waymo data directory; tables per difficulty and per motion profile")
    parser.add_argument("--first", type=positive_int, metavar="N", help="with --benchmark: only the list's first N tracklets "
                                                                 "(a generated list is ordered copy by copy)")
    parser.add_argument("--lists", metavar="DIR", help="with --benchmark lidar-sot: LiDAR-SOT's list folder "
                                                       "(bench_list.json, easy/medium/hard.json)")
    which = parser.add_mutually_exclusive_group()
    which.add_argument("--tracks", metavar="ID,...", help="comma-separated track ids (unique prefixes allowed)")
    which.add_argument("--all-moving", action="store_true", help="all moving vehicle tracks (see description)")
    parser.add_argument("--preset", nargs="+", action="extend", metavar="NAME",
                        help="tracker presets, one row each (default: full; 'all' = every preset)")
    parser.add_argument("--offline", action="store_true", help="add a row with offline refinement for each preset")
    parser.add_argument("--lag", type=positive_int, nargs="+", default=[], metavar="N",
                        help="add a fixed-lag row (each state final N frames later) for each preset and N")
    parser.add_argument("--seeds", type=positive_int, default=1, metavar="N",
                        help="run N tracker seeds, from --first-seed, and average (default 1)")
    parser.add_argument("--first-seed", type=nonnegative_int, default=0, metavar="S",
                        help="the first tracker seed (default 0): seeds S..S+N-1; reports of one set with disjoint "
                             "seeds pool in `sot-apps bench rule`")
    parser.add_argument("--end-frame", type=nonnegative_int, metavar="K", help="stop every track at frame K (default: span end)")
    parser.add_argument("--no-per-track", action="store_true", help="omit the per-track table")
    parser.add_argument("--json", metavar="FILE", help="also write the full report as JSON (atomically)")
    add_detections_arguments(parser)
    parser.add_argument("--simulate-detections", metavar="PROFILE",
                        help="instead of --detections: ground truth with a detector's errors, simulated per seed "
                             "(profiles: learned, noisy, clean; docs/detection.md)")
    parser.add_argument("--set", dest="overrides", action="append", default=[], metavar="FIELD=VALUE",
                        help="replace a tracker setting (a dotted TrackerConfig path, e.g. detection.weight=0.1 or "
                             "motion.alpha=0.6) in every preset; repeatable; the value is read as the field's type")
    parser.set_defaults(func=run)
    declare_outputs(parser, files=("json",), inputs=("sequence", "benchmark", "lists", "detections", "kitti_calib"))
    return parser


def run(args: argparse.Namespace) -> int:
    from tqdm import tqdm

    from ..bench.sequence_eval import checked_overrides, evaluate, resolve_presets
    from ..errors import InputError
    from ..evaluation.tracker import format_report
    from ..io.atomic import write_json
    from ..provenance import invoked_command, provenance_record

    if any(n < 1 for n in args.lag):
        raise InputError(None, f"--lag must be at least 1, not {min(args.lag)}")
    if args.seeds < 1:
        raise InputError(None, f"--seeds must be at least 1, not {args.seeds}")
    if args.detections and args.simulate_detections:
        raise InputError(None, "give --detections or --simulate-detections, not both")
    presets = resolve_presets(args.preset, with_detections=bool(args.detections or args.simulate_detections))
    args.overrides = checked_overrides(args.overrides, presets)
    if args.benchmark:
        return _run_benchmark(args, presets)
    if args.sequence is None or not (args.tracks or args.all_moving):
        raise InputError(None, "eval: give SEQUENCE with --tracks or --all-moving (or --benchmark LIST)")
    sequence = load_sequence(args)
    detections = load_detections(args, sequence)
    if args.simulate_detections:
        check_profile(args.simulate_detections)
        detections = lambda seed: simulated_detections(sequence, args.simulate_detections, seed)  # noqa: E731
    ids = [t.strip() for t in args.tracks.split(",") if t.strip()] if args.tracks else None
    if args.tracks is not None and not ids:
        raise InputError(None, "--tracks is empty")
    if args.end_frame is not None:
        sequence.check_index(args.end_frame)
    progress = lambda jobs: tqdm(jobs, desc="eval", unit="track", file=sys.stderr, leave=False)  # noqa: E731
    report = evaluate(sequence, ids, presets, offline=args.offline, seeds=_seeds(args),
                      end_frame=args.end_frame, progress=progress, detections=detections, lags=args.lag,
                      overrides=args.overrides)
    if args.overrides:
        print("set: " + " ".join(f"{k}={v}" for k, v in args.overrides.items()))
    print(format_report(report, per_track=not args.no_per_track))
    if args.json:
        write_json(args.json, report.to_dict() | {"provenance": provenance_record([invoked_command()])})
    return 0


def _run_benchmark(args: argparse.Namespace, presets: list[str]) -> int:
    from tqdm import tqdm

    from ..bench.benchmark_eval import evaluate_tracklets, format_benchmark, open_benchmark
    from ..errors import InputError
    from ..io.atomic import write_json
    from ..io.checksums import sha256_file
    from ..provenance import invoked_command, provenance_record

    if args.tracks or args.all_moving:
        raise InputError(None, "--benchmark takes its tracklets from the list: drop --tracks/--all-moving")
    if args.detections:
        raise InputError(None, "--benchmark spans several sequences: use --simulate-detections, not --detections")
    bench = open_benchmark(args.benchmark, args.lists, args.sequence, args.first)

    def progress(total: int):
        bar = tqdm(total=total, desc="eval", unit="run", file=sys.stderr, leave=False)
        return lambda: bar.update(1)

    detections = None
    if args.simulate_detections:
        check_profile(args.simulate_detections)
        detections = lambda seq, seed: simulated_detections(seq, args.simulate_detections, seed)  # noqa: E731
    run = evaluate_tracklets(bench.tracklets, bench.resolve, presets, _seeds(args), progress=progress,
                             detections=detections, overrides=args.overrides, lags=args.lag, offline=args.offline)
    title = f"benchmark: {bench.source} ({len(bench.tracklets)} tracklets)"
    if args.overrides:
        title += "; set " + " ".join(f"{k}={v}" for k, v in args.overrides.items())
    print(format_benchmark(run, title))
    if args.json:
        # the list evaluated (its path names the set in `sot-apps bench rule`; the sha256 of each list file read)
        source = Path(bench.source).resolve()
        files = sorted(source.glob("*.json")) if source.is_dir() else [source]
        listed = {"source": str(source), "sha256": {f.name: sha256_file(f) for f in files}}
        write_json(args.json, run.to_dict() | {"list": listed, "provenance": provenance_record([invoked_command()])})
    return 0


def _seeds(args: argparse.Namespace) -> list[int]:
    return list(range(args.first_seed, args.first_seed + args.seeds))
