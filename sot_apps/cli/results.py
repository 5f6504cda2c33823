"""``sot-apps results``: docs/results.md generated from saved result JSON (:mod:`sot_apps.report.results`)."""

from __future__ import annotations

import argparse

from .common import add_subcommand, declare_outputs


def register(subparsers) -> argparse.ArgumentParser:
    parser = add_subcommand(
        subparsers, "results", help="generate the results page (docs/results.md) from saved result JSON",
        description="Render every result JSON file of DIR (what `sot-apps eval ... --json` and `sot-apps bench ... "
                    "--json` wrote, each with a provenance record: commands, date, machine) as one Markdown page, a "
                    "section per file, stamped with its commands, machine and date. --stamp adds the provenance "
                    "record (this machine) to the JSON of a command that does not write one.",
        examples=["sot-apps results results --out docs/results.md",
                  "sot-apps results --stamp results/raycast.json --command \"sot-apps bench raycast --bank bank "
                  "--json results/raycast.json\""])
    parser.add_argument("directory", metavar="DIR", nargs="?", help="directory of result JSON files")
    parser.add_argument("--out", metavar="FILE", help="write the page here (atomically; default: print it)")
    parser.add_argument("--stamp", metavar="FILE", help="instead: add a provenance record to this result JSON")
    parser.add_argument("--command", dest="commands", action="append", default=[], metavar="CMD",
                        help="with --stamp: a command that made the file (repeatable, in order)")
    parser.add_argument("--date", help="with --stamp: when it was made (ISO 8601 UTC; default: now)")
    parser.add_argument("--note", default="", help="with --stamp: a remark printed with the file's stamp")
    parser.add_argument("--title", default="", help="with --stamp: the file's section title (default: its name)")
    parser.set_defaults(func=run)
    declare_outputs(parser, files=("out",), inputs=("directory",))
    return parser


def run(args: argparse.Namespace) -> int:
    from ..errors import InputError
    from ..report.results import read_results, render_results, stamp

    if args.stamp:
        if args.directory or args.out:
            raise InputError(None, "--stamp FILE changes one file: give no DIR and no --out")
        stamp(args.stamp, args.commands, args.date, args.note, args.title)
        print(f"stamped {args.stamp}")
        return 0
    if not args.directory:
        raise InputError(None, "results: give DIR (or --stamp FILE)")
    page = render_results(read_results(args.directory), args.directory.rstrip("/"), args.out or "FILE")
    if args.out:
        from ..io.atomic import write_text

        write_text(args.out, page)
        print(f"wrote {args.out}")
    else:
        print(page, end="")
    return 0
