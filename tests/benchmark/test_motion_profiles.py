"""The shared motion profiles: bounded dynamics and the manoeuvres they promise."""

from __future__ import annotations

import math

import numpy as np
import pytest

from sot_apps.objects.motion_profiles import ALL_PROFILES, VehicleLimits, integrate_motion, place_path, sample_motion

LIMITS = VehicleLimits()
DT = 0.01


@pytest.mark.parametrize("profile", ALL_PROFILES)
def test_dynamics_stay_within_the_bounds(profile):
    for seed in range(6):
        spec = sample_motion(profile, np.random.default_rng(seed), 6.0)
        path = integrate_motion(spec, 6.0, DT)
        assert np.all(path.speed >= 0.0) and np.all(path.speed <= LIMITS.max_speed + 1e-9)
        assert path.accel.min() >= -LIMITS.max_decel - 1e-9 and path.accel.max() <= LIMITS.max_accel + 1e-9
        jerk = np.abs(np.diff(path.accel)) / DT
        resting = (path.speed[1:] == 0.0) & (path.speed[:-1] > 0.0)  # the instant the car comes to rest
        assert np.all(jerk[~resting] <= LIMITS.max_jerk + 1e-6)
        assert np.all(jerk[resting] <= 2.0 * LIMITS.max_jerk)
        # the measured speed is the path's: the integrator is consistent
        step = np.hypot(np.diff(path.x), np.diff(path.y)) / DT
        assert np.allclose(step, path.speed[:-1], atol=1e-6)


def test_hard_profiles_drive_at_their_speeds_and_oblique_curves_gently():
    for seed in range(20):
        rng = np.random.default_rng(seed)
        for profile, (lo, hi) in (("far_approach", (5.0, 12.0)), ("passing", (7.0, 14.0)), ("hidden", (3.0, 10.0)),
                                  ("oblique", (3.0, 9.0))):
            path = integrate_motion(sample_motion(profile, rng, 4.0), 4.0, DT)
            assert lo <= path.speed.min() and path.speed.max() <= hi  # constant speed in the profile's range
            turned = abs(path.heading[-1] - path.heading[0])
            if profile == "oblique":  # radius >= wheelbase / tan(0.02 / 2)-ish: at most a few degrees in 4 s
                assert turned <= 2.0 * 9.0 * 4.0 * math.tan(0.02 / 2) / LIMITS.wheelbase + 1e-9
            else:
                assert turned == 0.0


def test_manoeuvres_do_what_their_names_say():
    rng = np.random.default_rng(0)
    for profile, angle in (("u_turn", math.pi), ("turn", math.pi / 2)):
        spec = sample_motion(profile, rng, 8.0)
        path = integrate_motion(spec, 8.0, DT)
        assert abs(abs(path.heading[-1]) - angle) < 0.12
    spec = sample_motion("lane_change", rng, 8.0)
    path = integrate_motion(spec, 8.0, DT)
    assert abs(path.heading[-1]) < 0.03 and 2.0 < abs(path.y[-1]) < 5.0
    spec = sample_motion("hard_brake", np.random.default_rng(2), 8.0)
    path = integrate_motion(spec, 8.0, DT)
    assert path.speed[-1] == 0.0 and path.accel.min() <= -5.0
    spec = sample_motion("stop_and_go", np.random.default_rng(1), 8.0)
    path = integrate_motion(spec, 8.0, DT)
    stopped = np.flatnonzero(path.speed < 0.05)
    assert stopped.size and path.speed[-1] > 1.0
    with pytest.raises(ValueError):
        sample_motion("moonwalk", rng, 4.0)


def test_place_path_is_a_rigid_motion():
    path = integrate_motion(sample_motion("turn", np.random.default_rng(3), 5.0), 5.0, DT)
    xyh = place_path(path, 10.0, -4.0, 1.0)
    assert np.allclose(xyh[0], [10.0, -4.0, 1.0])
    local = np.hypot(np.diff(path.x), np.diff(path.y))
    assert np.allclose(np.hypot(np.diff(xyh[:, 0]), np.diff(xyh[:, 1])), local)


def test_synth_world_uses_the_shared_profiles():
    from sot_apps.synth import make_world

    plain = make_world(frames=30, vehicles=7, seed=0)
    profiled = make_world(frames=30, vehicles=7, seed=0, profiles=True)
    assert not np.allclose(plain.objects[0].trajectory.states, profiled.objects[0].trajectory.states)
    braking = profiled.objects[1].trajectory  # vehicle 1: hard_brake
    speed = np.hypot(*np.diff(braking.states[:, :2], axis=0).T) / 1e-3
    assert speed[0] > 5.0 and speed[-1] < speed[0] - 3.0
