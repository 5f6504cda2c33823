"""The one CTRV model (tracker.ctrv_arc): the tracker's CTRV filter and the motion export's smoother move on it."""

from __future__ import annotations

import numpy as np
import pytest

from sot_apps.objects.smoother import ctrv_transition
from tracker import ctrv_arc
from tracker.motion_filter import ctrv_predict_state


@pytest.mark.parametrize("course, speed, turn_rate, dt", [(0.0, 10.0, 0.5, 0.4), (1.2, 7.0, -0.8, 1.0),
                                                           (-2.0, 12.0, 1e-5, 0.1), (0.3, 5.0, 0.0, 2.0)])
def test_the_arc_is_a_circle_of_radius_speed_over_turn_rate(course, speed, turn_rate, dt):
    (dx, dy), _ = ctrv_arc(course, speed, turn_rate, dt)
    if turn_rate == 0.0:
        expected = speed * dt * np.array([np.cos(course), np.sin(course)])
    else:   # centre at radius r to the left of the start; the chord subtends turn_rate * dt
        r = speed / turn_rate
        expected = r * np.array([np.sin(course + turn_rate * dt) - np.sin(course),
                                 np.cos(course) - np.cos(course + turn_rate * dt)])
    np.testing.assert_allclose([dx, dy], expected, rtol=1e-9, atol=1e-12)
    assert np.hypot(dx, dy) <= speed * dt + 1e-12     # a chord is never longer than the arc


def test_the_jacobian_matches_finite_differences():
    args = np.array([0.7, 9.0, 0.35])
    _, jac = ctrv_arc(*args, 0.5)
    numeric = np.zeros((2, 3))
    for j in range(3):
        step = np.zeros(3)
        step[j] = 1e-6
        numeric[:, j] = (ctrv_arc(*(args + step), 0.5)[0] - ctrv_arc(*(args - step), 0.5)[0]) / 2e-6
    np.testing.assert_allclose(jac, numeric, atol=1e-6)


def test_filter_and_smoother_predict_the_same_planar_motion():
    s = np.array([3.0, -1.0, 0.4, 11.0, 0.3])
    tracker_next = ctrv_predict_state(s, 0.3)
    smoother_next, _ = ctrv_transition(np.array([3.0, -1.0, 0.4, 11.0, 0.3, 0.5, 0.0, 0.0]), 0.3)
    np.testing.assert_allclose(tracker_next, smoother_next[:5], rtol=0, atol=1e-12)
