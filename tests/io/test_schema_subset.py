"""The compiled schema check (sot_apps.schema_subset) decides exactly as jsonschema's Draft202012Validator on every
shipped schema, for documents generated from the schema and then broken in random places (wrong types, True for 1,
1.0 for 1, values on and beyond the bounds, missing and extra keys, strings outside the patterns, repeated flags);
it never passes what jsonschema rejects, also for values a JSON parser does not make (it leaves those to
jsonschema); and validate() still words jsonschema's error."""

from __future__ import annotations

import copy
import json
import random
import re

import numpy as np
import pytest
from jsonschema import Draft202012Validator

from sot_apps.errors import InputError
from sot_apps.schema_subset import compile_schema
from sot_apps.schemas import load_schema, schema_names, validate

STRINGS = ["car", "Car", "a_b", "A-1.b", "shape.ply", "x/shape.ply", "../up", "a/../b", "/abs", "", "no_points",
           "prior_only", "online", "lag", "offline", "dense", "front_camera", "ümlaut", "two words", "..", "0"]
TRICKY = [True, False, None, 0, 1, -1, 1.0, 0.5, -0.0, 2.0 ** 40, 1e-9, 7, 64, "", "x", "no_points", [], [1], ["a", "a"],
          {}, {"x": 1.0}]


def _resolve(schema: dict, root: dict) -> dict:
    while "$ref" in schema:
        schema = {**root["$defs"][schema["$ref"].split("/")[-1]], **{k: v for k, v in schema.items() if k != "$ref"}}
    return schema


def _number(schema: dict, rng: random.Random, integer: bool):
    low = max(schema.get("minimum", -50), schema.get("exclusiveMinimum", -51) + 1)
    high = min(schema.get("maximum", 50), schema.get("exclusiveMaximum", 51) - 1)
    if high < low:
        low, high = schema.get("minimum", schema.get("exclusiveMinimum", 0)), schema.get("maximum", 1)
    if integer:
        value = rng.randint(int(np.ceil(low)), int(np.floor(high))) if np.ceil(low) <= np.floor(high) else int(low)
        return float(value) if rng.random() < 0.1 else value   # 3.0 is an integer too
    return rng.choice([low, high, rng.uniform(low, high), (low + high) / 2])


def _generate(schema, root: dict, rng: random.Random, depth: int = 0):
    """A document for ``schema``, valid most of the time."""
    schema = _resolve(schema, root)
    if "const" in schema:
        return schema["const"]
    if "enum" in schema:
        return rng.choice(schema["enum"])
    if "anyOf" in schema:
        return _generate(rng.choice(schema["anyOf"]), root, rng, depth)
    types = schema.get("type", rng.choice(["string", "number", "object"]))
    kind = rng.choice(types) if isinstance(types, list) else types
    if kind == "object":
        props = schema.get("properties", {})
        keys = [k for k in props if k in schema.get("required", []) or (depth < 6 and rng.random() < 0.6)]
        return {k: _generate(props[k], root, rng, depth + 1) for k in keys}
    if kind == "array":
        prefix = [_generate(s, root, rng, depth + 1) for s in schema.get("prefixItems", [])]
        count = rng.randint(schema.get("minItems", 0), min(schema.get("maxItems", 4), schema.get("minItems", 0) + 4))
        count = max(count - len(prefix), 0)
        items = schema.get("items", {"type": "number"})
        rest = [_generate(items, root, rng, depth + 1) for _ in range(count)] if depth < 8 else []
        if schema.get("uniqueItems"):
            rest = list(dict.fromkeys(rest)) if all(isinstance(r, str) for r in rest) else rest
        return prefix + rest
    if kind == "string":
        pool = [s for s in STRINGS if len(s) >= schema.get("minLength", 0)
                and ("pattern" not in schema or re.search(schema["pattern"], s))]
        return rng.choice(pool or STRINGS)
    if kind in ("number", "integer"):
        return _number(schema, rng, kind == "integer")
    if kind == "boolean":
        return rng.random() < 0.5
    return None


def _paths(doc, prefix=()):
    yield prefix
    if isinstance(doc, dict):
        for key, value in doc.items():
            yield from _paths(value, prefix + (key,))
    elif isinstance(doc, list):
        for i, value in enumerate(doc):
            yield from _paths(value, prefix + (i,))


def _break(doc, rng: random.Random):
    """``doc`` with one random change: a value replaced, a key removed or added, an item repeated."""
    doc = copy.deepcopy(doc)
    paths = list(_paths(doc))[1:]
    if not paths:
        return rng.choice(TRICKY)
    path = rng.choice(paths)
    parent = doc
    for part in path[:-1]:
        parent = parent[part]
    action = rng.random()
    if action < 0.6:
        parent[path[-1]] = copy.deepcopy(rng.choice(TRICKY + STRINGS))
    elif action < 0.75:
        del parent[path[-1]]
    elif action < 0.9 and isinstance(parent, dict):
        parent[rng.choice(["extra", "x", "notes"])] = rng.choice(TRICKY)
    elif isinstance(parent, list):
        parent.append(copy.deepcopy(parent[path[-1]]))
    else:
        value = parent[path[-1]]
        parent[path[-1]] = float(value) if type(value) is int else value
    return doc


@pytest.mark.parametrize("name", schema_names())
def test_compiled_check_decides_as_jsonschema(name):
    schema = load_schema(name)
    check = compile_schema(schema)
    assert check is not None, f"{name}: the shipped schemas stay inside the compiled subset"
    reference = Draft202012Validator(schema)
    rng = random.Random(name)
    valid = invalid = 0
    for i in range(300):
        doc = _generate(schema, schema, rng)
        for _ in range(i % 3):   # a third of them as generated, the rest broken once or twice
            doc = _break(doc, rng)
        doc = json.loads(json.dumps(doc))   # what a JSON parser makes
        expected = reference.is_valid(doc)
        assert check(doc) == expected, (name, doc)
        valid, invalid = valid + expected, invalid + (not expected)
    assert valid >= 50 and invalid >= 50, (name, valid, invalid)   # both sides exercised


def test_values_no_json_parser_makes_are_left_to_jsonschema():
    schema = {"type": "object", "properties": {"n": {"type": "integer", "minimum": 0}, "v": {"type": "array"},
                                               "s": {"type": "string"}}}
    check = compile_schema(schema)
    for doc in ({"n": np.int64(3)}, {"n": np.float64(2.0)}, {"v": (1, 2)}, {"s": np.str_("a")}, {1: 2}):
        assert check(doc) is False   # not judged here: jsonschema decides
    assert check({"n": 3, "v": [1], "s": "a"}) is True
    assert Draft202012Validator(schema).is_valid({"v": (1, 2)}) is False   # a tuple is no JSON array for jsonschema
    assert compile_schema({"type": "object", "oneOf": [{"type": "object"}]}) is None   # outside the subset
    assert compile_schema({"properties": {"a": True}}) is None
    assert compile_schema({"enum": [[1, 2]]}) is None


def test_true_is_not_one_and_integral_floats_are_integers():
    check = compile_schema({"type": "object", "properties": {"v": {"const": 1}, "i": {"type": "integer"},
                                                             "f": {"type": "array", "uniqueItems": True}}})
    assert check({"v": 1}) and check({"v": 1.0}) and not check({"v": True})
    assert check({"i": 3.0}) and not check({"i": 3.5}) and not check({"i": True})
    assert check({"f": ["a", "b"]}) and not check({"f": ["a", "a"]})


def test_validate_words_jsonschemas_error_for_a_failing_document():
    doc = {"schema_version": 1, "sequence": "s", "camera": "c", "mode": "dense", "source": "tracks",
           "instances": [], "pairs": [], "objects": []}
    validate("flow_stats", doc, "stats.json")
    with pytest.raises(InputError, match=r"mode: .*flow_stats schema"):
        validate("flow_stats", {**doc, "mode": "sideways"}, "stats.json")
    with pytest.raises(InputError, match="pairs: required field is missing"):
        validate("flow_stats", {k: v for k, v in doc.items() if k != "pairs"}, "stats.json")
