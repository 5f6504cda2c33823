"""The rule for changing ``full`` (issue 23 item 5), checked on ``sot-apps eval --json`` reports (docs/evaluation.md,
"The rule for changing `full`").

A candidate is compared with a baseline group by group: every (evaluation set, mode, group) both sides hold, a group
being a difficulty or a motion profile of a benchmark list (``sot-apps eval --benchmark ... --json``) or a
difficulty of a sequence's moving tracks (``sot-apps eval SEQ --all-moving ... --json``). A side may be several
reports of one set with disjoint tracker seeds (``--first-seed``): they are pooled into one mean and one spread
(the standard deviation over all their seeds, as ``eval`` prints it for one report). A group is **lost** when the
candidate's mean is below the baseline's by more than the larger of the two spreads.

Each report must hold one preset, or the side names the preset to take (``preset``); rows are matched by mode
(online, ``lag N``, offline), so a candidate preset is compared with another preset (``faithful`` against ``full``).
"""

from __future__ import annotations

import json
import math
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

from ..errors import InputError

__all__ = ["GroupStat", "SetReport", "GroupVerdict", "RuleCheck", "read_report", "pool", "check_rule",
           "format_rule"]


@dataclass(frozen=True)
class GroupStat:
    """One group's Acc (0..1) over ``seeds`` tracker seeds: their mean and standard deviation (None: the report has
    no spread for it), and its tracklet count."""

    mean: float
    std: float | None
    seeds: int
    tracklets: int


@dataclass(frozen=True)
class SetReport:
    """One ``eval --json`` report reduced to what the rule needs: the evaluation set it ran on (``key`` identifies
    it: the list's folder and its tracklets with their groups, or the sequence and its tracks;
    ``label`` names it), its seeds, and per (mode, group) the Acc statistics of the chosen preset."""

    path: str
    key: str
    label: str
    preset: str
    seeds: tuple[int, ...]
    groups: dict[tuple[str, str], GroupStat]


@dataclass(frozen=True)
class GroupVerdict:
    """One group of one set: the baseline's and the candidate's pooled statistics; lost when the candidate is below
    by more than the larger spread."""

    label: str
    mode: str
    group: str
    baseline: GroupStat
    candidate: GroupStat

    @property
    def spread(self) -> float:
        """The larger of the two sides' spreads (0 where neither has one)."""
        return max(self.baseline.std or 0.0, self.candidate.std or 0.0)

    @property
    def has_spread(self) -> bool:
        return self.baseline.std is not None or self.candidate.std is not None

    @property
    def difference(self) -> float:
        return self.candidate.mean - self.baseline.mean

    @property
    def lost(self) -> bool:
        return self.difference < -self.spread - 1e-12


@dataclass(frozen=True)
class RuleCheck:
    """Every group compared, the pooled Acc per mode, each side's seeds and the sets only one side holds."""

    verdicts: tuple[GroupVerdict, ...]
    pooled: dict[str, tuple[float, float]]   # mode -> (baseline, candidate) Acc of the sets' "all" groups,
    #                                          weighted by their tracklets
    baseline_seeds: tuple[int, ...]
    candidate_seeds: tuple[int, ...]
    unmatched: tuple[str, ...]               # sets only one side holds

    @property
    def lost(self) -> list[GroupVerdict]:
        return [v for v in self.verdicts if v.lost]

    @property
    def above(self) -> int:
        return sum(v.difference > 0 for v in self.verdicts)

    @property
    def below(self) -> int:
        return sum(v.difference < 0 for v in self.verdicts)

    def to_dict(self) -> dict:
        """Plain JSON: every group's two sides (Acc mean and spread over the seeds, 0..1), its verdict, the pooled
        Acc per mode and the counts."""
        def side(g: GroupStat) -> dict:
            return {"acc": g.mean, "acc_std": g.std, "seeds": g.seeds, "n": g.tracklets}

        return {"baseline_seeds": list(self.baseline_seeds), "candidate_seeds": list(self.candidate_seeds),
                "groups": [{"set": v.label, "mode": v.mode, "group": v.group, "baseline": side(v.baseline),
                            "candidate": side(v.candidate), "spread": v.spread, "lost": v.lost}
                           for v in self.verdicts],
                "counts": {"groups": len(self.verdicts), "above": self.above, "below": self.below,
                           "lost": len(self.lost)},
                "pooled": {mode: {"baseline": b, "candidate": c} for mode, (b, c) in self.pooled.items()},
                "unmatched": list(self.unmatched)}


def _mode(row_name: str, preset: str) -> str:
    """``full+lag10`` -> ``lag10``; ``full`` -> ``online``."""
    rest = row_name[len(preset):].lstrip("+")
    return rest or "online"


def _label_from_command(data: dict, fallback: str) -> str:
    import shlex

    for command in data.get("provenance", {}).get("commands", []):
        words = shlex.split(command)
        if "--benchmark" in words and words.index("--benchmark") + 1 < len(words):
            return Path(words[words.index("--benchmark") + 1]).parent.name or fallback
    return fallback


def read_report(path: str | Path, preset: str | None = None) -> SetReport:
    """The rule's view of an ``eval --json`` report (a benchmark's or a sequence's)."""
    from ..schemas import load_json

    data = load_json(path)
    if not isinstance(data, dict) or not ("tables" in data or "rows" in data):
        raise InputError(path, "not a `sot-apps eval --json` report (no 'tables' or 'rows')")
    try:
        if "tables" in data:
            return _benchmark_report(str(path), data, preset)
        return _sequence_report(str(path), data, preset)
    except (KeyError, TypeError, ValueError) as exc:
        raise InputError(path, f"not a `sot-apps eval --json` report ({type(exc).__name__}: {exc})") from exc


def _one_preset(path: str, presets: Sequence[str], preset: str | None) -> str:
    if preset is not None:
        if preset not in presets:
            raise InputError(path, f"has no preset {preset!r} (it holds {', '.join(presets)})")
        return preset
    if len(presets) != 1:
        raise InputError(path, f"holds presets {', '.join(presets)}: name the one to compare")
    return presets[0]


def _benchmark_report(path: str, data: dict, preset: str | None) -> SetReport:
    rows = list(data["tables"])
    base_presets = list(dict.fromkeys(r.split("+")[0] for r in rows))
    chosen = _one_preset(path, base_presets, preset)
    seeds = tuple(int(s) for s in data["seeds"])
    groups: dict[tuple[str, str], GroupStat] = {}
    for row, table in data["tables"].items():
        if row.split("+")[0] != chosen:
            continue
        for group, m in table.items():
            std = m.get("acc_std")
            groups[(_mode(row, chosen), group)] = GroupStat(float(m["acc"]), None if std is None else float(std),
                                                            len(seeds), int(m["n"]))
    # a set is its list's folder and its tracklets with their groups (generated lists of several seeds share
    # tracklet ids); the folder from the list's path (`list`, written by eval since 2026-11-28) or the command
    listed = data.get("list")
    if isinstance(listed, dict) and listed.get("source"):
        source = Path(str(listed["source"]))
        label = (source.parent.name if source.suffix == ".json" else source.name) or Path(path).stem
    else:
        label = _label_from_command(data, Path(path).stem)
    key = f"benchmark:{label}:" + json.dumps(data["tracklets"], sort_keys=True)
    return SetReport(path, key, label, chosen, seeds, groups)


def _sequence_report(path: str, data: dict, preset: str | None) -> SetReport:
    rows = data["rows"]
    chosen = _one_preset(path, list(dict.fromkeys(r["preset"] for r in rows)), preset)
    groups: dict[tuple[str, str], GroupStat] = {}
    seeds: tuple[int, ...] = ()
    for r in rows:
        if r["preset"] != chosen:
            continue
        seeds = tuple(int(s) for s in r["seeds"])
        mode = _mode(r["name"], chosen)
        n_all = sum(int(v["n_tracklets"]) for v in r["by_difficulty"].values())
        groups[(mode, "all")] = GroupStat(float(r["pooled"]["acc"]), float(r["pooled_std"]["acc"]), len(seeds),
                                          int(r["pooled"].get("n_tracklets", n_all)))
        spreads = r.get("by_difficulty_std", {})
        for level, v in r["by_difficulty"].items():
            std = spreads.get(level, {}).get("acc")
            groups[(mode, level)] = GroupStat(float(v["acc"]), None if std is None else float(std), len(seeds),
                                              int(v["n_tracklets"]))
    tracks = data.get("tracks") or []
    key = f"sequence:{data.get('sequence')}:" + json.dumps(tracks, sort_keys=True)
    label = Path(str(data.get("sequence") or path)).name
    return SetReport(path, key, label, chosen, seeds, groups)


def pool(stats: Sequence[GroupStat]) -> GroupStat:
    """Several reports' statistics of one group as one: the mean and the standard deviation over all their seeds
    (each report's standard deviation is over its own seeds, ddof 0, as ``eval`` computes it); no spread when a
    report has none."""
    seeds = sum(s.seeds for s in stats)
    mean = sum(s.seeds * s.mean for s in stats) / seeds
    if any(s.std is None for s in stats):
        return GroupStat(mean, None, seeds, stats[0].tracklets)
    second = sum(s.seeds * ((s.std or 0.0) ** 2 + s.mean ** 2) for s in stats) / seeds
    return GroupStat(mean, math.sqrt(max(second - mean ** 2, 0.0)), seeds, stats[0].tracklets)


def _by_set(reports: Sequence[SetReport]) -> dict[str, list[SetReport]]:
    out: dict[str, list[SetReport]] = {}
    for r in reports:
        out.setdefault(r.key, []).append(r)
    for runs in out.values():
        seen: dict[int, str] = {}
        for r in runs:
            for s in r.seeds:
                if s in seen:
                    raise InputError(r.path, f"tracker seed {s} of this set is also in {seen[s]}: a side pools "
                                             "reports of disjoint seeds (sot-apps eval --first-seed)")
                seen[s] = r.path
    return out


def check_rule(baseline: Sequence[SetReport], candidate: Sequence[SetReport]) -> RuleCheck:
    """Every group both sides hold, with each side's reports of a set pooled."""
    base, cand = _by_set(baseline), _by_set(candidate)
    verdicts = []
    pooled_sums: dict[str, list[float]] = {}
    for key in [k for k in base if k in cand]:
        b_runs, c_runs = base[key], cand[key]
        common = [g for g in b_runs[0].groups if all(g in r.groups for r in b_runs + c_runs)]
        for mode, group in common:
            b = pool([r.groups[(mode, group)] for r in b_runs])
            c = pool([r.groups[(mode, group)] for r in c_runs])
            verdicts.append(GroupVerdict(b_runs[0].label, mode, group, b, c))
            if group == "all":
                acc = pooled_sums.setdefault(mode, [0.0, 0.0, 0.0])
                acc[0] += b.tracklets * b.mean
                acc[1] += b.tracklets * c.mean
                acc[2] += b.tracklets
    pooled = {mode: (s[0] / s[2], s[1] / s[2]) for mode, s in pooled_sums.items() if s[2] > 0}
    unmatched = tuple(sorted({runs[0].label for k, runs in base.items() if k not in cand}
                             | {runs[0].label for k, runs in cand.items() if k not in base}))
    return RuleCheck(tuple(verdicts), pooled, _seeds(base), _seeds(cand), unmatched)


def _seeds(side: dict[str, list[SetReport]]) -> tuple[int, ...]:
    return tuple(sorted({s for runs in side.values() for r in runs for s in r.seeds}))


def format_rule(check: RuleCheck, baseline_name: str, candidate_name: str) -> str:
    """The lost groups per set, the counts, and the sets' pooled Acc per mode (percent)."""
    lines = [f"rule: {candidate_name} (seeds {_seed_text(check.candidate_seeds)}) against {baseline_name} "
             f"(seeds {_seed_text(check.baseline_seeds)}); a group is lost when below by more than the larger "
             "spread over the seeds"]
    labels = list(dict.fromkeys(v.label for v in check.verdicts))
    for label in labels:
        lost = [v for v in check.verdicts if v.label == label and v.lost]
        text = "; ".join(f"{v.mode} {v.group} {100 * v.baseline.mean:.1f} -> {100 * v.candidate.mean:.1f} "
                         + (f"(± {100 * v.spread:.1f})" if v.has_spread else "(no spread)") for v in lost)
        lines.append(f"  {label:28s} lost {len(lost):2d}" + (f": {text}" if text else ""))
    n = len(check.verdicts)
    lines.append(f"{n} groups of {len(labels)} sets: above on {check.above}, below on {check.below}, "
                 f"lost on {len(check.lost)} (of {len({v.label for v in check.lost})} sets)")
    for mode, (b, c) in check.pooled.items():
        lines.append(f"  pooled {mode:8s} {100 * b:5.1f} -> {100 * c:5.1f}")
    if check.unmatched:
        lines.append("not compared (one side only): " + ", ".join(check.unmatched))
    return "\n".join(lines)


def _seed_text(seeds: tuple[int, ...]) -> str:
    if seeds and list(seeds) == list(range(seeds[0], seeds[-1] + 1)):
        return f"{seeds[0]}-{seeds[-1]}" if len(seeds) > 1 else str(seeds[0])
    return ",".join(map(str, seeds))
