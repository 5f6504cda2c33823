"""``sot-apps bench reference``: our tracker against reference boxes (e.g. the authors' implementation), frame by
frame; the comparison itself is :mod:`sot_apps.evaluation.reference`.

For every track that both the reference and the sequence hold, a preset tracks from the ground-truth start box
over the track's annotated span (up to the reference's last frame) and the run is compared with the reference.
"""

from __future__ import annotations

import argparse
from typing import TYPE_CHECKING, Any, Sequence

if TYPE_CHECKING:   # imported by `sot-apps bench --help` (module discovery): the libraries load when a run starts
    import numpy as np

    from tracker import Box

    from ..evaluation.reference import ReferenceComparison

__all__ = ["compare_with_reference", "register"]


def compare_with_reference(source, track_id: str, gt_boxes: Sequence[Box], frames: Sequence[int],
                           reference: dict[int, np.ndarray], preset: str = "faithful", seed: int = 0,
                           overrides: dict[str, Any] | None = None) -> ReferenceComparison:
    """Track ``track_id`` with ``preset`` (dotted paths replaced by ``overrides``) from ``gt_boxes[0]`` over
    ``frames`` and compare with ``reference`` on the frames the reference holds."""
    from tracker import get_preset, track

    from ..evaluation.reference import compare_boxes

    config = get_preset(preset, seed=seed, **(overrides or {}))
    result = track(source, gt_boxes[0], frames[0], frames[-1], config)
    return compare_boxes(track_id, frames, result.boxes, gt_boxes, reference)


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("sequence", metavar="SEQUENCE", help="annotated sequence (e.g. ../shared/data/pandaset_002)")
    parser.add_argument("reference", metavar="REFERENCE",
                        help="reference boxes, JSON {track prefix: {frame: [x, y, z, heading, l, w, h]}} "
                             "(e.g. ../shared/data/upstream_lidar_sot/full_seed0.json)")
    parser.add_argument("--preset", default="faithful", help="tracker preset (default: faithful)")
    parser.add_argument("--seed", type=int, default=0, help="tracker seed (default 0)")
    parser.add_argument("--tracks", default=None, metavar="ID,...",
                        help="comma-separated prefixes (default: all in the reference)")
    parser.add_argument("--frames", action="store_true", help="print per-frame rows")
    parser.add_argument("--set", dest="overrides", nargs="+", action="extend", default=[], metavar="PATH=VALUE",
                        help="replace tracker settings (dotted TrackerConfig paths, e.g. motion.alpha=0.6)")


def run(args: argparse.Namespace) -> int:
    from ..errors import InputError
    from ..evaluation.reference import format_comparison, load_reference
    from ..io import open_sequence
    from ..io.cached_source import CachedSource
    from ..objects.selection import annotated_span
    from .sequence_eval import checked_overrides, resolve_presets

    overrides = checked_overrides(args.overrides, resolve_presets([args.preset]))
    sequence = open_sequence(args.sequence)
    reference = load_reference(args.reference)
    source = CachedSource(sequence)
    tracks = sequence.tracks()
    rows = []
    for prefix in (args.tracks.split(",") if args.tracks else reference):
        tid = sequence.resolve_track_id(prefix)
        ref = next((v for k, v in reference.items() if tid.startswith(k)), None)
        if ref is None:
            raise InputError(args.reference, f"no reference boxes for track {tid}")
        start, end = annotated_span(tracks[tid].frames)
        frames = list(range(start, min(end, max(ref)) + 1))
        rows.append(compare_with_reference(source, prefix, [tracks[tid].box_at(k) for k in frames], frames, ref,
                                           args.preset, args.seed, overrides))
    print(format_comparison(rows, args.frames))
    return 0


def register(registry) -> None:
    """Hook for the ``sot-apps bench`` registry (sot_apps/cli/bench.py)."""
    from . import module_docstring

    registry.add("reference", help="our tracker against reference boxes frame by frame (e.g. the authors' runs)",
                 add_arguments=add_arguments, run=run, description=module_docstring("sot_apps.bench.reference"))
