"""``sot-apps track``: track one vehicle through a sequence with SOTracker."""

from __future__ import annotations

import argparse
import sys

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
                  "sot-apps track ../shared/data/pandaset_002 --track-id 91aa5b5c --lag 10 --out out/tracks/91aa5b5c_lag10",
                  "sot-apps track ../shared/data/pandaset_002 --keyframes keyframes.json --track-id 91aa5b5c "
                  "--out out/tracks/91aa5b5c_keyframes"])
    from tracker import preset_names  # here, not at import: `sot-apps --help` lists the commands without it

    add_sequence_argument(parser)
    who = parser.add_mutually_exclusive_group()
    who.add_argument("--track-id", metavar="ID", help="annotated track id (a unique prefix is enough); the start "
                                                       "box is its annotation at the start frame; with --keyframes: "
                                                       "the track of the keyframe file")
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
    parser.add_argument("--keyframes", metavar="FILE",
                        help="boxes given at some frames (keyframes JSON, data_schema/keyframes.schema.json; KITTI "
                             "label_02 .txt; AV2 annotations .feather): track between them, each reproduced exactly "
                             "at its frame (docs/tracker.md, Keyframe-assisted tracks)")
    parser.add_argument("--keyframe-sigma", metavar="M[,RAD]",
                        help="with --keyframes: soft keyframes, pulled with weight 1/sigma^2 (centre sigma in metres, "
                             "heading sigma in radians, default 0.02) instead of held exactly")
    parser.add_argument("--quiet", action="store_true", help="no progress bar")
    add_detections_arguments(parser)
    parser.set_defaults(func=run)
    declare_outputs(parser, dirs=("out",), inputs=("sequence", "detections", "kitti_calib", "keyframes"))
    return parser


def run(args: argparse.Namespace) -> int:
    from tracker import DETECTION_PRESETS, get_preset

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
    if args.keyframes is None and args.track_id is None and args.init_box is None:
        raise InputError(None, "give --track-id ID, --init-box BOX or --keyframes FILE")
    if args.keyframes is not None and (args.init_box is not None or args.lag is not None):
        raise InputError(None, "--keyframes is a track of its own: drop --init-box / --lag (it is refined offline)")
    if args.keyframe_sigma is not None and args.keyframes is None:
        raise InputError(None, "--keyframe-sigma needs --keyframes FILE")

    overrides = {"seed": args.seed}
    if args.deskew is not None:
        overrides["deskew"] = args.deskew
    config = get_preset(args.preset, **overrides)
    seq = load_sequence(args)
    if args.keyframes is not None:
        return _run_keyframes(args, seq, config)
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


def keyframe_params(sigma: str | None):
    """``--keyframe-sigma M[,RAD]`` as :class:`tracker.keyframes.KeyframeParams` (None: hard keyframes)."""
    from tracker import KeyframeParams

    if sigma is None:
        return KeyframeParams()
    try:
        values = [float(v) for v in sigma.split(",")]
        if len(values) not in (1, 2):
            raise ValueError("one or two numbers")
        return KeyframeParams(sigma_xyz=values[0], sigma_heading=values[1] if len(values) > 1 else 0.0)
    except ValueError as exc:
        raise InputError(None, f"--keyframe-sigma {sigma!r}: expected M or M,RAD (non-negative numbers): {exc}") from None


def _run_keyframes(args: argparse.Namespace, seq, config) -> int:
    from tracker import track_keyframes

    from ..io.cached_source import CachedSource
    from ..io.keyframes import pick_keyframe_track, read_keyframes
    from ..tracking import resolve_span, write_track_result

    params = keyframe_params(args.keyframe_sigma)
    object_id, keyframes = pick_keyframe_track(read_keyframes(args.keyframes, seq, args.kitti_calib), args.track_id,
                                               args.keyframes)
    start = min(keyframes) if args.start_frame is None else args.start_frame
    end = max(keyframes) if args.end_frame is None else args.end_frame
    resolve_span(seq, start, end)
    if not any(start <= k <= end for k in keyframes):
        raise InputError(args.keyframes, f"track {object_id}: no keyframe in frames {start}..{end}")
    label = seq.tracks()[object_id].label if seq.annotations and object_id in seq.tracks() else None
    result = track_keyframes(CachedSource(seq), keyframes, start, end, config, params)
    first = min(k for k in keyframes if start <= k <= end)
    path = write_track_result(args.out, seq, result, object_id, keyframes[first], label, offline=True)
    used = sum(1 for k in keyframes if start <= k <= end)
    print(f"tracked {object_id} frames {start}..{end} ({len(result.frames)} frames) through {used} keyframes "
          f"({'soft' if params.anchor_sigma() is not None else 'held exactly'}), shape {len(result.shape)} points")
    print(f"wrote {path} and {path.parent / 'shape.ply'}")
    return 0
