"""The model-free detector's parts on analytic point sets: L-shape heading, range-adaptive clustering,
sweep-to-sweep nearness, and the logistic calibration."""

from __future__ import annotations

import numpy as np
import pytest

from sot_apps.detection.accumulate import near_mask, to_current_ego
from sot_apps.detection.calibrate import fit_logistic
from sot_apps.detection.clustering import cluster_bev, link_radius
from sot_apps.detection.lshape import fit_rectangle


def _l_shape(heading: float, length: float = 4.5, width: float = 1.8, n: int = 120, noise: float = 0.0,
             seed: int = 0) -> np.ndarray:
    """Points on two perpendicular sides (the near long side and the rear) of a box turned by ``heading``."""
    rng = np.random.default_rng(seed)
    side = np.column_stack([np.linspace(-length / 2, length / 2, n), np.full(n, -width / 2)])
    rear = np.column_stack([np.full(n // 3, -length / 2), np.linspace(-width / 2, width / 2, n // 3)])
    local = np.vstack([side, rear]) + noise * rng.standard_normal((n + n // 3, 2))
    c, s = np.cos(heading), np.sin(heading)
    return local @ np.array([[c, s], [-s, c]]) + np.array([12.0, -3.0])


@pytest.mark.parametrize("criterion", ["closeness", "variance"])
@pytest.mark.parametrize("heading_deg", [0.0, 17.0, 33.0, 45.0, 61.0, 88.0])
def test_l_shape_heading_of_exact_and_noisy_l_shapes(heading_deg, criterion):
    heading = np.deg2rad(heading_deg)
    for noise in (0.0, 0.03):
        fitted, lo, hi = fit_rectangle(_l_shape(heading, noise=noise), heading_steps=90, criterion=criterion)
        error = (fitted - heading + np.pi / 4) % (np.pi / 2) - np.pi / 4   # modulo 90 degrees
        assert abs(error) <= np.deg2rad(1.0) + (np.deg2rad(2.0) if noise else 0.0), (heading_deg, noise, fitted)
        extent = np.sort(hi - lo)
        assert np.allclose(extent, [1.8, 4.5], atol=0.05 + 3 * noise), extent


def test_l_shape_rejects_an_unknown_criterion():
    with pytest.raises(ValueError, match="criterion"):
        fit_rectangle(_l_shape(0.2), criterion="area")


def test_l_shape_of_a_single_straight_face_is_along_it():
    xy = np.column_stack([np.linspace(0, 3, 50), np.zeros(50)]) @ np.array([[np.cos(0.3), np.sin(0.3)],
                                                                            [-np.sin(0.3), np.cos(0.3)]])
    fitted, lo, hi = fit_rectangle(xy)
    assert abs((fitted - 0.3 + np.pi / 4) % (np.pi / 2) - np.pi / 4) < np.deg2rad(1.0)


def test_clustering_radius_grows_with_range():
    assert link_radius(np.array([0.0, 10.0, 100.0]), 0.3, 0.01, 0.6).tolist() == pytest.approx([0.3, 0.4, 0.6])
    # two point rows 0.5 m apart: separate near the sensor (radius 0.35), one cluster at 40 m (radius 0.7)
    row = np.column_stack([np.linspace(0, 2, 41), np.zeros(41)])
    for centre, expected in ((5.0, 2), (40.0, 1)):
        xy = np.vstack([row, row + [2.5, 0.0]]) + [centre - 2.25, 3.0]
        labels = cluster_bev(xy, np.zeros(2), base=0.3, slope=0.01, maximum=0.7, voxel=0.05)
        assert len(np.unique(labels)) == expected, (centre, np.unique(labels))
        assert len(np.unique(labels[:41])) == 1 and len(np.unique(labels[41:])) == 1


def test_near_mask_and_sweep_transform():
    ref = np.array([[0.0, 0.0], [10.0, 0.0]])
    query = np.array([[0.1, 0.0], [5.0, 0.0], [10.0, 0.05], [30.0, 30.0]])
    assert near_mask(ref, query, 0.2).tolist() == [True, False, True, False]
    # an earlier sweep 2 m behind (ego moved +2 m in x): its point at x=12 is the current x=10
    current = np.eye(4)
    current[0, 3] = 2.0
    earlier = np.eye(4)
    moved = to_current_ego(np.array([[12.0, 1.0, 0.5]]), earlier, current)
    assert np.allclose(moved, [[10.0, 1.0, 0.5]])


def test_logistic_fit_recovers_known_weights():
    rng = np.random.default_rng(0)
    x = rng.standard_normal((20000, 2))
    true = np.array([-0.5, 2.0, -1.0])
    y = rng.uniform(size=len(x)) < 1.0 / (1.0 + np.exp(-(true[0] + x @ true[1:])))
    w = fit_logistic(x, y.astype(float), l2=0.0)
    assert np.allclose(w, true, atol=0.1), w
