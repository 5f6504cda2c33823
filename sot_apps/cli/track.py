"""``sot-apps track``: track one vehicle through a sequence with SOTracker."""

from __future__ import annotations

import argparse
import sys

from tracker import DETECTION_PRESETS, get_preset, preset_names

from ..errors import InputError
from .common import (
    add_detections_arguments,
    add_sequence_argument,
    add_subcommand,
    declare_outputs,
    load_detections,
    load_sequence,
    nonnegative_int,
    positive_int,
)


def register(subparsers) -> argparse.ArgumentParser:
    parser = add_subcommand(
        subparsers, "track", help="track one vehicle from its first box (SOTracker)",
        description="Track one vehicle through a sequence from its box at the start frame (model-free SOTracker) "
                    "and write DIR/track.json (WORLD states, per-frame points, quality, flags, time) and "
                    "DIR/shape.ply (the aggregated shape in the object frame).",
        examples=["sot-apps track ../shared/data/pandaset_002 --track-id 8ac00bad --out out/tracks/8ac00bad",
                  "sot-apps track ../shared/data/pandaset_002 --init-box -5.49,-6.11,0.43,0.77,4.73,1.97,1.55 "
                  "--start-frame 0 --end-frame 20 --preset full --out out/car",
                  "sot-apps track ../shared/data/pandaset_002 --track-id 91aa5b5c --offline --out out/tracks/91aa5b5c",
                  "sot-apps track ../shared/data/pandaset_002 --track-id 91aa5b5c --lag 10 --out out/tracks/91aa5b5c_lag10"])
    add_sequence_argument(parser)
    who = parser.add_mutually_exclusive_group(required=True)
    who.add_argument("--track-id", metavar="ID", help="annotated track id (a unique prefix is enough); the start "
                                                       "box is its annotation at the start frame")
    who.add_argument("--init-box", metavar="x,y,z,heading,length,width,height",
                     help="start box in the WORLD frame at the start frame (metres, radians; heading of the length axis)")
    parser.add_argument("--allow-any-size", action="store_true",
                        help="track an --init-box whose size no road vehicle has (default: refused; limits in "
                             "sot_apps.tracking.VEHICLE_SIZE_RANGE_M: length 0.5-30 m, width 0.3-5 m, height 0.3-6 m)")
    parser.add_argument("--start-frame", type=nonnegative_int, default=None,
                        help="first frame (default: 0, or the track's first annotated frame)")
    parser.add_argument("--end-frame", type=nonnegative_int, default=None,
                        help="last frame, inclusive (default: the last frame, or the track's last annotated frame)")
    parser.add_argument("--preset", default="full", choices=preset_names(), help="tracker preset (default: full)")
    parser.add_argument("--seed", type=int, default=0, help="random seed (same seed, same output)")
    parser.add_argument("--deskew", action=argparse.BooleanOptionalAction, default=None,
                        help="de-skew the ego motion with per-point times (default: the preset's setting)")
    parser.add_argument("--out", required=True, metavar="DIR", help="output directory")
    parser.add_argument("--offline", action="store_true",
                        help="after the online pass, refine all states jointly against the final shape with a "
                             "smoothness prior, and rebuild the shape (docs/evaluation.md)")
    parser.add_argument("--lag", type=positive_int, metavar="N",
                        help="fixed-lag refinement: each state is re-optimised with the shape over a sliding window "
                             "and final N frames later (docs/tracker.md)")
    parser.add_argument("--quiet", action="store_true", help="no progress bar")
    add_detections_arguments(parser)
    parser.set_defaults(func=run)
    declare_outputs(parser, dirs=("out",), inputs=("sequence", "detections", "kitti_calib"))
    return parser


def run(args: argparse.Namespace) -> int:
    from ..io.bounds import check_box_values
    from ..tracking import (
        annotated_track_start,
        check_vehicle_size,
        init_points,
        parse_init_box,
        refine_track_fixed_lag,
        refine_track_offline,
        track_sequence,
        write_track_result,
    )

    if args.lag is not None and args.offline:
        raise InputError(None, "--lag and --offline are exclusive (offline refines with all frames)")

    overrides = {"seed": args.seed}
    if args.deskew is not None:
        overrides["deskew"] = args.deskew
    config = get_preset(args.preset, **overrides)
    seq = load_sequence(args)
    detections = load_detections(args, seq)
    if detections is None and args.preset in DETECTION_PRESETS:
        raise InputError(None, f"preset {args.preset!r} needs --detections FILE")
    if args.track_id is not None:
        begin = annotated_track_start(seq, args.track_id, config, args.start_frame, args.end_frame)
        object_id, label, init_box, start, end = begin.object_id, begin.label, begin.init_box, begin.start, begin.end
    else:
        init_box = parse_init_box(args.init_box)
        warning = check_vehicle_size(init_box, "--init-box", args.allow_any_size)
        check_box_values(init_box.to_array(), None, "--init-box")
        if warning:
            sys.stderr.write(warning + "\n")
        object_id, label = "custom", None
        start = 0 if args.start_frame is None else args.start_frame
        end = args.end_frame
    result = track_sequence(seq, init_box, start, end, config, progress=not args.quiet, detections=detections)
    if init_points(seq, result.frames[0], init_box) == 0:
        sys.stderr.write(f"warning: the init box holds no points at frame {result.frames[0]}; "
                         "frames continue on the motion prior and are flagged\n")
    if args.offline:
        result = refine_track_offline(seq, result)
    elif args.lag is not None:
        result = refine_track_fixed_lag(seq, result, args.lag)
    path = write_track_result(args.out, seq, result, object_id, init_box, label, offline=args.offline)
    flagged = sum(1 for e in result.estimates[1:] if "no_points" in e.flags or "prior_only" in e.flags)
    times = sorted(e.time_ms for e in result.estimates[1:]) or [0.0]
    print(f"tracked {object_id} frames {result.frames[0]}..{result.frames[-1]} ({len(result.frames)} frames, "
          f"{flagged} on the prior only), shape {len(result.shape)} points, median {times[len(times) // 2]:.1f} ms/frame")
    print(f"wrote {path} and {path.parent / 'shape.ply'}")
    return 0
