"""Parquet (read back with pyarrow), dense npz and CSV: columns, dtypes, invalid samples marked."""

from __future__ import annotations

import csv

import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq
import pytest

from sot_apps.motion_export.tables import av2_object_type, make_scenario, write_csv, write_npz_table, write_parquet
from sot_apps.objects.smoother import smooth_track

from .synthetic import constant_turn, frame_times_ns, make_track

N = 15


@pytest.fixture(scope="module")
def scenario():
    times = frame_times_ns(N, seed=21)
    t = (times - times[0]) * 1e-9
    valid_a = np.ones(N, dtype=bool)
    valid_a[[4, 9]] = False
    a = smooth_track(make_track("car-a", times, constant_turn(t, 7.0, 0.1), valid=valid_a, label="Car"))
    b = smooth_track(make_track("ped-b", times[5:12], constant_turn(t[5:12], 1.2, 0.0), frames=np.arange(5, 12),
                                label="Pedestrian"))
    return make_scenario("synthetic", times, [a, b], observed_steps=10)


# Argoverse 2 motion-forecasting columns and their types (AV2 schema), then the documented extras.
AV2_COLUMNS = [("observed", pa.bool_()), ("track_id", pa.string()), ("object_type", pa.string()),
               ("object_category", pa.int64()), ("timestep", pa.int64()), ("position_x", pa.float64()),
               ("position_y", pa.float64()), ("heading", pa.float64()), ("velocity_x", pa.float64()),
               ("velocity_y", pa.float64()), ("scenario_id", pa.string()), ("start_timestamp", pa.int64()),
               ("end_timestamp", pa.int64()), ("num_timestamps", pa.int64()), ("focal_track_id", pa.string()),
               ("city", pa.string())]
EXTRA_COLUMNS = [("valid", pa.bool_()), ("frame", pa.int64()), ("timestamp_ns", pa.int64()),
                 ("position_z", pa.float64()), ("speed", pa.float64()), ("acceleration", pa.float64()),
                 ("yaw_rate", pa.float64()), ("label", pa.string()), ("flags", pa.string())]


def test_parquet_columns_dtypes_and_invalid_rows(tmp_path, scenario):
    path = tmp_path / "scenario.parquet"
    assert write_parquet(path, scenario) == N + 7
    table = pq.read_table(path)
    assert [(f.name, f.type) for f in table.schema] == AV2_COLUMNS + EXTRA_COLUMNS
    rows = table.to_pylist()
    a_rows = [r for r in rows if r["track_id"] == "car-a"]
    assert [r["timestep"] for r in a_rows] == list(range(N))
    invalid = [r for r in a_rows if not r["valid"]]
    assert [r["timestep"] for r in invalid] == [4, 9]
    for r in invalid:
        assert not r["observed"] and r["flags"] == "no_points"
        assert all(np.isnan(r[c]) for c in ("position_x", "position_y", "heading", "velocity_x", "velocity_y"))
    # observed = valid and timestep < observed_steps (10)
    assert [r["observed"] for r in a_rows] == [r["valid"] and r["timestep"] < 10 for r in a_rows]
    b_rows = [r for r in rows if r["track_id"] == "ped-b"]
    assert [r["timestep"] for r in b_rows] == list(range(5, 12))
    assert {r["object_type"] for r in b_rows} == {"pedestrian"} and {r["object_type"] for r in a_rows} == {"vehicle"}
    # car-a is the focal track (first object), ped-b is valid at 7 of 15 timesteps -> fragment
    assert {r["object_category"] for r in a_rows} == {3} and {r["object_category"] for r in b_rows} == {0}
    assert {r["num_timestamps"] for r in rows} == {N} and {r["focal_track_id"] for r in rows} == {"car-a"}
    valid_speed = np.array([np.hypot(r["velocity_x"], r["velocity_y"]) for r in a_rows if r["valid"]])
    assert np.allclose(valid_speed, 7.0, rtol=0.02)


def test_npz_dense_arrays(tmp_path, scenario):
    path = tmp_path / "scenario.npz"
    write_npz_table(path, scenario)
    with np.load(path) as z:
        data = {k: z[k] for k in z.files}
    per_step = ["x", "y", "z", "length", "width", "height", "heading", "velocity_x", "velocity_y", "speed",
                "acceleration", "yaw_rate"]
    for name in per_step:
        assert data[name].dtype == np.float32 and data[name].shape == (2, N), name
    assert data["valid"].dtype == np.bool_ and data["valid"].shape == (2, N)
    assert data["timestamps_ns"].dtype == np.int64 and data["timestamps_ns"].shape == (N,)
    assert data["frames"].dtype == np.int64 and list(data["frames"]) == list(range(N))
    assert data["object_id"].dtype.kind == "U" and list(data["object_id"]) == ["car-a", "ped-b"]
    assert list(data["object_type"]) == ["vehicle", "pedestrian"]
    expected_valid = np.zeros((2, N), dtype=bool)
    expected_valid[0] = True
    expected_valid[0, [4, 9]] = False
    expected_valid[1, 5:12] = True
    assert np.array_equal(data["valid"], expected_valid)
    for name in per_step:
        assert np.isnan(data[name][~expected_valid]).all(), name
        assert np.isfinite(data[name][expected_valid]).all(), name
    assert np.allclose(data["length"][expected_valid], 4.5)
    assert np.allclose(np.hypot(data["velocity_x"][1, 5:12], data["velocity_y"][1, 5:12]), 1.2, rtol=0.02)


def test_csv_rows(tmp_path, scenario):
    path = tmp_path / "motion.csv"
    assert write_csv(path, scenario.objects) == N + 7
    with open(path, newline="") as handle:
        rows = list(csv.DictReader(handle))
    assert len(rows) == N + 7
    bad = [r for r in rows if r["valid"] == "0"]
    assert [(r["object_id"], r["frame"], r["flags"], r["x"]) for r in bad] == [
        ("car-a", "4", "no_points", ""), ("car-a", "9", "no_points", "")]
    assert np.isclose(float(rows[0]["speed"]), 7.0, rtol=0.02)


@pytest.mark.parametrize("label,expected", [("Car", "vehicle"), ("Pickup Truck", "vehicle"), ("Bus", "bus"),
                                            ("Pedestrian with Object", "pedestrian"), ("Motorcycle", "motorcyclist"),
                                            ("Cones", "construction"), ("", "unknown"), ("Towed Object", "unknown")])
def test_av2_object_types(label, expected):
    assert av2_object_type(label) == expected
