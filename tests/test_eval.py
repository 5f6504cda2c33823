"""sot_apps.evaluation.tracker and the ``eval`` / ``bench`` commands."""

from __future__ import annotations

import json

import numpy as np
import pytest

from sot_apps.cli.main import main
from sot_apps.evaluation import DEV_TRACKS  # the one list of the tuning set
from sot_apps.evaluation.tracker import select_moving_vehicle_tracks
from sot_apps.objects.selection import annotated_span


def test_annotated_span_is_the_first_contiguous_run():
    assert annotated_span([3, 4, 5, 7, 8]) == (3, 5)
    assert annotated_span([0]) == (0, 0)
    assert annotated_span([2, 1, 0]) == (0, 2)


def test_bench_registry_discovers_tracker():
    from sot_apps.bench import discover

    registry = discover()
    assert "tracker" in registry.benchmarks
    assert registry.benchmarks["tracker"].module == "sot_apps.bench.tracker"


def test_eval_rejects_unknown_preset(pandaset_root, capsys):
    code = main(["eval", str(pandaset_root), "--tracks", "91aa5b5c", "--preset", "nonsense"])
    err = capsys.readouterr().err
    assert code == 2
    assert "unknown preset 'nonsense'" in err and len(err.strip().splitlines()) == 1


def test_eval_rejects_unknown_track(pandaset_root, capsys):
    code = main(["eval", str(pandaset_root), "--tracks", "zzzz"])
    err = capsys.readouterr().err
    assert code == 2 and "no annotated track id starts with 'zzzz'" in err


@pytest.mark.slow
def test_all_moving_selects_exactly_the_dev_tracks(pandaset):
    ids = select_moving_vehicle_tracks(pandaset)
    assert {i[:8] for i in ids} == set(DEV_TRACKS)
    assert len(ids) == 9


@pytest.mark.slow
def test_eval_cli_prints_tables_and_writes_json(pandaset_root, tmp_path, capsys):
    out = tmp_path / "eval.json"
    code = main(["eval", str(pandaset_root), "--tracks", "91aa5b5c,1a46fa13", "--end-frame", "10", "--offline",
                 "--json", str(out)])
    printed = capsys.readouterr().out
    assert code == 0
    for text in ("Acc", "Rob", "Shape(m)", "Success", "Prec", "CE(m)", "ms/f med", "full+offline", "91aa5b5c",
                 "1a46fa13", "medium Acc", "hard Acc"):
        assert text in printed
    report = json.loads(out.read_text())
    rows = {r["name"]: r for r in report["rows"]}
    assert set(rows) == {"full", "full+offline"}
    assert [t["difficulty"] for t in report["tracks"]] == ["medium", "hard"]   # 216 and 33 points
    for row in rows.values():
        p = row["pooled"]
        assert p["n_frames"] == 20 and p["n_tracklets"] == 2            # frames 1..10 of two tracks
        assert 0.0 <= p["acc"] <= 1.0 and 0.0 <= p["rob"] <= 1.0
        assert 0.0 <= p["success"] <= 100.0 and 0.0 <= p["precision"] <= 100.0
        assert 0.0 < p["shape"] < 1.0 and p["centre_error"] >= 0.0
        assert row["timing"]["frames"] == 20 and row["timing"]["median_ms"] > 0
        # the printed pooled row is the JSON's
        line = next(ln for ln in printed.splitlines() if ln.split()[:1] == [row["name"]])
        assert line.split()[1] == f"{100 * p['acc']:.1f}"
    # an easy sanity bound: tracking these two cars over 10 frames from the true box works
    assert rows["full"]["pooled"]["acc"] > 0.5
    assert np.isfinite(report["rows"][0]["by_track"][report["tracks"][0]["track_id"]]["acc"])


def test_every_difficulty_group_carries_its_spread_over_the_seeds(pandaset):
    """``by_difficulty_std``: per difficulty, the standard deviation over the seeds of its pooled figures (a
    comparison of two runs needs each group's spread, not only the whole's). With one track per group it is the
    spread of that track's figures over the seeds, each seed evaluated alone."""
    from sot_apps.bench.sequence_eval import evaluate

    ids = ["91aa5b5c", "1a46fa13"]   # one medium, one hard (216 and 33 points)
    both = evaluate(pandaset, ids, ("full",), seeds=(0, 1), end_frame=8).rows[0]
    alone = [evaluate(pandaset, ids, ("full",), seeds=(s,), end_frame=8).rows[0] for s in (0, 1)]
    assert set(both.by_difficulty_std) == set(both.by_difficulty) == {"medium", "hard"}
    for level in ("medium", "hard"):
        per_seed = np.array([row.by_difficulty[level]["acc"] for row in alone])
        assert both.by_difficulty[level]["acc"] == pytest.approx(per_seed.mean())
        assert both.by_difficulty_std[level]["acc"] == pytest.approx(per_seed.std())
        assert alone[0].by_difficulty_std[level]["acc"] == 0.0   # one seed: no spread
    assert both.to_dict()["by_difficulty_std"] == both.by_difficulty_std
