"""``sot-apps bench rule`` (sot_apps/evaluation/rule.py): a candidate's eval reports against a baseline's, group by
group, each side's reports of a set with disjoint tracker seeds pooled."""

from __future__ import annotations

import json

import numpy as np
import pytest

from sot_apps.cli.main import main
from sot_apps.errors import InputError
from sot_apps.evaluation.rule import GroupStat, check_rule, pool, read_report


def test_pooled_reports_give_the_mean_and_spread_of_all_their_seeds():
    """Three reports of 3, 2 and 1 seeds pooled: the mean and the standard deviation (ddof 0, as eval prints it) of
    the six values, whatever they are."""
    rng = np.random.default_rng(0)
    values = rng.uniform(0.3, 0.9, 6)
    parts = [values[:3], values[3:5], values[5:]]
    pooled = pool([GroupStat(float(p.mean()), float(p.std()), len(p), 4) for p in parts])
    assert pooled.mean == pytest.approx(values.mean(), abs=1e-12)
    assert pooled.std == pytest.approx(values.std(), abs=1e-12)
    assert pooled.seeds == 6 and pooled.tracklets == 4
    assert pool([GroupStat(0.5, None, 3, 2), GroupStat(0.7, 0.1, 3, 2)]).std is None   # a report without spread


def _report(path, seeds: list[int], groups: dict[str, list[float]], preset: str = "full", folder: str = "set_a"):
    """An eval --benchmark --json report of ``preset`` online and offline, each group's Acc per seed given (the
    offline row 0.1 above)."""
    tables = {}
    for row, shift in ((preset, 0.0), (preset + "+offline", 0.1)):
        tables[row] = {g: {"acc": float(np.mean(v) + shift), "acc_std": float(np.std(v)), "n": 2}
                       for g, v in groups.items()}
    data = {"presets": [preset, preset + "+offline"], "seeds": seeds, "tables": tables,
            "tracklets": {"s/ins_c00_00": {"difficulty": "easy", "profile": "turn"}},
            "provenance": {"commands": [f"sot-apps eval --benchmark /x/{folder}/benchmark.json --preset {preset}"]}}
    path.write_text(json.dumps(data))
    return path


def test_a_group_is_lost_only_when_below_by_more_than_the_larger_spread(tmp_path):
    base = _report(tmp_path / "a.json", [0, 1, 2], {"all": [0.80, 0.82, 0.84], "profile turn": [0.70, 0.70, 0.70]})
    # all: 0.81 against 0.82, within the larger spread (0.016); turn: 0.66 against 0.70, beyond its spread (0.008)
    cand = _report(tmp_path / "b.json", [0, 1, 2], {"all": [0.80, 0.81, 0.82], "profile turn": [0.65, 0.66, 0.67]})
    check = check_rule([read_report(base)], [read_report(cand)])
    lost = {(v.mode, v.group) for v in check.lost}
    assert lost == {("online", "profile turn"), ("offline", "profile turn")}
    assert len(check.verdicts) == 4 and check.unmatched == ()
    assert check.pooled["online"] == pytest.approx((0.82, 0.81))
    assert check.pooled["offline"] == pytest.approx((0.92, 0.91))


def test_reports_with_overlapping_seeds_are_refused_and_other_sets_are_not_compared(tmp_path):
    a = _report(tmp_path / "a.json", [0, 1, 2], {"all": [0.8, 0.8, 0.8]})
    a2 = _report(tmp_path / "a2.json", [2, 3], {"all": [0.8, 0.8]})
    with pytest.raises(InputError, match="seed 2"):
        check_rule([read_report(a), read_report(a2)], [read_report(a)])
    other = _report(tmp_path / "c.json", [0], {"all": [0.5]}, folder="set_b")
    check = check_rule([read_report(a)], [read_report(a), read_report(other)])
    assert check.unmatched == ("set_b",) and {v.label for v in check.verdicts} == {"set_a"}


def test_a_report_of_two_presets_needs_the_one_to_compare(tmp_path):
    path = _report(tmp_path / "a.json", [0], {"all": [0.8]})
    data = json.loads(path.read_text())
    data["tables"]["faithful"] = {"all": {"acc": 0.7, "acc_std": 0.0, "n": 2}}
    path.write_text(json.dumps(data))
    with pytest.raises(InputError, match="name the one"):
        read_report(path)
    faithful = read_report(path, "faithful")
    assert faithful.groups == {("online", "all"): GroupStat(0.7, 0.0, 1, 2)}   # rows matched by mode, not name
    check = check_rule([faithful], [read_report(path, "full")])
    assert check.pooled["online"] == pytest.approx((0.7, 0.8))
    assert main(["bench", "rule", "--baseline", str(path), "--candidate", str(path)]) == 2
    assert main(["bench", "rule", "--baseline", str(tmp_path / "missing.json"), "--candidate", str(path)]) == 2


def test_two_one_seed_evals_pool_to_the_two_seed_eval(small_benchmark, tmp_path, capsys):
    """The real pipeline: `eval --seeds 1 --first-seed 0` and `--first-seed 1` pooled by the rule equal `eval --seeds
    2` group by group (mean and spread), and against it nothing is lost."""
    listing = str(small_benchmark / "benchmark.json")
    out = {}
    for name, extra in (("s0", ["--seeds", "1"]), ("s1", ["--seeds", "1", "--first-seed", "1"]),
                        ("both", ["--seeds", "2"])):
        out[name] = tmp_path / f"{name}.json"
        assert main(["eval", "--benchmark", listing, "--first", "3", "--preset", "full", "--offline",
                     *extra, "--json", str(out[name])]) == 0
    assert json.loads(out["s1"].read_text())["seeds"] == [1]
    pair = [read_report(out["s0"]), read_report(out["s1"])]
    both = read_report(out["both"])
    check = check_rule(pair, [both])
    assert len(check.verdicts) == len(both.groups) and not check.lost
    for v in check.verdicts:
        assert v.baseline.mean == pytest.approx(v.candidate.mean, abs=1e-9)
        assert v.baseline.std == pytest.approx(v.candidate.std, abs=1e-9)
    capsys.readouterr()
    result = tmp_path / "rule.json"
    assert main(["bench", "rule", "--baseline", str(out["s0"]), str(out["s1"]), "--candidate", str(out["both"]),
                 "--json", str(result)]) == 0
    text = capsys.readouterr().out
    assert "full (seeds 0-1) against full (seeds 0-1)" in text and "lost on 0" in text
    written = json.loads(result.read_text())
    assert written["counts"]["lost"] == 0 and written["counts"]["groups"] == len(both.groups)
    assert written["pooled"]["offline"]["baseline"] == pytest.approx(written["pooled"]["offline"]["candidate"])
    before = out["both"].read_bytes()   # the output never overwrites a report
    assert main(["bench", "rule", "--baseline", str(out["s0"]), "--candidate", str(out["both"]),
                 "--json", str(out["both"])]) == 2
    assert out["both"].read_bytes() == before


def test_a_sequences_reports_pool_like_a_benchmarks(pandaset_root, tmp_path):
    """`eval SEQ` reports (rows per mode, difficulties with their spreads; real PandaSet tracks, one medium, one
    hard, 8 frames): two one-seed runs pooled equal the two-seed run group by group."""
    out = {}
    for name, extra in (("s0", ["--seeds", "1"]), ("s1", ["--seeds", "1", "--first-seed", "1"]),
                        ("both", ["--seeds", "2"])):
        out[name] = tmp_path / f"{name}.json"
        assert main(["eval", str(pandaset_root), "--tracks", "91aa5b5c,1a46fa13", "--end-frame", "8", "--preset",
                     "full", "--offline", *extra, "--json", str(out[name])]) == 0
    both = read_report(out["both"])
    assert both.seeds == (0, 1) and {g for _, g in both.groups} == {"all", "medium", "hard"}
    assert any(g.std for g in both.groups.values())   # the seeds differ: the spreads are compared, not zeros
    check = check_rule([read_report(out["s0"]), read_report(out["s1"])], [both])
    assert len(check.verdicts) == len(both.groups) and not check.lost and not check.unmatched
    for v in check.verdicts:
        assert v.baseline.mean == pytest.approx(v.candidate.mean, abs=1e-9)
        assert v.baseline.std == pytest.approx(v.candidate.std, abs=1e-9)
