"""Sensors (beam tables), Embree ray casting (analytic distances), flat-ground ring radii."""

from __future__ import annotations

import numpy as np
import pytest
import trimesh

from sot_apps.errors import InputError
from sot_apps.objects.trajectory import Trajectory
from sot_apps.raycast import RaycastScene, cast_rays, compiled_backend_available
from sot_apps.raycast.scene import _horizontal_rectangle
from sot_apps.sensor.model import PRESETS, load_sensor
from sot_apps.sensor.noise import Realism
from sot_apps.sensor.scan import SimObject, range_image, simulate_scan

# Datasheet tables, written out independently of sensors.py (degrees, laser-id order).
DATASHEET = {
    "vlp16": [-15, 1, -13, 3, -11, 5, -9, 7, -7, 9, -5, 11, -3, 13, -1, 15],
    "hdl32e": [-30.67, -9.33, -29.33, -8.00, -28.00, -6.67, -26.67, -5.33, -25.33, -4.00, -24.00, -2.67, -22.67,
               -1.33, -21.33, 0.00, -20.00, 1.33, -18.67, 2.67, -17.33, 4.00, -16.00, 5.33, -14.67, 6.67, -13.33,
               8.00, -12.00, 9.33, -10.67, 10.67],
    "waymo_top": list(np.linspace(2.4, -17.6, 64)),
    "hdl64e": list(np.linspace(2.0, -8.33, 32)) + list(np.linspace(-8.83, -24.33, 32)),
}


@pytest.mark.parametrize("name", sorted(PRESETS))
def test_preset_ray_elevations_equal_table(name):
    sensor = PRESETS[name]
    dirs, beam, column = sensor.ray_grid()
    assert dirs.shape == (sensor.beams * sensor.columns, 3)
    elev = np.degrees(np.arctan2(dirs[:, 2], np.hypot(dirs[:, 0], dirs[:, 1])))
    table = np.asarray(DATASHEET.get(name, sensor.elevations_deg), dtype=float)
    np.testing.assert_allclose(elev, table[beam], atol=1e-9)
    if name == "pandar64":  # non-uniform: 0.167-deg spacing near the horizon, sparse at the edges
        gaps = -np.diff(np.sort(table)[::-1])
        assert np.isclose(table.max(), 14.882) and np.isclose(table.min(), -24.897)
        assert np.median(gaps) < 0.2 and gaps.max() > 5.0
    # columns are evenly spaced over a full turn
    az = np.unwrap(sensor.column_azimuths())
    np.testing.assert_allclose(np.abs(np.diff(az)), 2 * np.pi / sensor.columns, atol=1e-9)


def test_waymo_top_spec():
    s = PRESETS["waymo_top"]
    assert (s.beams, s.columns, s.num_rays, s.max_range) == (64, 2650, 169_600, 75.0)


def test_sensor_json_round_trip(tmp_path):
    import json

    path = tmp_path / "s.json"
    path.write_text(json.dumps(PRESETS["hdl32e"].to_dict()))
    assert load_sensor(str(path)) == PRESETS["hdl32e"]
    path.write_text(json.dumps({"name": "x", "elevations_deg": [], "columns": 10}))
    with pytest.raises(InputError, match="elevations_deg"):
        load_sensor(str(path))


BACKENDS = ["compiled", "embreex"]


def test_compiled_tracer_is_built():
    # pip install builds sot_apps/raycast/_embree_trace.c; the speed figures in README depend on it
    assert compiled_backend_available()
    assert RaycastScene().backend == "compiled"


@pytest.mark.parametrize("backend", BACKENDS)
def test_ray_at_box_returns_analytic_distance(backend):
    scene = RaycastScene(backend)
    box = trimesh.creation.box(extents=[2.0, 3.0, 1.5])
    gid0 = scene.add_mesh(box.vertices + [10.0, 0.0, 0.0], box.faces)
    gid1 = scene.add_mesh(box.vertices + [0.0, 20.0, 0.0], box.faces)
    rng = np.random.default_rng(0)
    # rays from the origin at random points on the near face (x = 9) of box 0, and at box 1's face y = 18.5
    targets0 = np.column_stack([np.full(50, 9.0), rng.uniform(-1.4, 1.4, 50), rng.uniform(-0.7, 0.7, 50)])
    targets1 = np.column_stack([rng.uniform(-0.9, 0.9, 50), np.full(50, 18.5), rng.uniform(-0.7, 0.7, 50)])
    targets = np.vstack([targets0, targets1])
    dirs = targets / np.linalg.norm(targets, axis=1, keepdims=True)
    hits = scene.cast(np.zeros(3), dirs)
    np.testing.assert_allclose(hits.distance, np.linalg.norm(targets, axis=1), atol=1e-5)
    assert (hits.geom_id[:50] == gid0).all() and (hits.geom_id[50:] == gid1).all()
    np.testing.assert_allclose(hits.normal[:50], np.tile([-1.0, 0, 0], (50, 1)), atol=1e-6)
    np.testing.assert_allclose(hits.normal[50:], np.tile([0, -1.0, 0], (50, 1)), atol=1e-6)
    assert (hits.prim_id >= 0).all() and (hits.prim_id < len(box.faces)).all()
    miss = scene.cast(np.zeros(3), np.array([[0.0, -1.0, 0.0]]))
    assert np.isinf(miss.distance[0]) and miss.geom_id[0] == -1
    # the parallel path (threads for compiled, forked processes for embreex) returns the same hits
    par = cast_rays(scene, np.zeros(3), np.repeat(dirs, 50, axis=0), processes=2, min_rays_per_process=1000)
    np.testing.assert_array_equal(par.distance, np.repeat(hits.distance, 50))
    np.testing.assert_array_equal(par.geom_id, np.repeat(hits.geom_id, 50))


def _ground_quad(z: float, x0: float, x1: float, y0: float, y1: float, diagonal: int = 0) -> tuple[np.ndarray, np.ndarray]:
    v = np.array([[x0, y0, z], [x1, y0, z], [x1, y1, z], [x0, y1, z]], float)
    f = np.array([[0, 1, 2], [0, 2, 3]]) if diagonal == 0 else np.array([[0, 1, 3], [1, 2, 3]])
    return v, f


def test_ground_rectangle_detection():
    assert _horizontal_rectangle(*_ground_quad(-1.5, -10, 20, -5, 5)) == (-1.5, -10.0, 20.0, -5.0, 5.0)
    assert _horizontal_rectangle(*_ground_quad(0.0, 0, 1, 0, 2, diagonal=1)) == (0.0, 0.0, 1.0, 0.0, 2.0)
    v, f = _ground_quad(0.0, 0, 1, 0, 1)
    tilted = v.copy()
    tilted[2, 2] = 0.1
    assert _horizontal_rectangle(tilted, f) is None                       # not horizontal
    rotated = v @ np.array([[0.8, -0.6, 0], [0.6, 0.8, 0], [0, 0, 1.0]]).T
    assert _horizontal_rectangle(rotated, f) is None                      # not axis-aligned
    assert _horizontal_rectangle(v, np.array([[0, 1, 2], [0, 1, 2]])) is None   # does not tile the rectangle
    box = trimesh.creation.box()
    assert _horizontal_rectangle(np.asarray(box.vertices), np.asarray(box.faces)) is None


def test_backends_agree_on_ground_and_meshes():
    """The compiled loop (analytic ground rectangle) and embreex (both through RaycastScene) give the same hits,
    and the analytic rectangle matches Embree tracing the same two triangles."""
    rng = np.random.default_rng(3)
    meshes = [_ground_quad(-1.8, -60, 60, -40, 40), _ground_quad(-1.0, 5, 9, -2, 2, diagonal=1)]
    for _ in range(8):
        shape = trimesh.creation.icosphere(2, rng.uniform(0.5, 1.5)) if rng.random() < 0.5 else \
            trimesh.creation.box(extents=rng.uniform(0.5, 4.0, 3))
        meshes.append((np.asarray(shape.vertices) + [rng.uniform(-30, 30), rng.uniform(-30, 30), rng.uniform(-1.5, 1.0)],
                       np.asarray(shape.faces)))
    tilted_v, tilted_f = _ground_quad(-1.2, -20, -10, 10, 20)
    tilted_v[2, 2] = -0.2
    meshes.append((tilted_v, tilted_f))
    scenes = {b: RaycastScene(b) for b in BACKENDS}
    for scene in scenes.values():
        for v, f in meshes:
            scene.add_mesh(v, f)
    assert scenes["compiled"].rectangle_ids == scenes["embreex"].rectangle_ids == [0, 1]
    dirs = rng.normal(size=(20_000, 3))
    dirs[:, 2] = -np.abs(dirs[:, 2]) * rng.uniform(0.02, 1.0, len(dirs))
    dirs[::7, 2] *= -1                                                    # some rays go up
    dirs /= np.linalg.norm(dirs, axis=1, keepdims=True)
    origins = rng.uniform([-2, -2, 0.0], [2, 2, 2.0], size=(len(dirs), 3))
    a = scenes["compiled"].cast(origins, dirs)
    b = scenes["embreex"].cast(origins, dirs)
    np.testing.assert_array_equal(a.geom_id, b.geom_id)
    np.testing.assert_array_equal(a.prim_id, b.prim_id)
    np.testing.assert_allclose(a.distance[a.hit], b.distance[b.hit], atol=2e-5, rtol=1e-6)
    assert np.isinf(a.distance[~a.hit]).all()
    np.testing.assert_allclose(a.normal, b.normal, atol=1e-5)
    assert {0, 1, len(meshes) - 1} <= set(np.unique(a.geom_id).tolist()) and (a.geom_id == -1).any()
    on_ground = a.geom_id == 0
    np.testing.assert_allclose(a.normal[on_ground], np.tile([0, 0, 1.0], (on_ground.sum(), 1)))
    points = origins[on_ground] + dirs[on_ground] * a.distance[on_ground, None]
    np.testing.assert_allclose(points[:, 2], -1.8, atol=1e-5)
    assert (np.abs(points[:, 0]) <= 60 + 1e-6).all() and (np.abs(points[:, 1]) <= 40 + 1e-6).all()
    # the same ground traced by Embree as two triangles (a 10 um tilt keeps it out of the analytic path)
    plain = RaycastScene("compiled")
    v, f = meshes[0]
    v = v.copy()
    v[0, 2] -= 1e-5
    plain.add_mesh(v, f)
    assert not plain.rectangle_ids
    c = plain.cast(origins, dirs)
    only_ground = RaycastScene("compiled")
    only_ground.add_mesh(*meshes[0])
    d = only_ground.cast(origins, dirs)
    assert (c.hit != d.hit).mean() < 1e-3                                   # only rays grazing the far edges
    both = c.hit & d.hit
    assert both.sum() > 5000
    # heights of the hit points agree to the tilt (distances differ by up to tilt / |dir_z|)
    np.testing.assert_allclose(c.distance[both] * dirs[both, 2], d.distance[both] * dirs[both, 2], atol=2e-5)


@pytest.mark.parametrize("name", ["vlp16", "hdl64e"])
def test_flat_ground_rings_have_analytic_radii(name):
    sensor = PRESETS[name]
    height = 1.73
    ground = SimObject(np.array([[-500, -500, 0], [500, -500, 0], [500, 500, 0], [-500, 500, 0]], float),
                       np.array([[0, 1, 2], [0, 2, 3]]), Trajectory.static(0, 0, 0, 0))
    world_from_sensor = np.eye(4)
    world_from_sensor[2, 3] = height
    scan = simulate_scan(sensor, [ground], world_from_sensor, realism=Realism.ideal())
    radius = np.hypot(scan.xyz[:, 0], scan.xyz[:, 1])
    elev = np.radians(np.asarray(sensor.elevations_deg))
    expected = height / np.tan(-elev[scan.beam])
    assert (elev[scan.beam] < 0).all()
    np.testing.assert_allclose(radius, expected, rtol=2e-6, atol=1e-4)
    np.testing.assert_allclose(scan.xyz[:, 2], -height, atol=1e-4)
    in_range = (elev < 0) & (height / np.sin(-np.minimum(elev, -1e-9)) <= sensor.max_range)
    assert len(scan) == int(in_range.sum()) * sensor.columns  # every down-looking beam in range returns
    image = range_image(scan)
    assert image.shape == (sensor.beams, sensor.columns)
    assert np.count_nonzero(image) == len(scan)


def test_raycast_benchmark_runs_and_reports_both_backends():
    import os

    from sot_apps.bench.raycast import format_table, run_benchmark

    affinity = os.sched_getaffinity(0) if hasattr(os, "sched_getaffinity") else None
    try:
        result = run_benchmark(None, vehicles=2, repeats=1)
    finally:  # the benchmark pins the process to one core
        if affinity is not None:
            os.sched_setaffinity(0, affinity)
    assert result["backend"] == "compiled" and result["rays"] == 169_600
    assert result["vehicle_hits"] > 100 and 0.5 < result["hit_fraction"] < 1.0
    for key in ("cast_rays_per_s", "embreex_cast_rays_per_s", "raw_rays_per_s", "boxes_rays_per_s", "sweep_rays_per_s"):
        assert result[key] > 0
    table = format_table(result)
    assert "compiled backend (default)" in table and "embreex backend" in table
