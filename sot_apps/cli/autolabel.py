"""``sot-apps autolabel``: full vehicle tracks (auto-labels) of a sequence from per-frame detections."""

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
    simulated_detections,
)


def register(subparsers) -> argparse.ArgumentParser:
    parser = add_subcommand(
        subparsers, "autolabel", help="auto-label every vehicle of a sequence from detections (Det+SOT, offline)",
        description="Associate detections into tracks (born at score >= 0.5, confirmed by a second one), start SOT "
                    "(det_sot with re-acquisition) at each track's most reliable detection, track forward and "
                    "backward past its detections in one pass each way over the sweeps for all tracks, cut the "
                    "unsupported ends, merge duplicates, drop unsupported tracks, refine offline, and write "
                    "DIR/sequence (canonical, the labels as its boxes), DIR/kitti/label_02/0000.txt (+ calib; only "
                    "when the sequence has a camera), "
                    "DIR/av2/annotations.feather and DIR/av2/submission.feather (AV2's detection submission form, "
                    "with scores). With "
                    "--evaluate, print the label quality against the sequence's annotations next to the raw "
                    "detections (docs/detection.md). Without --detections the model-free detector runs first. With "
                    "--keyframes FILE the labels are the file's tracks instead, tracked between their keyframes "
                    "(each reproduced exactly; docs/tracker.md, Keyframe-assisted tracks).",
        examples=["sot-apps autolabel ../shared/data/pandaset_002 --detections dets.json --out labels --evaluate",
                  "sot-apps autolabel /tmp/world --simulate learned --out /tmp/world_labels --evaluate",
                  "sot-apps autolabel ../shared/data/pandaset_002 --keyframes keyframes.json --out labels --evaluate"])
    add_sequence_argument(parser)
    add_detections_arguments(parser)
    parser.add_argument("--simulate", metavar="PROFILE", help="instead of --detections: simulated detections")
    parser.add_argument("--seed", type=int, default=0, help="seed of --simulate and of the tracker (default 0)")
    parser.add_argument("--out", required=True, metavar="DIR", help="output directory")
    parser.add_argument("--keyframes", metavar="FILE",
                        help="label the tracks of this keyframe file (keyframes JSON, KITTI label_02 .txt, AV2 "
                             "annotations .feather) between their keyframes instead of detecting")
    parser.add_argument("--keyframe-sigma", metavar="M[,RAD]",
                        help="with --keyframes: soft keyframes (weight 1/sigma^2) instead of held exactly")
    parser.add_argument("--no-offline", action="store_true", help="skip the offline refinement")
    parser.add_argument("--chunk", type=int, metavar="N", help="track N objects per pass over the sweeps "
                        "(bounds memory; the labels do not depend on it; default all)")
    parser.add_argument("--no-sequence", action="store_true", help="do not write the canonical sequence copy")
    parser.add_argument("--evaluate", action="store_true", help="print label quality against the annotations")
    parser.add_argument("--json", metavar="FILE", help="with --evaluate: write the quality rows as JSON")
    parser.add_argument("--quiet", action="store_true", help="no progress bars")
    declare_outputs(parser, files=("json",), dirs=("out",), inputs=("sequence", "detections", "kitti_calib", "keyframes"))
    parser.set_defaults(func=run)
    return parser


def run(args: argparse.Namespace) -> int:
    from tqdm import tqdm

    from tracker import get_preset

    from ..detection.autolabel import LabelConfig, autolabel, write_autolabels
    from ..io.atomic import write_json
    from ..io.cached_source import CachedSource
    from ..objects.selection import DEFAULT_SELECTION

    sequence = load_sequence(args)
    if args.chunk is not None and args.chunk < 1:
        raise InputError(None, f"--chunk: expected a positive number of objects, got {args.chunk}")

    def progress(items, desc="autolabel"):
        return items if args.quiet else tqdm(items, desc=desc, file=sys.stderr, leave=False)

    if args.keyframes is not None:
        return _run_keyframes(args, sequence, progress)
    if args.keyframe_sigma is not None:
        raise InputError(None, "--keyframe-sigma needs --keyframes FILE")
    detections = load_detections(args, sequence)
    if detections is None and args.simulate:
        detections = simulated_detections(sequence, args.simulate, args.seed)
    elif detections is None:
        from ..detection.detector import detect_sequence

        detections = detect_sequence(sequence, progress=lambda f: progress(f, "detect"))
    labels, det_tracks = autolabel(CachedSource(sequence), detections, get_preset("det_sot", seed=args.seed),
                                   offline=not args.no_offline, progress=progress,
                                   label_config=LabelConfig(chunk=args.chunk))
    written = write_autolabels(args.out, sequence, labels, with_sequence=not args.no_sequence)
    print(f"{len(labels)} labelled tracks ({sum(len(lbl.boxes) for lbl in labels)} boxes) from "
          f"{sum(len(d) for d in detections.values())} detections")
    for line in written:
        print(line)
    if args.evaluate:
        from ..detection.autolabel import labels_as_detections, tracks_as_detections
        from ..evaluation.detection import autolabel_quality, format_quality_table, ground_truth_frames, rows_for_json

        if not sequence.annotations:
            raise InputError(sequence.root, "--evaluate needs annotations")
        truth = ground_truth_frames(sequence, DEFAULT_SELECTION.vehicle_labels(sequence))
        rows = autolabel_quality(
            {"raw detections": (detections, None),
             "detection tracks (CV Kalman)": (tracks_as_detections(det_tracks),
                                              {t.object_id: dict(zip(t.frames.tolist(), t.boxes, strict=True))
                                               for t in det_tracks}),
             "auto-labels": (labels_as_detections(labels),
                             {lbl.track_id: {k: b.to_array() for k, b in lbl.boxes.items()} for lbl in labels})},
            truth, moving=DEFAULT_SELECTION.moving_vehicles(sequence))
        print(format_quality_table(rows))
        if args.json:
            write_json(args.json, rows_for_json(rows))
    return 0



def _run_keyframes(args: argparse.Namespace, sequence, progress) -> int:
    """Labels from a keyframe file: each of its tracks over its first..last keyframe (tracker.keyframes)."""
    import numpy as np

    from tracker import get_preset, track_keyframes

    from ..detection.autolabel import AutoLabel, labels_as_detections, write_autolabels
    from ..io.atomic import write_json
    from ..io.cached_source import CachedSource
    from ..io.keyframes import read_keyframes
    from ..io.object_track import ObjectTrack
    from .track import keyframe_params

    if args.detections or args.simulate:
        raise InputError(None, "--keyframes labels the keyframe file's tracks: drop --detections / --simulate")
    params = keyframe_params(args.keyframe_sigma)
    tracks = read_keyframes(args.keyframes, sequence, args.kitti_calib)
    source, config = CachedSource(sequence), get_preset("full", seed=args.seed)
    labels = []
    for track_id, keyframes in progress(list(tracks.items()), "keyframe tracks"):
        result = track_keyframes(source, keyframes, config=config, params=params)
        frames = sorted(keyframes)
        given = ObjectTrack(track_id, "", frames, [keyframes[k].to_array() for k in frames], scores=[1.0] * len(frames))
        labels.append(AutoLabel.of(track_id, {e.frame: e.box for e in result.estimates}, 1.0, result.shape, given))
    for line in write_autolabels(args.out, sequence, labels, with_sequence=not args.no_sequence):
        print(line)
    print(f"{len(labels)} labelled tracks ({sum(len(lbl.boxes) for lbl in labels)} boxes) from "
          f"{sum(len(k) for k in tracks.values())} keyframes")
    if args.evaluate:
        from ..evaluation.detection import autolabel_quality, format_quality_table, ground_truth_frames, rows_for_json
        from ..objects.selection import DEFAULT_SELECTION

        if not sequence.annotations:
            raise InputError(sequence.root, "--evaluate needs annotations")
        truth = ground_truth_frames(sequence, DEFAULT_SELECTION.vehicle_labels(sequence))
        rows = autolabel_quality({"keyframe tracks": (labels_as_detections(labels), {
            lbl.track_id: {k: np.asarray(b.to_array()) for k, b in lbl.boxes.items()} for lbl in labels})}, truth)
        print(format_quality_table(rows))
        if args.json:
            write_json(args.json, rows_for_json(rows))
    return 0
