"""The one numpy -> JSON converter (sot_apps.io.jsonable.json_safe): its behaviour on non-finite values is null."""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np

from sot_apps.io.jsonable import json_safe


def test_numpy_values_paths_and_tuples_become_plain_json():
    value = {1: np.float32(0.5), "a": (np.int64(3), np.bool_(True)), "p": Path("x/y.json"),
             "arr": np.arange(3, dtype=np.int16), "nested": [{"m": np.eye(2)}], "s": "text", "none": None}
    out = json_safe(value)
    assert out == {"1": 0.5, "a": [3, True], "p": "x/y.json", "arr": [0, 1, 2], "nested": [{"m": [[1.0, 0.0],
                   [0.0, 1.0]]}], "s": "text", "none": None}
    assert type(out["a"][0]) is int and type(out["a"][1]) is bool and type(out["1"]) is float
    assert json.loads(json.dumps(out, allow_nan=False)) == out


def test_non_finite_numbers_become_null_everywhere():
    out = json_safe({"nan": float("nan"), "inf": np.float64(np.inf), "arr": np.array([1.0, -np.inf, np.nan]),
                     "ok": 2.5})
    assert out == {"nan": None, "inf": None, "arr": [1.0, None, None], "ok": 2.5}
    assert not any(isinstance(v, float) and not math.isfinite(v) for v in out["arr"] if v is not None)
