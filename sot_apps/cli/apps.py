"""``sot-apps apps``: the installed apps (entry-point group ``sot_apps.apps``) and their config sections."""

from __future__ import annotations

import argparse
import json

from .common import add_subcommand


def register(subparsers) -> argparse.ArgumentParser:
    parser = add_subcommand(
        subparsers, "apps", help="list the installed apps (pipeline stages after tracking) and their config sections",
        description="List the apps a pipeline file can use as stages: the built-in ones and every installed package "
                    "registering one in the entry-point group 'sot_apps.apps' (docs/pipeline.md). For each: what it "
                    "writes, which apps it runs after, and its config section (stages.<name>) with types and defaults.",
        examples=["sot-apps apps", "sot-apps apps --json"])
    parser.add_argument("--json", action="store_true", help="print JSON instead of text")
    parser.set_defaults(func=run)
    return parser


def run(args: argparse.Namespace) -> int:
    from ..apps import describe, installed_apps
    from ..errors import InputError

    found = installed_apps()
    docs = [describe(app) if not isinstance(app, InputError) else {"name": name, "error": app.problem}
            for name, app in found.items()]
    if args.json:
        print(json.dumps(docs, indent=2))
    else:
        print(format_apps(docs))
    return 1 if any("error" in d for d in docs) else 0


def format_apps(docs: list[dict]) -> str:
    lines = []
    for d in docs:
        if "error" in d:
            lines += [f"{d['name']}: does not load: {d['error']}", ""]
            continue
        default = "runs unless disabled" if d["runs_by_default"] else "runs when the pipeline file has a section"
        needs = f"; after {', '.join(d['needs'])}" if d["needs"] else ""
        lines.append(f"{d['name']}  ({d['module']}; {default}{needs})")
        lines.append(f"  {d['description']}")
        for output in d["outputs"]:
            lines.append(f"  writes {output}")
        lines.append(f"  stages.{d['name']}:")
        for f in d["config"]:
            lines.append(f"    {f['field']:14s} {f['type']:24s} default {json.dumps(f['default'])}")
        lines.append("")
    return "\n".join(lines).rstrip()
