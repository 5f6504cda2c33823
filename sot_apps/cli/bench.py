"""``sot-apps bench NAME ...``: benchmarks registered by the modules of ``sot_apps.bench``."""

from __future__ import annotations

import argparse
import sys

from .common import add_subcommand, declare_outputs


def register(subparsers) -> argparse.ArgumentParser:
    parser = add_subcommand(subparsers, "bench", help="speed/accuracy benchmarks that print tables",
                            description="Benchmarks that print tables (README figures quote them). Each is a module "
                                        "of sot_apps/bench with register(registry); see `sot-apps bench BENCHMARK "
                                        "--help`.",
                            examples=["sot-apps bench tracker ../shared/data/pandaset_002",
                                      "sot-apps bench tracker ../shared/data/pandaset_002 --preset full faithful"])
    from ..bench import discover  # here: `sot-apps --help` lists the commands without importing the benchmarks

    registry = discover()
    broken = "\n".join(f"  {m}: {e}" for m, e in registry.errors.items())
    if broken:
        parser.description += f"\n\nNot available (import failed):\n{broken}"
    sub = parser.add_subparsers(dest="benchmark", metavar="BENCHMARK", parser_class=type(parser))
    for bench in registry.benchmarks.values():
        child = sub.add_parser(bench.name, help=bench.help, description=bench.description or bench.help,
                               formatter_class=argparse.RawDescriptionHelpFormatter)
        bench.add_arguments(child)
        child.set_defaults(bench_run=bench.run)
        # checked before the benchmark runs; a module names its input options in the default `bench_inputs`
        declare_outputs(child, files=("json", "plot"), inputs=("sequence", *(child.get_default("bench_inputs") or ())))
    parser.set_defaults(func=lambda args: _run(args, parser, registry.errors))
    return parser


def _run(args: argparse.Namespace, parser: argparse.ArgumentParser, errors: dict[str, str]) -> int:
    run = getattr(args, "bench_run", None)
    if run is None:
        parser.print_help()
        for module, error in errors.items():
            sys.stderr.write(f"warning: benchmark module {module} failed to import: {error}\n")
        return 2
    return int(run(args) or 0)
