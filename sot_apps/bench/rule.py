"""``sot-apps bench rule``: the rule for changing ``full`` checked on ``sot-apps eval --json`` reports.

Give the baseline's reports and the candidate's (one per evaluation set and seed range; several reports of a set
with disjoint ``--first-seed`` ranges are pooled), and it prints, per set, the groups where the candidate is below
the baseline by more than the larger spread over the seeds, the counts, and the pooled Acc per mode. The comparison
itself is :mod:`sot_apps.evaluation.rule` (docs/evaluation.md, "The rule for changing `full`"); what a count of lost
groups means: docs/tracker-decisions.md, "The rule's noise floor".
"""

from __future__ import annotations

import argparse

__all__ = ["register"]


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--baseline", nargs="+", required=True, metavar="REPORT",
                        help="the baseline's `sot-apps eval --json` reports")
    parser.add_argument("--candidate", nargs="+", required=True, metavar="REPORT",
                        help="the candidate's reports (the same sets)")
    parser.add_argument("--baseline-preset", default=None, metavar="NAME",
                        help="the baseline's preset where a report holds several (e.g. faithful)")
    parser.add_argument("--candidate-preset", default=None, metavar="NAME",
                        help="the candidate's preset where a report holds several")
    parser.add_argument("--json", metavar="FILE", help="also write every group's comparison as JSON (atomically)")
    parser.set_defaults(bench_inputs=("baseline", "candidate"))   # --json never overwrites a report


def run(args: argparse.Namespace) -> int:
    from ..errors import InputError
    from ..evaluation.rule import check_rule, format_rule, read_report

    baseline = [read_report(p, args.baseline_preset) for p in args.baseline]
    candidate = [read_report(p, args.candidate_preset) for p in args.candidate]
    check = check_rule(baseline, candidate)
    if not check.verdicts:
        raise InputError(args.candidate[0], "no evaluation set is in both the baseline's and the candidate's reports")
    names = [sorted({r.preset for r in side}) for side in (baseline, candidate)]
    print(format_rule(check, "/".join(names[0]), "/".join(names[1])))
    if args.json:
        from ..io.atomic import write_json
        from ..provenance import invoked_command, provenance_record

        write_json(args.json, check.to_dict() | {"provenance": provenance_record([invoked_command()])})
    return 0


def register(registry) -> None:
    """Hook for the ``sot-apps bench`` registry (sot_apps/cli/bench.py)."""
    from . import module_docstring

    registry.add("rule", help="the rule for changing full: a candidate's eval reports against a baseline's, group by "
                              "group over the pooled seeds", add_arguments=add_arguments, run=run,
                 description=module_docstring("sot_apps.bench.rule"))
