"""The offline solve's priors on an analytic steady turn (a kinematic bicycle, box centre ahead of the rear axle):
``smooth_turn`` leaves the turn where it is (the straight-line smoothness pulls it flat), and heading from travel
with ``travel_rear_axle`` aims at the true heading (the box centre's direction of travel is off it by the
sideslip); ``shape_frames`` builds each frame's shape from nearby frames only."""

from __future__ import annotations

import dataclasses

import numpy as np

from tracker.config import OFFLINE_PARAMS
from tracker.offline import _Solver

REAR_AXLE = 1.4   # m behind the box centre (the benchmark's motion profiles: wheelbase 2.8 m / 2)


def _steady_turn(k: int = 30, speed: float = 1.0, rate: float = 0.04) -> np.ndarray:
    """States (k, 4) of a vehicle turning left at ``rate`` rad per frame whose rear axle moves at ``speed`` m per
    frame along its heading: the rear axle on a circle of radius speed / rate, the centre REAR_AXLE ahead."""
    heading = 0.3 + rate * np.arange(k)
    radius = speed / rate
    rear = np.c_[radius * np.sin(heading), -radius * np.cos(heading)] + [10.0, 5.0]
    centre = rear + REAR_AXLE * np.c_[np.cos(heading), np.sin(heading)]
    return np.c_[centre, np.full(k, 0.75), heading]


def _solver(states: np.ndarray, points: list[np.ndarray] | None = None, **params) -> _Solver:
    points = points if points is not None else [np.zeros((0, 3)) for _ in states]
    return _Solver(points, states, np.array([4.5, 1.9, 1.5]), dataclasses.replace(OFFLINE_PARAMS, **params),
                   np.random.default_rng(0))


def test_smooth_turn_leaves_a_steady_turn_where_it_is():
    truth = _steady_turn()
    straight = _solver(truth)
    straight._turn_targets(truth)
    cost, grad = straight._prior(truth)
    assert cost > 10.0 and np.abs(grad[:, :2]).max() > 10.0   # the line prior pulls the turn flat
    turn = _solver(truth, smooth_turn=True)
    turn._turn_targets(truth)
    cost, grad = turn._prior(truth)
    assert cost < 1e-6 and np.abs(grad).max() < 1e-3          # the turn is the prior's minimum


def test_smooth_turn_gradient_matches_finite_differences_with_the_targets_held():
    truth = _steady_turn(k=9)
    rng = np.random.default_rng(1)
    solver = _solver(truth, smooth_turn=True)
    x = truth + rng.normal(size=truth.shape) * [0.05, 0.05, 0.02, 0.01]
    solver._turn_targets(x)
    cost, grad = solver._prior(x)
    eps = 1e-6
    flat = x.ravel()
    num = np.array([(solver._prior((flat + eps * e).reshape(x.shape))[0] - cost) / eps / 2
                    for e in np.eye(flat.size)])
    np.testing.assert_allclose(num, grad.ravel(), rtol=1e-4, atol=1e-3 * np.abs(grad).max())


def test_travel_target_with_the_rear_axle_is_the_true_heading_in_a_turn():
    truth = _steady_turn()
    m = OFFLINE_PARAMS.travel_frames
    inner = slice(m, len(truth) - m)
    plain = _solver(truth, travel_sigma_heading=0.05)
    plain._travel_targets(truth)
    slip = np.degrees(np.abs(plain._travel[0][inner] - truth[inner, 3]))
    assert slip.min() > 2.5                        # the centre moves 3.2 deg off its heading (asin(1.4 x 0.04 / 1))
    axle = _solver(truth, travel_sigma_heading=0.05, travel_rear_axle=REAR_AXLE)
    axle._travel_targets(truth)
    np.testing.assert_allclose(axle._travel[0][inner], truth[inner, 3], atol=np.radians(0.05))
    np.testing.assert_array_equal(axle._travel[1], plain._travel[1])   # the same weights
    straight = _steady_turn(rate=1e-9)
    axle._travel_targets(straight)
    np.testing.assert_allclose(axle._travel[0][inner], straight[inner, 3], atol=1e-6)


def test_shape_frames_builds_each_frame_shape_from_the_other_fold_of_its_own_and_next_blocks():
    """``shape_frames`` = 5: frame k matches a shape made only of the other fold's frames in k's block of 5 frames
    and the two next to it (each frame's points sit at their own place along the box, so a shape point names its
    frame); without it, of the whole other fold."""
    k, block = 30, 5
    states = np.zeros((k, 4))
    points = [np.c_[np.full(8, -2.0 + 0.125 * j), np.linspace(-0.5, 0.5, 8), np.zeros(8)] for j in range(k)]

    def frame_of(shape: np.ndarray) -> np.ndarray:
        return np.unique(np.rint((shape[:, 0] + 2.0) / 0.125).astype(int))

    for blocks, shape_frames in ((1, 0), (k // block, block)):
        solver = _solver(states, points, min_shape_points=1, shape_frames=shape_frames)
        assert solver.set_shapes(states)
        assert len(solver.shapes) == 2 * blocks
        solver.select(states)
        for g, shape in enumerate(solver.shapes):
            fold, b = g % 2, g // 2
            expected = [j for j in range(k) if j % 2 != fold and (blocks == 1 or abs(j // block - b) <= 1)]
            np.testing.assert_array_equal(frame_of(shape), expected)
            rows = solver.fold_rows[g]     # the data points matched against it: frames of that fold and block
            frames = np.unique(solver.frame_idx[rows])
            assert all(j % 2 == fold and (blocks == 1 or j // block == b) for j in frames) and len(frames)
