"""``sot-apps motion-export``: smoothed object motion to MCAP (Foxglove) and forecasting tables."""

from __future__ import annotations

import argparse
import dataclasses
import sys

from .common import add_sequence_argument, add_subcommand, declare_outputs, load_sequence, nonnegative_int


def register(subparsers) -> argparse.ArgumentParser:
    parser = add_subcommand(
        subparsers, "motion-export",
        help="export smoothed object motion (MCAP for Foxglove, AV2 parquet, Waymo-style npz, CSV)",
        description="Smooth per-frame object states (RTS smoother on a constant-turn-rate-and-velocity model), "
                    "derive velocity, speed, acceleration and yaw rate with uncertainties, and write an MCAP file "
                    "that Foxglove opens directly plus optional forecasting tables. Frames the tracker flagged as not "
                    "measured (no_points, prior_only) are exported as invalid, never interpolated. "
                    "See docs/motion-export.md.",
        examples=[
            "sot-apps motion-export ../shared/data/pandaset_002 --tracks out/tracks/8ac00bad out/tracks/20d13d1d --out motion.mcap --parquet motion.parquet",
            "sot-apps motion-export ../shared/data/pandaset_002 --from-annotations --track-id 8ac00bad --out gt.mcap --npz gt.npz --csv gt.csv",
            "sot-apps motion-export ../shared/data/pandaset_002 --from-annotations --with-points --out scene.mcap",
        ])
    add_sequence_argument(parser)
    source = parser.add_mutually_exclusive_group(required=True)
    source.add_argument("--tracks", nargs="+", metavar="TRACK_DIR", help="track directories (track.json + shape.ply) "
                        "written by `sot-apps track`")
    source.add_argument("--from-annotations", action="store_true", help="use the sequence's ground-truth boxes")
    parser.add_argument("--track-id", nargs="+", metavar="ID", default=None,
                        help="with --from-annotations: only these annotated tracks (unique id prefixes); default all")
    parser.add_argument("--out", required=True, metavar="FILE.mcap", help="MCAP file to write")
    parser.add_argument("--with-points", action="store_true",
                        help="also write the LiDAR sweeps (/lidar/points) and, with --from-annotations, object shapes "
                             "aggregated from the points inside the boxes (/objects/<id>/shape)")
    parser.add_argument("--parquet", metavar="FILE", help="Argoverse-2-style parquet (all objects in one file)")
    parser.add_argument("--npz", metavar="FILE", help="dense Waymo-motion-style npz (objects x timesteps)")
    parser.add_argument("--csv", metavar="FILE", help="CSV for quick looks (one row per object and frame)")
    parser.add_argument("--invalid-flags", nargs="+", default=None, metavar="FLAG",
                        help="tracker flags that make a frame invalid (default: no_points prior_only lost no_sweep "
                             "bridged); the start frame is always valid")
    parser.add_argument("--focal-track", metavar="ID", default=None,
                        help="AV2 focal track (id or prefix; default: the first exported object)")
    parser.add_argument("--observed-steps", type=nonnegative_int, default=None, metavar="N",
                        help="AV2 'observed' = valid and timestep < N (default: every valid timestep is observed)")
    parser.add_argument("--quiet", action="store_true", help="no progress bar")
    parser.set_defaults(func=run)
    declare_outputs(parser, files=("out", "parquet", "npz", "csv"), inputs=("sequence", "tracks"))
    return parser


def run(args: argparse.Namespace) -> int:
    from ..errors import InputError
    from ..motion_export.export import export_motion
    from ..motion_export.sources import (
        DEFAULT_INVALID_FLAGS,
        aggregate_shape,
        tracks_from_annotations,
        tracks_from_dirs,
    )

    if args.track_id and not args.from_annotations:
        raise InputError(None, "--track-id selects annotated tracks and needs --from-annotations")
    if args.invalid_flags is not None:
        from ..io.tracks import TRACKER_FLAGS

        unknown = sorted(set(args.invalid_flags) - TRACKER_FLAGS)
        if unknown:
            raise InputError(None, f"--invalid-flags: unknown flag {', '.join(map(repr, unknown))}; tracker flags: "
                                   f"{', '.join(sorted(TRACKER_FLAGS))}")
    if args.observed_steps is not None and args.observed_steps < 0:
        raise InputError(None, "--observed-steps must be >= 0")
    sequence = load_sequence(args)
    if args.from_annotations:
        tracks = tracks_from_annotations(sequence, args.track_id)
        source = "annotations"
        if args.with_points:
            tracks = [dataclasses.replace(t, shape_points=aggregate_shape(sequence, t)) for t in tracks]
    else:
        invalid_flags = DEFAULT_INVALID_FLAGS if args.invalid_flags is None else args.invalid_flags
        tracks = tracks_from_dirs(args.tracks, sequence, invalid_flags=invalid_flags)
        source = "tracks"
    focal = None
    if args.focal_track:
        matches = [t.object_id for t in tracks if t.object_id.startswith(args.focal_track)]
        if len(matches) != 1:
            raise InputError(None, f"--focal-track {args.focal_track!r} matches {len(matches)} exported objects")
        focal = matches[0]
    result = export_motion(sequence, tracks, args.out, parquet=args.parquet, npz=args.npz, csv=args.csv,
                           with_points=args.with_points, source=source, focal_track_id=focal,
                           observed_steps=args.observed_steps, progress=not args.quiet)
    invalid = sum(int((~k.valid).sum()) for k in result.kinematics)
    total = sum(len(k) for k in result.kinematics)
    summary = result.mcap
    print(f"{len(tracks)} objects, {summary.frames} frames, {total} samples ({invalid} invalid); "
          f"{summary.messages} MCAP messages")
    if source == "tracks":   # how each track's states were made (track.json; also in the MCAP metadata)
        modes: dict[str, int] = {}
        for t in tracks:
            mode = str((t.config or {}).get("tracker", {}).get("mode", "online"))
            modes[mode] = modes.get(mode, 0) + 1
        print("tracker states: " + ", ".join(f"{n} {mode}" for mode, n in sorted(modes.items())))
    for kind, path in result.outputs.items():
        print(f"wrote {kind}: {path}")
    sys.stdout.flush()
    return 0
