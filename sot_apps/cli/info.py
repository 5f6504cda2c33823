"""``sot-apps info``: what is in a sequence (frames, timing, points, cameras, annotated tracks)."""

from __future__ import annotations

import argparse
import json
import sys
from typing import TYPE_CHECKING

from ..errors import InputError
from ..io import FORMATS
from ..objects.selection import DEFAULT_SELECTION
from .common import add_subcommand

if TYPE_CHECKING:
    from ..summary import SequenceSummary


def register(subparsers) -> argparse.ArgumentParser:
    parser = add_subcommand(
        subparsers, "info", help="summarise a sequence: frames, points, cameras, annotated tracks",
        description="Summarise a sequence: frames, time span, points per frame, cameras (timing offset to the "
                    "lidar), and annotated tracks with mean points in the box over their first 10 frames, "
                    f"displacement and motion (moving = the box centre gets >= {DEFAULT_SELECTION.min_displacement_m:g} m from "
                    "its first position, or a short track moves >= 0.3 m at >= 1 m/s; see docs/data-formats.md).",
        examples=["sot-apps info --tiny", "sot-apps info ../shared/data/pandaset_002 --vehicles-only",
                  "sot-apps info out/pandaset_002 --json > info.json"])
    parser.add_argument("sequence", metavar="SEQUENCE", nargs="?", help="sequence: canonical or PandaSet directory, Waymo v1 .tfrecord or v2 directory/component .parquet, Argoverse 2 log, nuScenes root (DIR#scene), KITTI tracking (label_02/SSSS.txt or DIR#SSSS), KITTI object / View-of-Delft folder")
    parser.add_argument("--format", choices=FORMATS, default=None, help="force the reader (default: auto-detect)")
    parser.add_argument("--tiny", action="store_true",
                        help="use the built-in tiny synthetic sequence (generated into ~/.cache/sot-apps)")
    parser.add_argument("--json", action="store_true", help="print JSON instead of tables")
    parser.add_argument("--vehicles-only", action="store_true", help="list only vehicle tracks")
    parser.add_argument("--no-point-stats", action="store_true",
                        help="skip points per frame (which reads every sweep)")
    parser.set_defaults(func=run)
    return parser


def run(args: argparse.Namespace) -> int:
    from ..io import open_sequence
    from ..summary import summarize_sequence

    if args.tiny == bool(args.sequence):
        raise InputError(None, "info: give either a SEQUENCE directory or --tiny")
    if args.tiny:
        from ..io.tiny import tiny_sequence_dir

        path = tiny_sequence_dir()
        sys.stderr.write(f"tiny sequence: {path}\n")
    else:
        path = args.sequence
    seq = open_sequence(path, format=args.format)
    summary = summarize_sequence(seq, point_stats=not args.no_point_stats, vehicles_only=args.vehicles_only,
                                 progress=sys.stderr.isatty())
    if args.json:
        print(json.dumps(summary.to_json(), indent=1))
    else:
        print(format_summary(summary))
    return 0


def _table(headers: list[str], rows: list[list[str]], right: set[int]) -> list[str]:
    widths = [max(len(h), *(len(r[i]) for r in rows)) if rows else len(h) for i, h in enumerate(headers)]
    def line(cells: list[str]) -> str:
        return "  ".join(c.rjust(w) if i in right else c.ljust(w)
                         for i, (c, w) in enumerate(zip(cells, widths, strict=True))).rstrip()
    return [line(headers)] + [line(r) for r in rows]


def _frame_list(frames: list[int]) -> str:
    """``[3, 4, 5, 9]`` -> ``"3-5, 9"`` (``"none"`` when empty)."""
    if not frames:
        return "none"
    runs: list[list[int]] = []
    for k in frames:
        if runs and k == runs[-1][1] + 1:
            runs[-1][1] = k
        else:
            runs.append([k, k])
    return ", ".join(str(a) if a == b else f"{a}-{b}" for a, b in runs)


def format_summary(s: SequenceSummary) -> str:
    out = [f"sequence  {s.id}  ({s.format}: {s.root})",
           f"frames    {s.num_frames}, time span {s.time_span_s:.3f} s ({s.rate_hz:.2f} Hz)"]
    if s.points_min is not None:
        out.append(f"points    per frame: min {s.points_min}, median {s.points_median:.0f}, max {s.points_max}")
        if s.points_max == 0:
            out.append("          no points in any frame: the source holds no lidar data (e.g. a Waymo file without "
                       "range images)")
    out.append(f"sweeps    {s.num_frames - len(s.missing_sweeps)} of {s.num_frames} frames; missing: "
               f"{_frame_list(s.missing_sweeps)}" + ("" if s.empty_sweeps is None else f"; empty: {_frame_list(s.empty_sweeps)}"))
    if s.cameras:
        out += ["", "cameras"]
        out += ["  " + r for r in _table(
            ["name", "size", "frames", "offset to lidar (ms)"],
            [[c.name, f"{c.width}x{c.height}", str(c.num_frames), f"{c.mean_offset_to_lidar_ms:+.1f}"] for c in s.cameras],
            right={2, 3})]
    moving = [t for t in s.tracks if t.moving]
    out += ["", f"annotated tracks: {len(s.tracks)} ({sum(t.vehicle for t in s.tracks)} vehicles, "
                f"{sum(t.vehicle for t in moving)} moving vehicles)"]
    if s.tracks:
        out += ["  " + r for r in _table(
            ["id", "class", "frames", "pts(10)", "disp(m)", "motion"],
            [[t.track_id[:8], t.label, str(t.num_frames), f"{t.mean_points_first10:.0f}", f"{t.displacement_m:.1f}",
              t.motion] for t in s.tracks],
            right={2, 3, 4})]
        out.append("  pts(10): mean points in the GT box over the track's first 10 frames; "
                   "disp: first to last box centre")
    return "\n".join(out)
