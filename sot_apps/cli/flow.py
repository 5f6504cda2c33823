"""``sot-apps flow``: optical-flow pseudo-ground-truth for tracked objects in camera image pairs."""

from __future__ import annotations

import argparse
import sys

from ..errors import InputError
from .common import add_sequence_argument, add_subcommand, declare_outputs, load_sequence, positive_int


def _pairs(text: str) -> tuple[int, int]:
    try:
        a, b = (int(v) for v in text.split(":"))
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected A:B (pairs k -> k+1 for A <= k < B), got {text!r}") from None
    return a, b


def register(subparsers) -> argparse.ArgumentParser:
    parser = add_subcommand(
        subparsers, "flow", help="optical-flow ground truth of tracked objects (KITTI PNG, .flo, masks)",
        description="Dense (or sparse) optical flow of tracked objects between consecutive images k -> k+1 of one "
                    "camera: shapes are meshed, placed at the state interpolated to each camera timestamp, "
                    "raycast, moved with the object and projected (ego motion and lens distortion included). "
                    "Pixels where the object is not the nearest surface (other objects, LiDAR points) are "
                    "invalid. Output layout: docs/flow.md. Rerunning resumes (finished pairs are skipped).",
        examples=["sot-apps flow ../shared/data/pandaset_002 --from-annotations --track-id 8ac00bad "
                  "--camera front_camera --pairs 0:5 --out out/flow",
                  "sot-apps flow ../shared/data/pandaset_002 --tracks out/tracks/8ac00bad out/tracks/20d13d1d "
                  "--camera front_camera --out out/flow",
                  "sot-apps flow SEQ --from-annotations --moving-only --camera front_camera --mode sparse --out out/flow"])
    add_sequence_argument(parser)
    source = parser.add_mutually_exclusive_group(required=True)
    source.add_argument("--tracks", nargs="+", metavar="TRACK_DIR", help="track directories (track.json + shape.ply)")
    source.add_argument("--from-annotations", action="store_true",
                        help="use ground-truth boxes; shapes from the ground-removed points inside them")
    parser.add_argument("--track-id", nargs="+", metavar="ID", help="with --from-annotations: only these track ids (prefixes)")
    parser.add_argument("--moving-only", action="store_true", help="with --from-annotations: skip objects that do not move (sot_apps.objects.selection)")
    parser.add_argument("--box-time", choices=("points", "frame"), default="points",
                        help="time of a box/track state = median capture time of the LiDAR points inside it (default; "
                             "PandaSet boxes and tracker states fit unmotion-compensated sweeps) or the frame "
                             "timestamp (track.json's timestamp_ns; boxes given at frame time, e.g. sot-apps synth)")
    parser.add_argument("--shape-frames", type=_pairs, metavar="A:B",
                        help="with --from-annotations: sweeps A <= k < B build the shapes (default: pairs +- 10 frames)")
    parser.add_argument("--camera", required=True, metavar="NAME", help="camera name, e.g. front_camera")
    parser.add_argument("--pairs", type=_pairs, metavar="A:B", help="pairs k -> k+1 for A <= k < B (default: all)")
    parser.add_argument("--mode", choices=("dense", "sparse"), default="dense",
                        help="dense: raycast meshes (default); sparse: project shape points with a z-buffer")
    parser.add_argument("--mesh", choices=("hull", "surfel", "auto"), default="hull",
                        help="meshing of shape points (default: convex hull, closed silhouettes)")
    parser.add_argument("--smooth", action="store_true",
                        help="smooth the states with the motion export's CTRV smoother before interpolating "
                             "(removes per-frame box jitter; see docs/flow.md)")
    parser.add_argument("--no-lidar-occlusion", action="store_true", help="ignore LiDAR points as occluders")
    parser.add_argument("--dilate-px", type=positive_int, default=7,
                        help="min-filter size densifying LiDAR depth in pixels (default 7; 1 = no densifying)")
    vis = parser.add_mutually_exclusive_group()
    vis.add_argument("--vis", action="store_true",
                     help="also write vis/ pictures (flow colour wheel PNG, overlay JPEG on the camera image); "
                          "off by default: they cost more than the flow files")
    vis.add_argument("--no-vis", action="store_true", help=argparse.SUPPRESS)   # the default; kept for old scripts
    parser.add_argument("--out", required=True, metavar="OUT", help="output directory (OUT/<camera>/...)")
    parser.add_argument("--quiet", action="store_true", help="no progress bars")
    parser.set_defaults(func=run)
    declare_outputs(parser, dirs=("out",), inputs=("sequence", "tracks"))
    return parser


def run(args: argparse.Namespace) -> int:
    from ..flow.annotate import FlowOptions, annotate_camera
    from ..flow.objects import objects_for_pairs, objects_from_annotations
    from ..flow.scene import OcclusionParams

    if args.track_id and not args.from_annotations:
        raise InputError(None, "--track-id needs --from-annotations (track directories name their object)")
    from ..io.sweep_cache import with_sweep_cache

    # sweeps through the one-time conversion cache ($SOT_APPS_CACHE_DIR=off disables it), as the pipeline reads them
    seq = with_sweep_cache(load_sequence(args))
    if args.camera not in seq.cameras:
        raise InputError(seq.root, f"no camera {args.camera!r}; cameras: {', '.join(seq.cameras) or 'none'}")
    if args.from_annotations:
        if args.shape_frames:
            a, b = args.shape_frames
            if not 0 <= a < b <= len(seq.frames):
                raise InputError(seq.root, f"--shape-frames {a}:{b} is out of range: the sequence has frames "
                                           f"0..{len(seq.frames) - 1} (A:B takes sweeps A <= k < B, A < B)")
            shape_frames = range(a, b)
        else:
            a, b = args.pairs or (0, len(seq.frames) - 1)
            shape_frames = range(max(a - 10, 0), min(b + 11, len(seq.frames)))
        objects = objects_from_annotations(seq, args.track_id, frames=shape_frames, moving_only=args.moving_only,
                                           mesh_method=args.mesh, box_time=args.box_time, progress=not args.quiet)
        source = "annotations"
    else:
        if args.box_time == "points":
            # the states' re-stamping reads the sweeps of the pairs (+- 2 frames) just before the pairs read them
            # again: keep them decoded when they are few (~2.5 MB each)
            a, b = args.pairs or (0, len(seq.frames) - 1)
            seq.cache_size = max(seq.cache_size, min(b - a + 5, 16))
        objects = objects_for_pairs(seq, args.tracks, args.pairs, mesh_method=args.mesh, box_time=args.box_time)
        source = "tracks"
    if not objects:
        raise InputError(seq.root, "no objects to annotate")
    if args.smooth:
        from ..flow.objects import smoothed

        objects = smoothed(objects, source)
    options = FlowOptions(mode=args.mode, occlusion=OcclusionParams(dilate_px=args.dilate_px),
                          use_lidar=not args.no_lidar_occlusion, write_vis=args.vis)
    stats = annotate_camera(seq, args.camera, objects, args.out, args.pairs, options, progress=not args.quiet,
                            source=source)
    pairs = stats["pairs"]
    pixels = sum(p["pixels"] for p in pairs)
    noc = sum(p["pixels_noc"] for p in pairs)
    print(f"{len(pairs)} pairs, {len(objects)} objects, {pixels} object pixels "
          f"({noc} non-occluded) -> {args.out}/{args.camera}", file=sys.stdout)
    for o in stats["objects"][:20]:
        name = o["object_id"] if len(o["object_id"]) <= 16 else o["object_id"][:8]
        print(f"  {name:16s}  pairs {o['pairs']:3d}  pixels {o['pixels']:8d}  mean |flow| "
              f"{o['mean_flow_px']:7.2f} px  occluded {100 * o['occluded_share']:5.1f} %")
    return 0
