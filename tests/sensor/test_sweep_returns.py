"""The per-return models of a simulated sweep (noise, drops, intensity, points) in the compiled loop: the same
scan as the numpy implementation for the same seed, each effect as its model says, and the counter-based random
draws they use (uniform and normal, the same in C and numpy, deterministic per seed)."""

from __future__ import annotations

import math

import numpy as np
import pytest

import sot_apps.raycast.compiled as compiled_module
import sot_apps.sensor.scan as scan_module
from sot_apps.objects.trajectory import Trajectory
from sot_apps.raycast import RaycastScene
from sot_apps.raycast.compiled import (
    ReturnModels,
    _CompiledTracer,
    compiled_backend_available,
    compiled_draws,
    compiled_sweep_returns,
)
from sot_apps.sensor.model import PRESETS, load_sensor
from sot_apps.sensor.noise import GRAZING_DROP, NOISE, RANDOM_DROP, RANGE_DROP, Realism, ndtri, ray_draws
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


def _assert_same_scan(a, b):
    assert len(a) == len(b) > 1000
    for name in FIELDS:
        x, y = getattr(a, name), getattr(b, name)
        assert x.dtype == y.dtype, name
        if name in ("xyz", "intensity", "distance"):   # libm and numpy's SIMD exp/log/acos may differ in the last bit
            np.testing.assert_allclose(x, y, rtol=2e-7, atol=1e-6, err_msg=name)
        else:
            np.testing.assert_array_equal(x, y, err_msg=name)


@pytest.mark.parametrize("realism", REALISMS)
@pytest.mark.parametrize("sensor_name", ["pandaset_pandar64", "vlp16"])
@pytest.mark.parametrize("moving", [True, False])   # without moving objects the loop maps geometry ids itself
def test_compiled_returns_equal_the_numpy_models(realism, sensor_name, moving, monkeypatch):
    assert compiled_backend_available()   # built by pip install (a C compiler is part of the dev setup)
    sensor = load_sensor(sensor_name)
    ego = Trajectory(np.array([-100_000_000, 0]), np.array([[0.0, 0.0, 0.3, 0.1], [1.2, 0.4, 0.3, 0.15]]))
    scene = _scene() if moving else _scene()[:3]
    compiled = simulate_scan(sensor, scene, ego, 0, realism)
    monkeypatch.setattr(scan_module, "compiled_sweep_returns", lambda *args, **kwargs: None)
    reference = simulate_scan(sensor, scene, ego, 0, realism)
    _assert_same_scan(compiled, reference)
    assert set(np.unique(compiled.object_index)) <= set(range(len(scene)))
    assert (compiled.instance == np.array([o.instance for o in scene])[compiled.object_index]).all()


def test_without_the_compiled_loop_embreex_and_numpy_give_the_same_scan(monkeypatch):
    """The clean fallback: when the compiled library is missing, RaycastScene traces with embreex and the
    per-return models run in numpy, with the same draws, so the scan is the compiled path's."""
    sensor = load_sensor("pandaset_pandar64")
    realism = Realism(drop_random=0.1, seed=11)
    compiled = simulate_scan(sensor, _scene(), np.eye(4), 0, realism)
    monkeypatch.setattr(_CompiledTracer, "lib", None)
    monkeypatch.setattr(_CompiledTracer, "error", None)
    monkeypatch.setattr(compiled_module.glob, "glob", lambda pattern: [])   # as if pip install had no C compiler
    assert not compiled_backend_available() and "not built" in _CompiledTracer.error
    assert RaycastScene().backend == "embreex"
    with pytest.raises(RuntimeError, match="not available"):
        RaycastScene("compiled")
    fallback = simulate_scan(sensor, _scene(), np.eye(4), 0, realism)
    _assert_same_scan(compiled, fallback)


def test_draws_are_the_same_in_c_and_numpy_and_fixed_by_the_seed():
    n = 50_000
    index = np.arange(n)
    for seed in (0, 7, -3):
        for stream in (NOISE, RANDOM_DROP, GRAZING_DROP, RANGE_DROP):
            np.testing.assert_array_equal(compiled_draws(seed, stream, n), ray_draws(seed, stream, index))
            np.testing.assert_allclose(compiled_draws(seed, stream, n, normal=True),
                                       ray_draws(seed, stream, index, normal=True), rtol=0, atol=1e-14)
    # a ray's draw depends on the seed, the stream and its index only (not on which other rays are drawn)
    subset = np.array([5, 17, 40_000, 3])
    np.testing.assert_array_equal(ray_draws(4, NOISE, subset), ray_draws(4, NOISE, index)[subset])
    assert not np.array_equal(ray_draws(4, NOISE, index), ray_draws(5, NOISE, index))
    assert not np.array_equal(ray_draws(4, NOISE, index), ray_draws(4, GRAZING_DROP, index))


def test_draws_are_uniform_and_normal():
    from scipy import stats

    n = 200_000
    u = ray_draws(1, GRAZING_DROP, np.arange(n))
    assert 0.0 < u.min() and u.max() < 1.0
    assert stats.kstest(u, "uniform").pvalue > 1e-3
    z = ray_draws(1, NOISE, np.arange(n), normal=True)
    assert stats.kstest(z, "norm").pvalue > 1e-3
    assert abs(z.mean()) < 5 / np.sqrt(n) and abs(z.std() - 1.0) < 5 / np.sqrt(2 * n)
    # streams are independent of each other and of the neighbouring ray
    v = ray_draws(1, RANGE_DROP, np.arange(n))
    assert abs(np.corrcoef(u, v)[0, 1]) < 5 / np.sqrt(n) and abs(np.corrcoef(u[:-1], u[1:])[0, 1]) < 5 / np.sqrt(n)


def test_ndtri_is_the_normal_quantile():
    from statistics import NormalDist

    p = np.concatenate([[1e-300, 1e-20, 1e-11, 1e-6, 0.02, 0.075, 0.0751, 0.5, 0.9249, 0.925, 0.98, 1 - 2 ** -53],
                        np.random.default_rng(0).random(1000)])
    expected = np.array([NormalDist().inv_cdf(float(x)) for x in p])
    np.testing.assert_allclose(ndtri(p), expected, rtol=1e-15, atol=1e-15)


def _rays(n: int, cos_incidence: float | np.ndarray, distance: float):
    """n rays along +x hitting a surface whose normal makes the given incidence with the reversed ray."""
    dirs = np.tile([1.0, 0.0, 0.0], (n, 1))
    cos_incidence = np.broadcast_to(cos_incidence, (n,))
    normal = np.column_stack([-cos_incidence, np.sqrt(1 - cos_incidence ** 2), np.zeros(n)]).astype(np.float32)
    return np.full(n, distance), normal, dirs, np.zeros(3)


def _returns(dist, normal, dirs, origin, models, objects=None, reflectivity=(0.7,)):
    n = len(dist)
    objects = np.zeros(n, np.int32) if objects is None else objects
    return compiled_sweep_returns(dist, normal, dirs, origin, objects, np.asarray(reflectivity, float),
                                  np.arange(len(reflectivity), dtype=np.int32), models, np.eye(4), n, np.zeros(n))


def test_each_effect_follows_its_model():
    n = 200_000
    index = np.arange(n)
    for theta in (60.0, 80.0, 85.0):
        dist, normal, dirs, origin = _rays(n, np.cos(np.radians(theta)), 30.0)
        models = ReturnModels(0.5, 200.0, seed=2, noise_sigma=0.03, drop_grazing=True, intensity=True,
                              attenuation=0.002)
        out = _returns(dist, normal, dirs, origin, models)
        p = np.clip((theta - 75.0) / 15.0, 0, 1) ** 2   # the grazing drop model
        kept = len(out.keep) / n
        assert abs(kept - (1 - p)) < 5 * np.sqrt(p * (1 - p) / n) + 1e-12, (theta, kept, 1 - p)
        np.testing.assert_array_equal(out.keep, np.flatnonzero(ray_draws(2, GRAZING_DROP, index) >= p))
        noise = out.distance.astype(np.float64) - 30.0
        np.testing.assert_allclose(noise, 0.03 * ray_draws(2, NOISE, out.keep, normal=True), atol=2e-6)
        assert abs(np.std(noise) - 0.03) < 0.001 and abs(np.mean(noise)) < 0.001
        expected = np.clip(0.7 * np.cos(np.radians(theta)) * np.exp(-2 * 0.002 * (30.0 + noise)), 0, 1)
        np.testing.assert_allclose(out.intensity, expected, rtol=1e-6)
        np.testing.assert_allclose(out.xyz[:, 0], out.distance, rtol=1e-6)
    # the range drop model and the random drop, on their own draws
    sensor = PRESETS["pandaset_pandar64"]
    dist, normal, dirs, origin = _rays(n, 1.0, 40.0)
    models = ReturnModels(0.5, 200.0, seed=9, drop_random=0.1, drop_range=True, range_a=sensor.drop_at_zero_range,
                          range_b=sensor.drop_per_m)
    out = _returns(dist, normal, dirs, origin, models, reflectivity=(0.5,))
    p_range = float(sensor.range_drop_probability(np.array([40.0]))[0])
    expected = (1 - p_range) * 0.9
    assert abs(len(out.keep) / n - expected) < 5 * np.sqrt(expected * (1 - expected) / n)
    np.testing.assert_array_equal(out.keep, np.flatnonzero((ray_draws(9, RANGE_DROP, index) >= p_range)
                                                           & (ray_draws(9, RANDOM_DROP, index) >= 0.1)))
    assert (out.intensity == 0).all() and (out.distance == 40.0).all()


def test_out_of_range_and_missed_rays_are_not_returned():
    dist = np.array([np.inf, 0.2, 5.0, 250.0, np.nan, 100.0])
    normal = np.tile(np.array([-1.0, 0.0, 0.0], np.float32), (6, 1))
    dirs = np.tile([1.0, 0.0, 0.0], (6, 1))
    out = compiled_sweep_returns(dist, normal, dirs, np.array([1.0, 2.0, 3.0]), np.array([0, -1, 0, 0, 0, -1], np.int32),
                                 np.array([0.5]), np.array([4], np.int32), ReturnModels(0.5, 200.0, intensity=True),
                                 np.eye(4), 4, np.array([-30, -20, -10, 0]))
    np.testing.assert_array_equal(out.keep, [2, 5])
    np.testing.assert_array_equal(out.intensity, np.float32([0.5, 0.0]))   # object -1 (no object): reflectivity 0
    np.testing.assert_array_equal(out.xyz, np.float32([[6, 2, 3], [101, 2, 3]]))
    np.testing.assert_array_equal(out.instance, [4, -1])
    np.testing.assert_array_equal(out.beam, [0, 1])          # ray i is beam i // columns, column i % columns
    np.testing.assert_array_equal(out.column, [2, 1])
    np.testing.assert_array_equal(out.time_offset_ns, [-10, -20])


def test_ray_packets_give_the_same_hits_as_single_rays(monkeypatch):
    """sot_rt_cast16 (16-ray packets) against sot_rt_cast (one ray at a time) on a sweep of vehicles and ground,
    with float32 and float64 rays."""
    from sot_apps.sensor.scan import build_static_scene
    from sot_apps.synth.vehicles import random_vehicle

    assert _CompiledTracer.load().sot_rt_has_packets()
    rng = np.random.default_rng(2)
    objects = _scene()[:1] + [SimObject(np.asarray(v.vertices), np.asarray(v.faces),
                                        Trajectory.static(*rng.uniform(-30, 30, 2), -1.0, rng.uniform(-3, 3)), i)
                              for i, v in enumerate(random_vehicle(rng) for _ in range(8))]
    dirs, _, _ = load_sensor("hdl64e").ray_grid()
    dirs = dirs[: len(dirs) - 3]   # not a multiple of 16: a partial packet
    hits = {}
    for packets in ("1", "0"):
        monkeypatch.setenv("SOT_APPS_RAY_PACKETS", packets)
        scene = build_static_scene(objects)
        for dtype in (np.float32, np.float64):
            hits[packets, dtype] = scene.cast(np.zeros(3, dtype), np.ascontiguousarray(dirs, dtype=dtype))
    reference = hits["0", np.float32]
    assert (reference.geom_id >= 1).sum() > 1000   # many vehicle hits
    for key, h in hits.items():
        for name in ("distance", "normal", "prim_id", "geom_id"):
            np.testing.assert_array_equal(getattr(h, name), getattr(reference, name), err_msg=f"{key} {name}")


def test_grazing_drops_are_the_exact_formulas_decisions():
    """The compiled loop brackets the incidence angle before calling acos; every decision is still the exact
    formula's, also for rays whose draw falls right at their drop probability."""
    n = 400_000
    seed = 7
    u = ray_draws(seed, GRAZING_DROP, np.arange(n))
    rng = np.random.default_rng(7)
    cos_incidence = np.concatenate([rng.uniform(0.0, np.cos(np.radians(75.0)), n - 4), [0.0, 1e-9, 0.2588, 0.0871]])
    # a quarter of the rays get the incidence whose drop probability is their own draw
    half = n // 4
    cos_incidence[:half] = np.cos(np.radians(75.0 + 15.0 * np.sqrt(u[:half])))
    dist, normal, dirs, origin = _rays(n, cos_incidence, 30.0)
    c = np.clip(-(dirs * normal.astype(np.float64)).sum(axis=1), 0.0, 1.0)
    theta = np.array([math.acos(x) for x in c]) * (180.0 / np.pi)   # libm's acos, as the loop's exact path
    p = np.clip((theta - 75.0) / 15.0, 0.0, 1.0) ** 2
    assert np.abs(u[:half] - p[:half]).max() < 1e-6   # the draws sit at their probability (float32 normals)
    out = _returns(dist, normal, dirs, origin, ReturnModels(0.5, 200.0, seed=seed, drop_grazing=True))
    np.testing.assert_array_equal(out.keep, np.flatnonzero(~(u < p)))
