"""Each schema rejects malformed documents with a message naming the field; valid documents pass."""

from __future__ import annotations

import copy
import json

import numpy as np
import pytest

from sot_apps.errors import InputError
from sot_apps.schemas import load_json_validated, schema_names, validate


@pytest.fixture(scope="module")
def sequence_doc(tiny_dir) -> dict:
    return json.loads((tiny_dir / "sequence.json").read_text())


def track_doc() -> dict:
    return {"schema_version": 1, "sequence": "tiny", "object_id": "car-move", "label": "Car",
            "size": {"length": 4.5, "width": 1.8, "height": 1.5}, "start_frame": 0, "end_frame": 1,
            "init_box": {"x": 1.0, "y": 2.0, "z": 0.7, "heading": 0.1, "length": 4.5, "width": 1.8, "height": 1.5},
            "config": {"preset": "default", "mode": "online"}, "shape": "shape.ply",
            "frames": [{"frame": 0, "timestamp_ns": 10, "state": {"x": 1.0, "y": 2.0, "z": 0.7, "heading": 0.1},
                        "num_points": 120, "quality": 0.9, "flags": [], "time_ms": 3.5},
                       {"frame": 1, "timestamp_ns": 20, "state": {"x": 1.8, "y": 2.0, "z": 0.7, "heading": 0.1},
                        "num_points": 0, "quality": 0.0, "flags": ["no_points", "prior_only"]}]}


def _set(doc: dict, path: list, value) -> dict:
    doc = copy.deepcopy(doc)
    target = doc
    for part in path[:-1]:
        target = target[part]
    target[path[-1]] = value
    return doc


def _delete(doc: dict, path: list) -> dict:
    doc = copy.deepcopy(doc)
    target = doc
    for part in path[:-1]:
        target = target[part]
    del target[path[-1]]
    return doc


def test_every_shipped_schema_is_a_valid_2020_12_schema():
    from jsonschema import Draft202012Validator
    from jsonschema.exceptions import SchemaError

    from sot_apps.schemas import load_schema

    assert len(schema_names()) >= 10
    for name in schema_names():
        Draft202012Validator.check_schema(load_schema(name))
    with pytest.raises(SchemaError):   # the check itself bites
        Draft202012Validator.check_schema({"type": "no-such-type"})


def test_schemas_are_versioned_and_have_ids():
    from sot_apps.schemas import load_schema

    assert {"sequence", "track"} <= set(schema_names())
    for name in ("sequence", "track"):
        schema = load_schema(name)
        assert schema["$id"].endswith(f"/{name}/{schema['version']}.schema.json")
        accepted = schema["properties"]["schema_version"]
        assert accepted.get("const", schema["version"]) == schema["version"]
        assert max(accepted.get("enum", [schema["version"]])) == schema["version"]


def test_valid_documents_pass(sequence_doc):
    validate("sequence", sequence_doc, "sequence.json")
    validate("track", track_doc(), "track.json")


SEQUENCE_CASES = [
    ("missing", ["frames", 2, "timestamp_ns"], None, "frames[2].timestamp_ns: required field is missing"),
    ("missing", ["ego_from_lidar"], None, "ego_from_lidar: required field is missing"),
    ("missing", ["cameras", "front_camera", "K"], None, "cameras.front_camera.K: required field is missing"),
    ("type", ["frames", 1, "timestamp_ns"], 1.5, "frames[1].timestamp_ns: wrong type"),
    ("type", ["frames", 1, "timestamp_ns"], "100", "frames[1].timestamp_ns: wrong type"),
    ("type", ["frames", 0, "boxes", 0, "length"], "long", "frames[0].boxes[0].length: wrong type"),
    ("type", ["cameras", "front_camera", "width"], 64.5, "cameras.front_camera.width: wrong type"),
    ("nan", ["frames", 3, "world_from_ego", 0, 3], float("nan"), "frames[3].world_from_ego[0][3]: non-finite"),
    ("nan", ["frames", 0, "boxes", 1, "heading"], float("inf"), "frames[0].boxes[1].heading: non-finite"),
    ("nan", ["cameras", "front_camera", "K", 0, 0], float("-inf"), "cameras.front_camera.K[0][0]: non-finite"),
    ("unknown", ["frames", 0, "colour"], "red", "frames[0].colour: unknown field"),
    ("unknown", ["extra"], 1, "extra: unknown field"),
    ("value", ["schema_version"], 3, "schema_version"),
    ("value", ["frames", 0, "world_from_ego"], [[1, 0, 0, 0]] * 3, "frames[0].world_from_ego"),
    ("value", ["frames", 0, "points"], "../elsewhere.npz", "frames[0].points"),
]


@pytest.mark.parametrize("kind,path,value,message", SEQUENCE_CASES, ids=[f"{c[0]}-{c[3].split(':')[0]}" for c in SEQUENCE_CASES])
def test_sequence_schema_rejects(sequence_doc, kind, path, value, message):
    bad = _delete(sequence_doc, path) if kind == "missing" else _set(sequence_doc, path, value)
    with pytest.raises(InputError) as info:
        validate("sequence", bad, "somewhere/sequence.json")
    assert info.value.path == "somewhere/sequence.json"
    assert message in info.value.problem
    assert "\n" not in str(info.value)


TRACK_CASES = [
    ("missing", ["size", "width"], None, "size.width: required field is missing"),
    ("missing", ["frames", 1, "quality"], None, "frames[1].quality: required field is missing"),
    ("missing", ["sequence"], None, "sequence: required field is missing"),
    ("missing", ["config", "preset"], None, "config.preset: required field is missing"),
    ("type", ["frames", 0, "num_points"], 3.5, "frames[0].num_points: wrong type"),
    ("type", ["frames", 0, "flags"], "no_points", "frames[0].flags: wrong type"),
    ("type", ["object_id"], 17, "object_id: wrong type"),
    ("nan", ["frames", 1, "state", "heading"], float("nan"), "frames[1].state.heading: non-finite"),
    ("nan", ["size", "length"], float("inf"), "size.length: non-finite"),
    ("unknown", ["frames", 0, "state", "roll"], 0.0, "frames[0].state.roll: unknown field"),
    ("value", ["frames", 0, "quality"], 1.5, "frames[0].quality"),
    ("value", ["size", "height"], 0.0, "size.height"),
    ("value", ["shape"], "../shape.ply", "shape"),
]


@pytest.mark.parametrize("kind,path,value,message", TRACK_CASES, ids=[f"{c[0]}-{c[3].split(':')[0]}" for c in TRACK_CASES])
def test_track_schema_rejects(kind, path, value, message):
    doc = track_doc()
    bad = _delete(doc, path) if kind == "missing" else _set(doc, path, value)
    with pytest.raises(InputError) as info:
        validate("track", bad, "t/track.json")
    assert message in info.value.problem


def test_track_config_is_open_but_typed():
    doc = track_doc()
    doc["config"]["anything"] = {"nested": [1, 2]}
    validate("track", doc, "t/track.json")
    doc["config"]["mode"] = "sometimes"
    with pytest.raises(InputError, match=r"config\.mode"):
        validate("track", doc, "t/track.json")


def test_numpy_nan_is_rejected_too():
    doc = track_doc()
    doc["frames"][0]["quality"] = np.float64("nan")
    with pytest.raises(InputError, match=r"frames\[0\]\.quality: non-finite"):
        validate("track", doc, "t/track.json")


def test_load_json_validated_errors(tmp_path, sequence_doc):
    with pytest.raises(InputError, match="file is missing") as info:
        load_json_validated(tmp_path / "nope.json", "sequence")
    assert info.value.path == str(tmp_path / "nope.json")
    bad = tmp_path / "bad.json"
    bad.write_text('{"id": "x", "frames": [')
    with pytest.raises(InputError, match="not valid JSON"):
        load_json_validated(bad, "sequence")
    nan = tmp_path / "nan.json"
    doc = _set(sequence_doc, ["frames", 4, "world_from_ego", 1, 1], float("nan"))
    nan.write_text(json.dumps(doc))  # writes the literal token NaN
    assert "NaN" in nan.read_text()
    with pytest.raises(InputError, match=r"frames\[4\]\.world_from_ego\[1\]\[1\]: non-finite"):
        load_json_validated(nan, "sequence")
