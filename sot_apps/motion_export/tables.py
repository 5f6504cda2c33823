"""Forecasting tables from smoothed kinematics: AV2-style parquet, Waymo-style dense npz, CSV.

Column lists and dtypes are the contract documented in docs/motion-export.md; tests check them.
Invalid samples (the tracker flagged the frame, or a gap in the annotations) keep their row (parquet,
CSV) or cell (npz) with ``valid = False`` and NaN values; AV2's ``observed`` is False for them.
"""

from __future__ import annotations

import csv
import io
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..errors import InputError
from ..io.atomic import atomic_path, write_npz, write_text
from ..io.object_track import ObjectTrack

__all__ = ["Scenario", "make_scenario", "av2_object_type", "PARQUET_COLUMNS", "NPZ_ARRAYS", "CSV_COLUMNS",
           "write_parquet", "write_npz_table", "write_csv", "TRACK_CATEGORY"]

# Argoverse 2 TrackCategory values.
TRACK_CATEGORY = {"TRACK_FRAGMENT": 0, "UNSCORED_TRACK": 1, "SCORED_TRACK": 2, "FOCAL_TRACK": 3}

# name -> pyarrow type name. The first ten are AV2's motion-forecasting columns, then AV2's
# scenario-level columns, then this project's extras.
PARQUET_COLUMNS: dict[str, str] = {
    "observed": "bool",
    "track_id": "string",
    "object_type": "string",
    "object_category": "int64",
    "timestep": "int64",
    "position_x": "double",
    "position_y": "double",
    "heading": "double",
    "velocity_x": "double",
    "velocity_y": "double",
    "scenario_id": "string",
    "start_timestamp": "int64",
    "end_timestamp": "int64",
    "num_timestamps": "int64",
    "focal_track_id": "string",
    "city": "string",
    "valid": "bool",
    "frame": "int64",
    "timestamp_ns": "int64",
    "position_z": "double",
    "speed": "double",
    "acceleration": "double",
    "yaw_rate": "double",
    "label": "string",
    "flags": "string",
}

# name -> numpy dtype string; shape (O,) per object, (T,) per timestep, (O, T) per object and timestep.
NPZ_ARRAYS: dict[str, tuple[str, str]] = {
    "object_id": ("U", "(O,)"),
    "object_type": ("U", "(O,)"),
    "label": ("U", "(O,)"),
    "timestamps_ns": ("int64", "(T,)"),
    "frames": ("int64", "(T,)"),
    "x": ("float32", "(O, T)"),
    "y": ("float32", "(O, T)"),
    "z": ("float32", "(O, T)"),
    "length": ("float32", "(O, T)"),
    "width": ("float32", "(O, T)"),
    "height": ("float32", "(O, T)"),
    "heading": ("float32", "(O, T)"),
    "velocity_x": ("float32", "(O, T)"),
    "velocity_y": ("float32", "(O, T)"),
    "speed": ("float32", "(O, T)"),
    "acceleration": ("float32", "(O, T)"),
    "yaw_rate": ("float32", "(O, T)"),
    "valid": ("bool", "(O, T)"),
}

CSV_COLUMNS = ["object_id", "label", "frame", "timestamp_ns", "valid", "flags", "x", "y", "z", "heading",
               "velocity_x", "velocity_y", "speed", "acceleration", "yaw_rate", "position_std", "heading_std",
               "speed_std", "yaw_rate_std"]

_AV2_TYPES = [
    ("bus", "bus"), ("pedestrian", "pedestrian"), ("motorcycl", "motorcyclist"), ("bicycl", "cyclist"),
    ("cyclist", "cyclist"), ("cone", "construction"), ("construction", "construction"), ("barrier", "static"),
    ("sign", "static"), ("towed", "unknown"), ("animal", "unknown"),
    ("car", "vehicle"), ("truck", "vehicle"), ("van", "vehicle"), ("vehicle", "vehicle"), ("suv", "vehicle"),
    ("trailer", "vehicle"), ("tram", "vehicle"),
]


def av2_object_type(label: str) -> str:
    """Map a dataset label (PandaSet, KITTI, nuScenes style) onto Argoverse 2's object_type values."""
    text = label.strip().lower()
    if not text:
        return "unknown"
    for key, value in _AV2_TYPES:
        if key in text:
            return value
    return "unknown"


@dataclass
class Scenario:
    """All objects on a common timestep axis (the frames first..last of any object)."""

    scenario_id: str
    frames: np.ndarray          # (T,) int64 sequence frames
    timestamps_ns: np.ndarray   # (T,) int64
    objects: list[ObjectTrack]
    focal_track_id: str
    observed_steps: int | None = None
    city: str = "unknown"

    def category(self, k: ObjectTrack) -> int:
        """AV2 category: FOCAL for the focal track; SCORED if valid at every timestep of the scenario;
        UNSCORED if valid at >= 10 timesteps; otherwise TRACK_FRAGMENT."""
        if k.object_id == self.focal_track_id:
            return TRACK_CATEGORY["FOCAL_TRACK"]
        n_valid = int(k.valid.sum())
        if n_valid == len(self.frames):
            return TRACK_CATEGORY["SCORED_TRACK"]
        return TRACK_CATEGORY["UNSCORED_TRACK"] if n_valid >= 10 else TRACK_CATEGORY["TRACK_FRAGMENT"]

    def observed(self, k: ObjectTrack) -> np.ndarray:
        steps = k.frames - self.frames[0]
        limit = len(self.frames) if self.observed_steps is None else self.observed_steps
        return k.valid & (steps < limit)


def make_scenario(scenario_id: str, sequence_timestamps_ns: np.ndarray, objects: list[ObjectTrack],
                  focal_track_id: str | None = None, observed_steps: int | None = None) -> Scenario:
    """Scenario over the frames spanned by ``objects``; ``sequence_timestamps_ns`` indexed by frame."""
    if objects:
        lo = min(int(k.frames[0]) for k in objects)
        hi = max(int(k.frames[-1]) for k in objects)
    else:
        lo, hi = 0, len(sequence_timestamps_ns) - 1
    frames = np.arange(lo, hi + 1, dtype=np.int64)
    focal = focal_track_id if focal_track_id is not None else (objects[0].object_id if objects else "")
    return Scenario(scenario_id=scenario_id, frames=frames,
                    timestamps_ns=np.asarray(sequence_timestamps_ns, dtype=np.int64)[frames],
                    objects=objects, focal_track_id=focal, observed_steps=observed_steps)


def _parquet_columns(scenario: Scenario) -> dict[str, list | np.ndarray]:
    cols: dict[str, list] = {name: [] for name in PARQUET_COLUMNS}
    start, end = int(scenario.timestamps_ns[0]), int(scenario.timestamps_ns[-1])
    for k in scenario.objects:
        n = len(k)
        cols["observed"].append(scenario.observed(k))
        cols["track_id"].append([k.object_id] * n)
        cols["object_type"].append([av2_object_type(k.label)] * n)
        cols["object_category"].append(np.full(n, scenario.category(k), dtype=np.int64))
        cols["timestep"].append(k.frames - scenario.frames[0])
        cols["position_x"].append(k.boxes[:, 0])
        cols["position_y"].append(k.boxes[:, 1])
        cols["heading"].append(k.boxes[:, 3])
        cols["velocity_x"].append(k.velocity[:, 0])
        cols["velocity_y"].append(k.velocity[:, 1])
        cols["scenario_id"].append([scenario.scenario_id] * n)
        cols["start_timestamp"].append(np.full(n, start, dtype=np.int64))
        cols["end_timestamp"].append(np.full(n, end, dtype=np.int64))
        cols["num_timestamps"].append(np.full(n, len(scenario.frames), dtype=np.int64))
        cols["focal_track_id"].append([scenario.focal_track_id] * n)
        cols["city"].append([scenario.city] * n)
        cols["valid"].append(k.valid)
        cols["frame"].append(k.frames)
        cols["timestamp_ns"].append(k.timestamps_ns)
        cols["position_z"].append(k.boxes[:, 2])
        cols["speed"].append(k.speed)
        cols["acceleration"].append(k.acceleration)
        cols["yaw_rate"].append(k.yaw_rate)
        cols["label"].append([k.label] * n)
        cols["flags"].append([",".join(f) for f in k.flags])
    out: dict[str, list | np.ndarray] = {}
    for name, parts in cols.items():
        if PARQUET_COLUMNS[name] == "string":
            out[name] = [s for part in parts for s in part]
        else:
            out[name] = np.concatenate(parts) if parts else np.zeros(0)
    return out


def write_parquet(path: str | Path, scenario: Scenario) -> int:
    """All objects of the scenario in ONE parquet file (as AV2 does per scenario); returns the row count.

    Rows are sorted by track then timestep (AV2 order). Needs pyarrow.
    """
    try:
        import pyarrow as pa
        import pyarrow.parquet as pq
    except ImportError as exc:
        raise InputError(path, "writing parquet needs pyarrow (pip install pyarrow)") from exc

    columns = _parquet_columns(scenario)
    types = {"bool": pa.bool_(), "string": pa.string(), "int64": pa.int64(), "double": pa.float64()}
    schema = pa.schema([(name, types[type_name]) for name, type_name in PARQUET_COLUMNS.items()])
    arrays = []
    for name, type_name in PARQUET_COLUMNS.items():
        values = columns[name]
        if type_name == "double":
            arrays.append(pa.array(np.asarray(values, dtype=np.float64), type=pa.float64()))
        elif type_name == "int64":
            arrays.append(pa.array(np.asarray(values, dtype=np.int64), type=pa.int64()))
        elif type_name == "bool":
            arrays.append(pa.array(np.asarray(values, dtype=bool), type=pa.bool_()))
        else:
            arrays.append(pa.array(list(values), type=pa.string()))
    table = pa.Table.from_arrays(arrays, schema=schema)
    with atomic_path(path) as tmp:
        pq.write_table(table, tmp)
    return table.num_rows


def dense_arrays(scenario: Scenario) -> dict[str, np.ndarray]:
    """Waymo-motion-style dense arrays (see NPZ_ARRAYS); NaN and valid=False where invalid or absent."""
    O, T = len(scenario.objects), len(scenario.frames)
    out: dict[str, np.ndarray] = {}
    for name, (dtype, shape) in NPZ_ARRAYS.items():
        if shape == "(O, T)":
            out[name] = np.zeros((O, T), dtype=bool) if dtype == "bool" else np.full((O, T), np.nan, dtype=np.float32)
    for o, k in enumerate(scenario.objects):
        cols = k.frames - scenario.frames[0]
        v = k.valid
        for name, values in (("x", k.boxes[:, 0]), ("y", k.boxes[:, 1]), ("z", k.boxes[:, 2]), ("heading", k.boxes[:, 3]),
                             ("velocity_x", k.velocity[:, 0]), ("velocity_y", k.velocity[:, 1]), ("speed", k.speed),
                             ("acceleration", k.acceleration), ("yaw_rate", k.yaw_rate)):
            out[name][o, cols[v]] = values[v]
        for name, value in zip(("length", "width", "height"), k.size, strict=True):
            out[name][o, cols[v]] = value
        out["valid"][o, cols] = v
    out["object_id"] = np.array([k.object_id for k in scenario.objects], dtype=str)
    out["object_type"] = np.array([av2_object_type(k.label) for k in scenario.objects], dtype=str)
    out["label"] = np.array([k.label for k in scenario.objects], dtype=str)
    out["timestamps_ns"] = scenario.timestamps_ns.astype(np.int64)
    out["frames"] = scenario.frames.astype(np.int64)
    return out


def write_npz_table(path: str | Path, scenario: Scenario) -> tuple[int, int]:
    """Write the dense npz; returns (objects, timesteps)."""
    arrays = dense_arrays(scenario)
    write_npz(path, **arrays)
    return arrays["valid"].shape


def write_csv(path: str | Path, objects: list[ObjectTrack]) -> int:
    """Long CSV (one row per object and frame, CSV_COLUMNS); NaN is written as an empty cell."""
    buffer = io.StringIO()
    writer = csv.writer(buffer, lineterminator="\n")
    writer.writerow(CSV_COLUMNS)
    rows = 0

    def num(value: float, digits: int) -> str:
        return "" if not np.isfinite(value) else f"{value:.{digits}f}"

    for k in objects:
        for i in range(len(k)):
            writer.writerow([k.object_id, k.label, int(k.frames[i]), int(k.timestamps_ns[i]), int(bool(k.valid[i])),
                             ",".join(k.flags[i]), num(k.boxes[i, 0], 4), num(k.boxes[i, 1], 4), num(k.boxes[i, 2], 4),
                             num(k.boxes[i, 3], 5), num(k.velocity[i, 0], 4), num(k.velocity[i, 1], 4),
                             num(k.speed[i], 4), num(k.acceleration[i], 4), num(k.yaw_rate[i], 5),
                             num(k.position_std[i], 4), num(k.heading_std[i], 5), num(k.speed_std[i], 4),
                             num(k.yaw_rate_std[i], 5)])
            rows += 1
    write_text(path, buffer.getvalue())
    return rows
