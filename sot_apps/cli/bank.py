"""``sot-apps bank build|list``: the vehicle bank used by simulate-lidar."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from ..errors import InputError
from .common import add_action, add_subcommand, declare_outputs, nonnegative_int


def register(subparsers) -> argparse.ArgumentParser:
    parser = add_subcommand(
        subparsers, "bank", help="build or list a vehicle bank (meshes for simulate-lidar)",
        description="Build a vehicle bank from tracker outputs (track.json + shape.ply), from annotated tracks of a "
                    "sequence (points inside the ground-truth boxes, aggregated in the object frame), or from mesh "
                    "files; point sets are meshed with surfel disks oriented by k-NN normals.",
        examples=["sot-apps bank build out/tracks/* --out bank",
                  "sot-apps bank build --from-annotations ../shared/data/pandaset_002 --track-id 20d13d1d --mirror --out bank",
                  "sot-apps bank build --from-annotations ../shared/data/pandaset_002 --all --min-points 2000 --out bank",
                  "sot-apps bank build car.obj --out bank", "sot-apps bank list bank"])
    sub = parser.add_subparsers(dest="bank_command", metavar="ACTION")
    build = add_action(sub, "build", help="add entries to a bank (created if missing)",
                       description="Add entries to BANK (entries with the same id are replaced). A build that adds "
                                   "no entry (every input skipped) is an error (exit code 2).",
                       examples=["sot-apps bank build out/tracks/* --out bank",
                                 "sot-apps bank build --from-annotations ../shared/data/pandaset_002 --track-id 20d13d1d "
                                 "--mirror --out bank"])
    build.add_argument("inputs", nargs="*", metavar="TRACK_DIR_OR_MESH",
                       help="tracker output directories (track.json + shape.ply) or mesh files")
    build.add_argument("--out", required=True, metavar="BANK", help="bank directory")
    build.add_argument("--from-annotations", metavar="SEQUENCE", help="build from annotated tracks of this sequence")
    build.add_argument("--track-id", action="append", default=[], metavar="PREFIX",
                       help="annotated track id (or unique prefix); repeatable")
    build.add_argument("--all", action="store_true", help="every annotated vehicle track (sot_apps.objects.selection; with --from-annotations)")
    build.add_argument("--min-points", type=nonnegative_int, default=200,
                       help="skip annotated tracks with fewer aggregated points (default 200)")
    build.add_argument("--mirror", action="store_true", help="mirror-complete about the length axis (y -> -y)")
    build.set_defaults(func=run_build)
    declare_outputs(build, dirs=("out",), inputs=("inputs", "from_annotations"))
    lst = add_action(sub, "list", help="print the entries of a bank", description="Print the entries of BANK.",
                     examples=["sot-apps bank list bank"])
    lst.add_argument("bank", metavar="BANK")
    lst.set_defaults(func=run_list)
    parser.set_defaults(func=lambda args: (parser.print_help(), 2)[1])
    return parser


def run_build(args: argparse.Namespace) -> int:
    from ..io import open_sequence
    from ..objects.bank import (
        entries_from_annotations,
        entry_from_mesh_file,
        entry_from_track_dir,
        is_track_dir,
        read_bank,
        write_bank_index,
    )
    from ..objects.selection import DEFAULT_SELECTION

    if not args.inputs and not args.from_annotations:
        raise InputError(None, "bank build: give TRACK_DIR/mesh inputs or --from-annotations SEQUENCE")
    if args.from_annotations and not (args.track_id or args.all):
        raise InputError(None, "bank build --from-annotations needs --track-id PREFIX or --all")
    out = Path(args.out)
    bank = read_bank(out, must_exist=False)
    added = []
    for item in args.inputs:
        path = Path(item)
        if path.is_dir():
            if not is_track_dir(path):
                raise InputError(path, "not a track directory (no track.json)")
            added.append(entry_from_track_dir(out, path, mirror=args.mirror))
        elif path.is_file():
            added.append(entry_from_mesh_file(out, path))
        else:
            raise InputError(path, "no such file or directory")
    if args.from_annotations:
        seq = open_sequence(args.from_annotations)
        if args.all:
            ids = DEFAULT_SELECTION.vehicles(seq)
        else:
            ids = [seq.resolve_track_id(p) for p in args.track_id]
        entries, skipped = entries_from_annotations(out, seq, ids, mirror=args.mirror, min_points=args.min_points,
                                                    progress=sys.stderr.isatty())
        added += entries
        for msg in skipped:
            sys.stderr.write(f"skipped {msg}\n")
    if not added:
        raise InputError(out, "bank build: no entry added (every input was skipped; see the lines above); "
                              "nothing written")
    for entry in added:
        bank.upsert(entry)
    write_bank_index(bank)
    for e in added:
        print(f"{e.id}: {e.point_count} points, size {e.size['length']:.2f} x {e.size['width']:.2f} x "
              f"{e.size['height']:.2f} m, quality {e.quality:.2f}, built in {e.build_seconds:.2f} s")
    print(f"bank {out}: {len(bank.entries)} entries ({len(added)} added)")
    return 0


def run_list(args: argparse.Namespace) -> int:
    from ..objects.bank import bank_summary_rows, read_bank

    bank = read_bank(args.bank)
    headers = ["id", "split", "label", "size LxWxH (m)", "points", "quality", "source", "sequence/path", "track"]
    rows = bank_summary_rows(bank)
    widths = [max([len(h)] + [len(r[i]) for r in rows]) for i, h in enumerate(headers)]
    print("  ".join(h.ljust(w) for h, w in zip(headers, widths, strict=True)).rstrip())
    for r in rows:
        print("  ".join(c.ljust(w) for c, w in zip(r, widths, strict=True)).rstrip())
    print(f"{len(rows)} entries")
    return 0
