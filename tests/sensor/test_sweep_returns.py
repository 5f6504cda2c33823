"""The per-return models of a simulated sweep (noise, drops, intensity, points) in the compiled loop: the same
scan as the numpy implementation for the same seed, and each effect as its model says."""

from __future__ import annotations

import math

import numpy as np
import pytest

import sot_apps.sensor.scan as scan_module
from sot_apps.objects.trajectory import Trajectory
from sot_apps.raycast.compiled import compiled_backend_available, compiled_sweep_returns
from sot_apps.sensor.model import PRESETS, load_sensor
from sot_apps.sensor.noise import Realism
from sot_apps.sensor.scan import SimObject, simulate_scan

FIELDS = ("xyz", "instance", "intensity", "time_offset_ns", "beam", "column", "distance", "object_index")


def _box(x: float, y: float, heading: float, instance: int, moving: bool = False) -> SimObject:
    v = np.array([[sx * 2.2, sy * 0.9, sz * 0.75] for sx in (-1, 1) for sy in (-1, 1) for sz in (-1, 1)], float)
    f = np.array([[0, 1, 3], [0, 3, 2], [4, 6, 7], [4, 7, 5], [0, 4, 5], [0, 5, 1], [2, 3, 7], [2, 7, 6],
                  [0, 2, 6], [0, 6, 4], [1, 5, 7], [1, 7, 3]])
    trajectory = (Trajectory(np.array([-100_000_000, 0]), np.array([[x - 1.0, y, -1.05, heading], [x, y, -1.05, heading]]))
                  if moving else Trajectory.static(x, y, -1.05, heading))
    return SimObject(v, f, trajectory, instance, 0.3 + 0.1 * instance)


def _scene():
    ground = SimObject(np.array([[-80, -80, -1.8], [80, -80, -1.8], [80, 80, -1.8], [-80, 80, -1.8]], float),
                       np.array([[0, 1, 2], [0, 2, 3]]), Trajectory.static(0, 0, 0, 0), -1, 0.2, "ground")
    return [ground, _box(8, 3, 0.4, 0), _box(-12, -6, 2.0, 1), _box(15, -9, -1.0, 2, moving=True)]


REALISMS = [Realism(seed=3),   # noise, grazing drop, range drop (pandaset sensor), intensity, rolling scan
            Realism(drop_random=0.2, attenuation_per_m=0.01, seed=5),
            Realism.ideal()]


@pytest.mark.parametrize("realism", REALISMS)
@pytest.mark.parametrize("sensor_name", ["pandaset_pandar64", "vlp16"])
def test_compiled_returns_equal_the_numpy_models(realism, sensor_name, monkeypatch):
    assert compiled_backend_available()   # built by pip install (a C compiler is part of the dev setup)
    sensor = load_sensor(sensor_name)
    ego = Trajectory(np.array([-100_000_000, 0]), np.array([[0.0, 0.0, 0.3, 0.1], [1.2, 0.4, 0.3, 0.15]]))
    compiled = simulate_scan(sensor, _scene(), ego, 0, realism)
    monkeypatch.setattr(scan_module, "compiled_sweep_returns", lambda *args, **kwargs: None)
    reference = simulate_scan(sensor, _scene(), ego, 0, realism)
    assert len(compiled) == len(reference) > 1000
    for name in FIELDS:
        a, b = getattr(compiled, name), getattr(reference, name)
        assert a.dtype == b.dtype, name
        if name in ("xyz", "intensity"):   # libm and numpy's SIMD exp/acos may differ in the last bit
            np.testing.assert_allclose(a, b, rtol=2e-7, atol=1e-7, err_msg=name)
        else:
            np.testing.assert_array_equal(a, b, err_msg=name)


def _rays(n: int, cos_incidence: float, distance: float):
    """n rays along +x hitting a surface whose normal makes the given incidence with the reversed ray."""
    dirs = np.tile([1.0, 0.0, 0.0], (n, 1))
    sin = np.sqrt(1 - cos_incidence ** 2)
    normal = np.tile(np.array([-cos_incidence, sin, 0.0], np.float32), (n, 1))
    return np.full(n, distance), normal, dirs, np.zeros(3)


def test_each_effect_follows_its_model():
    rng = np.random.default_rng(0)
    n = 200_000
    for theta in (60.0, 80.0, 85.0):
        dist, normal, dirs, origin = _rays(n, np.cos(np.radians(theta)), 30.0)
        noise = rng.normal(0.0, 0.03, n)
        u = rng.random(n)
        out = compiled_sweep_returns(dist, normal, dirs, origin, np.zeros(n, np.int32), np.array([0.7]), 0.5, 200.0,
                                     noise, None, 0.0, u, 75.0, None, 0.0, 0.0, True, 0.002, np.eye(4))
        p = np.clip((theta - 75.0) / 15.0, 0, 1) ** 2   # the grazing drop model
        kept = len(out.keep) / n
        assert abs(kept - (1 - p)) < 5 * np.sqrt(p * (1 - p) / n) + 1e-12, (theta, kept, 1 - p)
        np.testing.assert_array_equal(out.keep, np.flatnonzero(u >= p))   # exactly the rays whose draw passed
        np.testing.assert_array_equal(out.measured, dist[out.keep] + noise[out.keep])
        assert abs(np.std(out.measured - 30.0) - 0.03) < 0.001 and abs(np.mean(out.measured - 30.0)) < 0.001
        expected = np.clip(0.7 * np.cos(np.radians(theta)) * np.exp(-2 * 0.002 * out.measured), 0, 1)
        np.testing.assert_allclose(out.intensity, expected, rtol=1e-6)
        np.testing.assert_allclose(out.xyz[:, 0], out.measured, rtol=1e-6)
    # the range drop model and the random drop, on their own draws
    sensor = PRESETS["pandaset_pandar64"]
    dist, normal, dirs, origin = _rays(n, 1.0, 40.0)
    u_range, u_random = rng.random(n), rng.random(n)
    out = compiled_sweep_returns(dist, normal, dirs, origin, np.zeros(n, np.int32), np.array([0.5]), 0.5, 200.0,
                                 None, u_random, 0.1, None, 75.0, u_range, sensor.drop_at_zero_range,
                                 sensor.drop_per_m, False, 0.0, np.eye(4))
    p_range = float(sensor.range_drop_probability(np.array([40.0]))[0])
    expected = (1 - p_range) * 0.9
    assert abs(len(out.keep) / n - expected) < 5 * np.sqrt(expected * (1 - expected) / n)
    np.testing.assert_array_equal(out.keep, np.flatnonzero((u_range >= p_range) & (u_random >= 0.1)))
    assert (out.intensity == 0).all()


def test_out_of_range_and_missed_rays_are_not_returned():
    dist = np.array([np.inf, 0.2, 5.0, 250.0, np.nan, 100.0])
    normal = np.tile(np.array([-1.0, 0.0, 0.0], np.float32), (6, 1))
    dirs = np.tile([1.0, 0.0, 0.0], (6, 1))
    out = compiled_sweep_returns(dist, normal, dirs, np.array([1.0, 2.0, 3.0]), np.array([0, -1, 0, 0, 0, -1], np.int32),
                                 np.array([0.5]), 0.5, 200.0, None, None, 0.0, None, 75.0, None, 0.0, 0.0, True, 0.0,
                                 np.eye(4))
    np.testing.assert_array_equal(out.keep, [2, 5])
    np.testing.assert_array_equal(out.intensity, np.float32([0.5, 0.0]))   # object -1 (no object): reflectivity 0
    np.testing.assert_array_equal(out.xyz, np.float32([[6, 2, 3], [101, 2, 3]]))


def test_ray_packets_give_the_same_hits_as_single_rays(monkeypatch):
    """sot_rt_cast8 (8-ray packets) against sot_rt_cast (one ray at a time) on a sweep of vehicles and ground."""
    from sot_apps.raycast.compiled import _CompiledTracer
    from sot_apps.sensor.scan import build_static_scene
    from sot_apps.synth.vehicles import random_vehicle

    assert hasattr(_CompiledTracer.load(), "sot_rt_cast8")
    rng = np.random.default_rng(2)
    objects = _scene()[:1] + [SimObject(np.asarray(v.vertices), np.asarray(v.faces),
                                        Trajectory.static(*rng.uniform(-30, 30, 2), -1.0, rng.uniform(-3, 3)), i)
                              for i, v in enumerate(random_vehicle(rng) for _ in range(8))]
    dirs, _, _ = load_sensor("hdl64e").ray_grid()
    dirs = np.ascontiguousarray(dirs[: len(dirs) - 3], dtype=np.float32)   # not a multiple of 8: a partial packet
    hits = {}
    for packets in ("1", "0"):
        monkeypatch.setenv("SOT_APPS_RAY_PACKETS", packets)
        scene = build_static_scene(objects)
        hits[packets] = scene.cast(np.zeros(3, np.float32), dirs)
    assert (hits["1"].geom_id >= 1).sum() > 1000   # many vehicle hits
    for name in ("distance", "normal", "prim_id", "geom_id"):
        np.testing.assert_array_equal(getattr(hits["1"], name), getattr(hits["0"], name), err_msg=name)


def test_grazing_drops_are_the_exact_formulas_decisions():
    """The compiled loop brackets the incidence angle before calling acos; every decision is still the exact
    formula's, also for draws that fall right at a ray's drop probability."""
    rng = np.random.default_rng(7)
    n = 400_000
    cos_incidence = np.concatenate([rng.uniform(0.0, np.cos(np.radians(75.0)), n - 4), [0.0, 1e-9, 0.2588, 0.0871]])
    dirs = np.tile([1.0, 0.0, 0.0], (n, 1))
    normal = np.column_stack([-cos_incidence, np.sqrt(1 - cos_incidence ** 2), np.zeros(n)]).astype(np.float32)
    c = np.clip(-(dirs * normal.astype(np.float64)).sum(axis=1), 0.0, 1.0)
    theta = np.array([math.acos(x) for x in c]) * (180.0 / np.pi)   # libm's acos, as the loop's exact path
    p = np.clip((theta - 75.0) / 15.0, 0.0, 1.0) ** 2
    u = rng.random(n)
    u[: n // 4] = p[: n // 4]                                     # draws exactly at the probability: kept
    u[n // 4: n // 2] = np.nextafter(p[n // 4: n // 2], -1.0)     # just below it: dropped
    out = compiled_sweep_returns(np.full(n, 30.0), normal, dirs, np.zeros(3), np.zeros(n, np.int32), np.array([0.5]),
                                 0.5, 200.0, None, None, 0.0, u, 75.0, None, 0.0, 0.0, False, 0.0, np.eye(4))
    np.testing.assert_array_equal(out.keep, np.flatnonzero(~(u < p)))
