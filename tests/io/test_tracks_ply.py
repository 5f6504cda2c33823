"""Track files and PLY: round trips, checked against trimesh as an independent PLY reader."""

from __future__ import annotations

import json
from dataclasses import replace

import numpy as np
import pytest
import trimesh

from sot_apps.errors import InputError
from sot_apps.io.object_track import ObjectTrack
from sot_apps.io.ply import read_ply, read_ply_mesh, read_ply_points, write_ply_mesh, write_ply_points
from sot_apps.io.tracks import TrackHeader, read_track, write_track
from tracker.geometry import Box


def test_ply_points_read_by_trimesh(tmp_path):
    rng = np.random.default_rng(3)
    xyz = rng.normal(size=(500, 3)) * 10
    intensity = rng.uniform(0, 255, 500)
    label = rng.integers(0, 7, 500).astype(np.uint8)
    normals = rng.normal(size=(500, 3))
    path = tmp_path / "p.ply"
    write_ply_points(path, xyz, intensity=intensity, label=label, nx=normals[:, 0], ny=normals[:, 1], nz=normals[:, 2])
    cloud = trimesh.load(path)
    assert isinstance(cloud, trimesh.PointCloud)
    np.testing.assert_array_equal(np.asarray(cloud.vertices), xyz.astype(np.float32).astype(np.float64))
    props = read_ply(path)
    np.testing.assert_array_equal(props["intensity"], intensity.astype(np.float32))
    np.testing.assert_array_equal(props["label"], label)
    assert props["label"].dtype == np.uint8
    np.testing.assert_array_equal(read_ply_points(path), xyz.astype(np.float32).astype(np.float64))


def test_read_ply_of_trimesh_files(tmp_path):
    """Our reader reads what trimesh writes (binary and ascii)."""
    rng = np.random.default_rng(4)
    xyz = rng.normal(size=(50, 3))
    for encoding in ("binary", "ascii"):
        path = tmp_path / f"{encoding}.ply"
        path.write_bytes(trimesh.PointCloud(xyz).export(file_type="ply", encoding=encoding))
        np.testing.assert_allclose(read_ply_points(path), xyz, rtol=1e-6, atol=1e-6)


def test_mesh_round_trip(tmp_path):
    box = trimesh.creation.box(extents=(4.0, 2.0, 1.5))
    write_ply_mesh(tmp_path / "m.ply", box.vertices, box.faces)
    vertices, faces = read_ply_mesh(tmp_path / "m.ply")
    np.testing.assert_allclose(vertices, box.vertices)
    np.testing.assert_array_equal(faces, box.faces)
    assert trimesh.load(tmp_path / "m.ply").volume == pytest.approx(12.0)


def test_ply_errors(tmp_path):
    path = tmp_path / "t.ply"
    write_ply_points(path, np.ones((100, 3)))
    path.write_bytes(path.read_bytes()[:-10])
    with pytest.raises(InputError, match="truncated"):
        read_ply_points(path)
    (tmp_path / "x.ply").write_text("hello")
    with pytest.raises(InputError, match="not a PLY"):
        read_ply_points(tmp_path / "x.ply")
    with pytest.raises(InputError, match="missing"):
        read_ply_points(tmp_path / "none.ply")


def make_track(shape: np.ndarray | None = None) -> tuple[TrackHeader, ObjectTrack]:
    frames = range(3, 8)
    track = ObjectTrack.from_states(
        "car-move", "Car", (4.5, 1.8, 1.5), frames, [1_000 + k * 100_000_000 for k in frames],
        [[1.0 + k, 2.0, 0.7, 0.1 * k] for k in frames], None, [["low_points"] if k == 5 else [] for k in frames],
        scores=[0.5] * 5, num_points=[100 - k for k in frames], time_ms=[1.5 * k for k in frames],
        shape_points=np.zeros((3, 3)) if shape is None else shape)
    header = TrackHeader(sequence="tiny", start_frame=3, end_frame=7, init_box=Box(4.0, 2.0, 0.7, 0.3, 4.4, 1.7, 1.5),
                         config={"preset": "default", "refined": True, "gate": np.float32(2.5)})
    return header, track


def test_track_round_trip(tmp_path):
    shape = np.random.default_rng(5).normal(size=(300, 3))
    header, track = make_track(shape)
    write_track(tmp_path / "t", header, track)
    assert sorted(p.name for p in (tmp_path / "t").iterdir()) == ["shape.ply", "track.json"]
    back_header, back = read_track(tmp_path / "t")
    assert back_header == TrackHeader("tiny", 3, 7, header.init_box, {"preset": "default", "refined": True,
                                                                      "gate": 2.5})
    assert back.object_id == "car-move" and back.label == "Car" and back.size == (4.5, 1.8, 1.5)
    for column in ("frames", "timestamps_ns", "boxes", "scores", "num_points", "time_ms", "valid"):
        np.testing.assert_array_equal(getattr(back, column), getattr(track, column), err_msg=column)
    assert back.flags == track.flags and back.config == {"tracker": back_header.config}
    np.testing.assert_allclose(back.shape_points, shape, atol=1e-5)
    # the shape is a PLY any reader understands
    np.testing.assert_allclose(np.asarray(trimesh.load(tmp_path / "t" / "shape.ply").vertices), shape, atol=1e-5)
    # json path works too; boxes combine state and size
    again_header, again = read_track(tmp_path / "t" / "track.json")
    assert again.box_at(5) == Box(6.0, 2.0, 0.7, 0.1 * 5, 4.5, 1.8, 1.5) and again_header == back_header
    assert again.source == str(tmp_path / "t" / "track.json")


def test_track_write_refuses_bad_track_and_writes_nothing(tmp_path):
    header, track = make_track()
    scores = track.scores.copy()
    scores[1] = np.nan
    with pytest.raises(InputError, match=r"frames\[1\]\.quality: non-finite"):
        write_track(tmp_path / "t", header, replace(track, scores=scores))
    assert not (tmp_path / "t").exists()
    with pytest.raises(ValueError, match="needs timestamps_ns, scores"):
        write_track(tmp_path / "t", header, replace(track, num_points=None))
    boxes = track.boxes.copy()
    boxes[2, 4] = 5.0
    with pytest.raises(ValueError, match="level boxes of one size"):
        write_track(tmp_path / "t", header, replace(track, boxes=boxes))
    assert not (tmp_path / "t").exists()


def test_read_track_validates(tmp_path):
    write_track(tmp_path / "t", *make_track())
    doc = json.loads((tmp_path / "t" / "track.json").read_text())
    doc["frames"][0].pop("num_points")
    (tmp_path / "t" / "track.json").write_text(json.dumps(doc))
    with pytest.raises(InputError, match=r"frames\[0\]\.num_points: required field is missing"):
        read_track(tmp_path / "t")
    write_track(tmp_path / "u", *make_track())
    (tmp_path / "u" / "shape.ply").unlink()
    with pytest.raises(InputError, match="PLY file is missing"):
        read_track(tmp_path / "u")
    write_track(tmp_path / "v", *make_track())
    doc = json.loads((tmp_path / "v" / "track.json").read_text())
    doc["frames"][2]["frame"] = doc["frames"][1]["frame"]
    (tmp_path / "v" / "track.json").write_text(json.dumps(doc))
    with pytest.raises(InputError, match="appears more than once"):
        read_track(tmp_path / "v")
    doc["frames"][2]["frame"] = 9
    doc["frames"][2]["timestamp_ns"] = 1   # before the frames it follows
    (tmp_path / "v" / "track.json").write_text(json.dumps(doc))
    with pytest.raises(InputError, match=r"track\.json.*strictly increasing"):
        read_track(tmp_path / "v")


def test_ply_round_trip_property(tmp_path):
    from hypothesis import given, settings
    from hypothesis import strategies as st
    from hypothesis.extra.numpy import arrays

    @settings(max_examples=25, deadline=None)
    @given(arrays(np.float32, st.tuples(st.integers(0, 40), st.just(3)),
                  elements=st.floats(-1e4, 1e4, allow_nan=False, width=32)))
    def check(xyz):
        path = tmp_path / "h.ply"
        write_ply_points(path, xyz, value=np.arange(len(xyz), dtype=np.int32))
        np.testing.assert_array_equal(read_ply_points(path), xyz.astype(np.float64))
        np.testing.assert_array_equal(read_ply(path)["value"], np.arange(len(xyz)))

    check()
