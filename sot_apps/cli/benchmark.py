"""``sot-apps benchmark make|build|realism``: generate a LiDAR-SOT benchmark, build lists, measure realism."""

from __future__ import annotations

import argparse
from pathlib import Path

from ..errors import InputError
from .common import (
    add_action,
    add_subcommand,
    coordinate,
    declare_outputs,
    finite_float,
    nonnegative_float,
    nonnegative_int,
    positive_float,
    positive_int,
    probability,
)


def _frames(text: str) -> tuple[int, int]:
    try:
        a, b = (int(v) for v in text.split(":"))
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected A:B (frames A..B-1), got {text!r}") from None
    if not 0 <= a < b:
        raise argparse.ArgumentTypeError(f"expected 0 <= A < B, got {text!r}")
    return a, b


def _range(text: str) -> tuple[float, float]:
    try:
        lo, hi = (finite_float(v) for v in text.split(":"))
    except (ValueError, argparse.ArgumentTypeError):
        raise argparse.ArgumentTypeError(f"expected MIN:MAX in metres, got {text!r}") from None
    if not 0 < lo < hi:
        raise argparse.ArgumentTypeError(f"expected 0 < MIN < MAX, got {text!r}")
    return lo, hi


def register(subparsers) -> argparse.ArgumentParser:
    parser = add_subcommand(
        subparsers, "benchmark", help="generate a LiDAR-SOT benchmark into real sweeps; build LiDAR-SOT lists",
        description="make: insert bank vehicles with motion profiles into copies of a real sequence (rolling scan, "
                    "occlusion both ways) and write canonical sequences + benchmark.json (LiDAR-SOT list format). "
                    "build: LiDAR-SOT-style lists from annotated sequences with the paper's criteria. realism: points "
                    "in box versus range of inserted and real vehicles (table + PNG). See docs/benchmark.md.",
        examples=["sot-apps benchmark make --background ../shared/data/pandaset_002 --bank bank --tracklets 200 "
                  "--frames 0:40 --seed 0 --out out/bench",
                  "sot-apps eval --benchmark out/bench/benchmark.json --preset full faithful --seeds 3",
                  "sot-apps benchmark build ../shared/data/pandaset_002 --min-frames 20 --out out/lists",
                  "sot-apps benchmark realism out/bench --plot docs/images/benchmark_points_vs_range.png"])
    sub = parser.add_subparsers(dest="action", metavar="ACTION", parser_class=type(parser))
    make = add_action(
        sub, "make", help="generate a benchmark (see docs/benchmark.md)",
        description="Insert bank vehicles that follow motion profiles (constant speed, braking, acceleration, "
                    "stop-and-go, lane change, turn, U-turn) into copies of a real annotated sequence: each vehicle is "
                    "ray cast with the background's sensor (rolling scan, point times), real returns behind it are "
                    "removed and its returns behind real objects dropped. Writes OUT/copy_NNN/ (canonical "
                    "sequences), OUT/benchmark.json (LiDAR-SOT list format: tracklets with difficulty and profile) "
                    "and OUT/make.json. The same seed gives the same bytes; a rerun resumes finished copies. "
                    "See docs/benchmark.md.",
        examples=["sot-apps benchmark make --background ../shared/data/pandaset_002 --bank bank --tracklets 200 "
                  "--frames 0:40 --seed 0 --out out/bench",
                  "sot-apps benchmark make --background ../shared/data/pandaset_002 --bank bank --tracklets 28 "
                  "--workers 2 --drop 0.05 --out out/bench_drop",
                  "sot-apps benchmark make --background ../shared/data/pandaset_002 --bank bank --replicas 20d13d1d "
                  "91aa5b5c --out out/replicas"])
    make.add_argument("--background", required=True, metavar="SEQUENCE", help="real annotated sequence")
    make.add_argument("--bank", required=True, metavar="BANK", help="vehicle bank (sot-apps bank build)")
    make.add_argument("--tracklets", type=positive_int, default=200, metavar="N", help="listed tracklets (default 200)")
    make.add_argument("--frames", type=_frames, default=(0, 40), metavar="A:B",
                      help="background frames A..B-1 = every tracklet's span (default 0:40)")
    make.add_argument("--seed", type=int, default=0, help="seed (default 0): same seed, same bytes")
    make.add_argument("--out", required=True, metavar="DIR", help="output directory (rerun to resume)")
    make.add_argument("--per-copy", type=positive_int, default=14, metavar="K",
                      help="listed tracklets per copy of the background (default 14)")
    make.add_argument("--sensor", default="pandaset_pandar64",
                      help="sensor preset or JSON (default pandaset_pandar64: PandaSet's Pandar64 with its range drop; "
                           "the scan phase is fitted to the background's point times)")
    make.add_argument("--range", type=_range, default=(5.0, 80.0), metavar="MIN:MAX",
                      help="range of the tracklets at their first frame in metres (default 5:80, cut into --bands; a "
                           "start is drawn uniformly over the free ground of its band)")
    make.add_argument("--bands", type=positive_float, nargs="*", default=(17.0, 40.0), metavar="M",
                      help="range edges (m) of the bands that tracklets fill in turn, so that every difficulty is "
                           "present (default 17 40: pandar64's easy / medium / hard ranges)")
    make.add_argument("--drop", type=probability, default=0.0, help="random ray drop probability in [0, 1) (default 0)")
    make.add_argument("--workers", type=positive_int, default=1, help="processes simulating copies (default 1)")
    make.add_argument("--quiet", action="store_true", help="no progress bars")
    make.add_argument("--origin", type=coordinate, nargs=3, default=(0.0, 0.0, 0.0), metavar=("X", "Y", "Z"),
                      help="the simulated optical centre in the background's LiDAR frame (m; default 0 0 0: the "
                           "reader's LiDAR frame, which for PandaSet is the Pandar64's optical centre measured from "
                           "the sweeps; docs/lidar_sim.md). Only for what-if experiments")
    make.add_argument("--replicas", nargs="+", default=(), metavar="TRACK_ID",
                      help="realism check instead of profiles: one copy in which each of these real tracks is "
                           "replaced by its bank vehicle on its own path (real points cut, vehicle simulated; same "
                           "ranges, headings, occluders), listed over the track's annotated frames; compare "
                           "`eval --benchmark` with `eval SEQUENCE --tracks`")
    make.add_argument("--profiles", nargs="+", default=None, metavar="PROFILE",
                      help="motion profiles, tracklet i gets the (i mod P)-th (default: the 8 classic ones, "
                           "constant_speed ... occluded); also far_approach, passing, hidden, oblique (they start "
                           "in their own range band; docs/benchmark.md)")
    make.add_argument("--split", choices=("choose", "confirm", "all"), default="all",
                      help="the part of the bank to draw vehicles from: choose (tuning), confirm (never used to "
                           "choose), all (default); see docs/benchmark.md")
    make.set_defaults(action_run=_run_make)
    declare_outputs(make, dirs=("out",), inputs=("background", "bank", "sensor"))

    build = add_action(
        sub, "build", help="LiDAR-SOT-style lists from annotated sequences",
        description="Select annotated tracklets with the LiDAR-SOT paper's criteria (long enough, enough points in "
                    "each of the first 10 frames, not static) and write OUT/bench_list.json and "
                    "OUT/easy.json, medium.json, hard.json (difficulty from the mean points in the first 10 frames). A build "
                    "in which no tracklet qualifies is an error (exit code 2) and writes nothing.",
        examples=["sot-apps benchmark build ../shared/data/pandaset_002 --min-frames 20 --out out/lists",
                  "sot-apps benchmark build out/seq_a out/seq_b --types vehicle,cyclist --max-frames 100 --out out/lists",
                  "sot-apps eval --benchmark out/lists/bench_list.json --preset full"])
    build.add_argument("sequences", nargs="+", metavar="SEQUENCE")
    build.add_argument("--out", required=True, metavar="DIR", help="writes bench_list.json, easy/medium/hard.json")
    build.add_argument("--min-frames", type=positive_int, default=100, help="minimum tracklet length (default 100, the paper's)")
    build.add_argument("--max-frames", type=positive_int, default=None, help="cut tracklets to this length (default: whole run)")
    build.add_argument("--min-points", type=nonnegative_int, default=20,
                       help="more than this many points in each of the first 10 frames (default 20)")
    build.add_argument("--min-displacement", type=nonnegative_float, default=2.0,
                       help="not static: the centre moves more than this (m, default 2)")
    build.add_argument("--types", default="vehicle", help="comma-separated: vehicle,pedestrian,cyclist (default vehicle)")
    build.add_argument("--quiet", action="store_true", help="no progress bar")
    build.set_defaults(action_run=_run_build)
    declare_outputs(build, dirs=("out",), inputs=("sequences",))

    realism = add_action(
        sub, "realism", help="points in box versus range: inserted versus real vehicles (and, for "
                             "--replicas benchmarks, each copy against its real track)",
        description="Count the LiDAR points in every box of a `benchmark make` output, inserted vehicles against the "
                    "background's real vehicles, binned by range, and print the table (medians and quartiles per "
                    "bin). For a --replicas benchmark, each copy is also compared with the real track it replaces. "
                    "--plot writes the points-versus-range figure, --json the binned figures.",
        examples=["sot-apps benchmark realism out/bench",
                  "sot-apps benchmark realism out/bench --plot docs/images/benchmark_points_vs_range.png "
                  "--json out/realism.json"])
    realism.add_argument("benchmark", metavar="DIR", help="a `benchmark make` output directory")
    realism.add_argument("--plot", metavar="PNG", help="write the points-versus-range plot")
    realism.add_argument("--json", metavar="FILE", help="write the binned figures as JSON")
    realism.set_defaults(action_run=_run_realism)
    declare_outputs(realism, files=("plot", "json"), inputs=("benchmark",))
    parser.set_defaults(func=lambda args: _run(args, parser))
    return parser


def _run(args: argparse.Namespace, parser: argparse.ArgumentParser) -> int:
    run = getattr(args, "action_run", None)
    if run is None:
        parser.print_help()
        return 2
    return int(run(args) or 0)


def _run_make(args: argparse.Namespace) -> int:
    from ..benchmark.make import MakeConfig, make_benchmark
    from ..objects.motion_profiles import PROFILES

    config = MakeConfig(str(args.background), str(args.bank), args.tracklets, tuple(args.frames), args.seed,
                        str(args.out), args.per_copy, args.sensor, tuple(args.range), args.drop, args.workers,
                        tuple(args.origin), tuple(args.replicas), tuple(args.bands),
                        tuple(args.profiles) if args.profiles else PROFILES, args.split)
    report = make_benchmark(config, progress=not args.quiet)
    counts = report["counts"]
    print(f"{report['tracklets']} tracklets in {report['copies']} copies -> {Path(args.out) / 'benchmark.json'}")
    print("difficulty: " + ", ".join(f"{k} {v}" for k, v in counts["difficulty"].items()))
    print("profile:    " + ", ".join(f"{k} {v}" for k, v in counts["profile"].items()))
    if report.get("unlisted"):
        print("unlisted (the points did not show the profile; docs/benchmark.md): "
              + ", ".join(f"{k} {v}" for k, v in report["unlisted"].items()))
    print(f"time: {report['seconds']['total']:.0f} s (planning {report['seconds']['planning']:.0f} s)")
    return 0


def _run_build(args: argparse.Namespace) -> int:
    from tqdm import tqdm

    from ..benchmark.lists import ListCriteria, build_lists, relative, write_lists
    from ..io import open_sequence

    names = {"vehicle": 1, "pedestrian": 2, "cyclist": 4}
    types = tuple(t.strip() for t in args.types.split(",") if t.strip())
    bad = [t for t in types if t not in names]
    if bad or not types:
        raise InputError(None, f"--types: unknown {bad}; choose from {', '.join(names)}")
    criteria = ListCriteria(args.min_frames, args.max_frames, args.min_points, 10, args.min_displacement,
                            tuple(names[t] for t in types))
    out = Path(args.out)
    sequences = [(open_sequence(p), relative(Path(p), out)) for p in args.sequences]
    progress = lambda it: tqdm(it, desc="counting", unit="frame", disable=args.quiet, leave=False)  # noqa: E731
    entries = build_lists(sequences, criteria, progress)
    if not entries:
        raise InputError(out, f"benchmark build: no tracklet of {len(sequences)} sequence(s) meets the criteria "
                              f"(--min-frames {args.min_frames}, --min-points {args.min_points}, --min-displacement "
                              f"{args.min_displacement:g}, --types {','.join(types)}); nothing written")
    paths = write_lists(entries, out)
    levels = {d: sum(e["difficulty"] == d for e in entries) for d in ("easy", "medium", "hard")}
    print(f"{len(entries)} tracklets ({', '.join(f'{k} {v}' for k, v in levels.items())}) -> "
          + ", ".join(str(p) for p in paths))
    return 0


def _run_realism(args: argparse.Namespace) -> int:
    from ..benchmark.realism import format_realism, format_replicas, points_versus_range, replica_counts, write_plot
    from ..io.atomic import write_json

    curves = points_versus_range(Path(args.benchmark))
    print(format_realism(curves))
    replicas = replica_counts(Path(args.benchmark))
    if replicas:
        print()
        print(format_replicas(replicas))
    if args.plot:
        write_plot(curves, Path(args.plot))
        print(f"plot -> {args.plot}")
    if args.json:
        write_json(args.json, curves.to_dict())
    return 0
