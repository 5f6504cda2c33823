"""One vehicle / moving rule (sot_apps.objects.selection): info, planning, bank build --all and eval --all-moving agree."""

from __future__ import annotations

import numpy as np
import pytest

from sot_apps.objects.selection import DEFAULT_SELECTION, Selection

# The 9 moving vehicles LiDAR-SOT's criteria keep on pandaset_002 (the dev tracks; dense enough at the start).
DEV_PREFIXES = {"20d13d1d", "8ac00bad", "0d238564", "f0b32b02", "91aa5b5c", "71a404f3", "8febbea0", "1a46fa13",
                "b09e1c68"}


@pytest.mark.parametrize("label, vehicle", [
    ("Car", True), ("Pickup Truck", True), ("Medium-sized Truck", True), ("Semi-truck", True), ("Bus", True),
    ("Other Vehicle - Construction Vehicle", True), ("Emergency Vehicle", True), ("vehicle.car", True),
    ("TYPE_VEHICLE", True), ("Motorcycle", False), ("vehicle.motorcycle", False), ("vehicle.bicycle", False),
    ("Pedestrian", False), ("Cones", False), ("Towed Object", False), ("Cyclist", False)])
def test_vehicle_rule(label, vehicle):
    assert DEFAULT_SELECTION.is_vehicle(label) is vehicle


def test_motion_rule_thresholds():
    rule = Selection()
    t = np.arange(11) * 100_000_000  # 10 Hz, 1 s
    still = np.zeros((11, 2)) + np.random.default_rng(0).normal(0, 0.02, (11, 2))
    assert not rule.motion(still, t).moving
    straight = np.c_[np.linspace(0, 1.2, 11), np.zeros(11)]
    assert rule.motion(straight, t).moving and rule.motion(straight, t).max_displacement_m == pytest.approx(1.2)
    # there and back: far at some frame, back at the start at the end -> moving (max displacement)
    back = np.c_[np.r_[np.linspace(0, 2, 6), np.linspace(1.6, 0, 5)], np.zeros(11)]
    assert rule.motion(back, t).moving and rule.motion(back, t).displacement_m == pytest.approx(0)
    # two frames 0.1 s apart, 0.35 m: the short-track rule (3.5 m/s)
    assert rule.motion(np.array([[0, 0], [0.35, 0]]), np.array([0, 100_000_000])).moving
    assert not rule.motion(np.array([[0, 0], [0.35, 0]]), np.array([0, 1_000_000_000])).moving


def test_info_planning_bank_and_eval_select_the_same_vehicles(pandaset, pandaset_root, tmp_path, monkeypatch):
    from sot_apps.cli.main import main
    from sot_apps.evaluation.tracker import select_moving_vehicle_tracks
    from sot_apps.objects import bank as bank_module
    from sot_apps.pipeline.config import ObjectSource, PipelineConfig, SequenceConfig
    from sot_apps.pipeline.plan import make_plan
    from sot_apps.summary import summarize_tracks

    info = summarize_tracks(pandaset, progress=False)
    info_vehicles = {t.track_id for t in info if t.vehicle}
    info_moving = {t.track_id for t in info if t.vehicle and t.moving}
    info_evaluable = {t.track_id for t in info if t.vehicle and t.moving
                      and DEFAULT_SELECTION.evaluable(t.num_frames, t.mean_points_first10)}

    def planned(moving_only: bool) -> set[str]:
        config = PipelineConfig(out=str(tmp_path / "run"), sequences=(SequenceConfig(str(pandaset_root),
                                                          objects=ObjectSource(moving_only=moving_only)),))
        return {o.object_id for o in make_plan(config).objects}

    captured: list[str] = []

    def fake_entries(out, seq, ids, **kwargs):
        captured.extend(ids)
        return [], []

    monkeypatch.setattr(bank_module, "entries_from_annotations", fake_entries)
    # the fake builds no entry, and a bank build that adds nothing is exit code 2 (issue 16); the ids it was asked for count
    assert main(["bank", "build", "--from-annotations", str(pandaset_root), "--all", "--out", str(tmp_path / "bank")]) == 2

    assert len(info_vehicles) == 76 and len(info_moving) == 20   # the motorcycle is not a vehicle
    assert set(captured) == info_vehicles == planned(moving_only=False)
    assert planned(moving_only=True) == info_moving
    evaluated = set(select_moving_vehicle_tracks(pandaset))
    assert evaluated == info_evaluable
    assert {t[:8] for t in evaluated} == DEV_PREFIXES
