"""The model-free detector on a synthetic world with exact boxes and unannotated roadside clutter (bushes,
hedges, trees, building corners, kiosks, pedestrians; a seed the score was not fitted on)."""

from __future__ import annotations

import numpy as np
import pytest

from sot_apps.detection.detector import DetectorConfig, detect_sequence
from sot_apps.evaluation.detection import OperatingPoint, ground_truth_frames, operating_point
from sot_apps.io import open_sequence
from sot_apps.objects.selection import DEFAULT_SELECTION
from sot_apps.synth import write_world


@pytest.fixture(scope="module")
def world(tmp_path_factory):
    return open_sequence(write_world(tmp_path_factory.mktemp("detector") / "world", frames=5, vehicles=5, seed=11,
                                     clutter=True, parked=16))


def test_detector_finds_the_vehicles_of_a_synthetic_world(world):
    frames = [2, 3, 4]   # each with its 2 earlier sweeps
    detections = detect_sequence(world, frames=frames)
    truth = ground_truth_frames(world, DEFAULT_SELECTION.vehicle_labels(world), frames)
    point = operating_point(detections, truth)
    assert point["n_gt"] >= 20 and point["n_det"] >= 20
    assert point["recall"] >= 0.7, point
    assert point["precision"] >= 0.9, point
    # the clutter is there and seen: every candidate (no score threshold) is only 40 % precise; the score drops
    # the clutter, not the vehicles
    everything = detect_sequence(world, DetectorConfig(min_score=0.0), frames=frames)
    unscored = operating_point(everything, truth, OperatingPoint(min_score=0.0))
    assert unscored["precision"] <= 0.6 and unscored["n_det"] >= 2 * point["n_det"], unscored
    assert point["recall"] >= unscored["recall"] - 0.05
    # every box is a vehicle-sized box in the world frame with a score in (0, 1)
    for det in detections.values():
        assert np.all((det.scores > 0) & (det.scores < 1))
        assert np.all(det.boxes[:, 4] >= det.boxes[:, 5])


def test_one_sweep_still_detects(world):
    single = detect_sequence(world, DetectorConfig(sweeps=1), frames=[0])
    truth = ground_truth_frames(world, DEFAULT_SELECTION.vehicle_labels(world), [0])
    assert operating_point(single, truth)["recall"] >= 0.5
