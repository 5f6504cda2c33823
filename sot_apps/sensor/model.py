"""Spinning LiDAR models: an explicit per-beam elevation table, azimuth columns, range limits, timing.

A sensor fires every beam once per column; columns are evenly spaced in azimuth and in time over one
revolution. The sensor frame is right-handed, x forward, z up; azimuth is ``atan2(y, x)``; elevation
is ``atan2(z, hypot(x, y))``. Column ``j`` fires at azimuth ``scan_start + direction * 2*pi*j/columns``
at time ``-period + (j + 0.5) * period / columns`` relative to the frame timestamp, which marks the END of
the sweep (as PandaSet does).

Beam tables (degrees, in laser-id order) — see docs/lidar_sim.md for sources:

- ``waymo_top``: 64 beams, +2.4 ... -17.6 deg evenly (Waymo calibrates inclinations per vehicle and
  publishes no fixed table; the issue specifies the range), 2650 columns, 75 m.
- ``hdl64e``: Velodyne HDL-64E nominal: upper block 32 beams +2.0 ... -8.33 deg (1/3 deg), lower block
  32 beams -8.83 ... -24.33 deg (1/2 deg); 0.1728 deg azimuth at 10 Hz (2083 columns), 120 m.
- ``vlp16``: Velodyne VLP-16, -15 ... +15 deg every 2 deg in firing order; 0.2 deg at 10 Hz, 100 m.
- ``hdl32e``: Velodyne HDL-32E, -30.67 ... +10.67 deg every 1.33 deg in firing order; 20 Hz as in
  nuScenes, 1084 columns (~0.33 deg), 100 m.
- ``pandar64``: Hesai Pandar64 angle-correction table as we remember the published datasheet (dense 0.167
  deg spacing from +1.86 to -6.06 deg, sparse above and below, +14.88 ... -24.90 deg); 0.2 deg at 10 Hz
  (1800 columns), 200 m. ``sot-apps sensor fit`` on PandaSet checks it (docs/lidar_sim.md).
- ``pandaset_pandar64``: ``pandar64`` with PandaSet's range drop, ``clip(0.05 + 0.005 * r, 0, 1)``, fitted
  on real against simulated points of non-dev vehicles (docs/lidar_sim.md). Its optical centre is not a
  sensor property: the PandaSet reader puts the LiDAR frame there (``ego_from_lidar``).
"""

from __future__ import annotations

import functools
import json
import math
from dataclasses import asdict, dataclass, field, replace
from pathlib import Path

import numpy as np

from ..errors import InputError

__all__ = ["Sensor", "PRESETS", "preset", "load_sensor", "sensor_to_json", "sensor_from_dict"]


@dataclass(frozen=True)
class Sensor:
    """A spinning LiDAR.

    Attributes:
        name: preset or user name.
        elevations_deg: per-beam elevation (degrees), laser-id order (not necessarily sorted).
        columns: firings per revolution (azimuth resolution = 360 / columns degrees).
        min_range, max_range: metres; returns outside are dropped.
        rotation_hz: revolutions per second (sweep period = 1 / rotation_hz).
        scan_start_deg: azimuth of column 0 (degrees).
        direction: +1 counter-clockwise (seen from above), -1 clockwise.
        range_noise_sigma: Gaussian range noise (metres, 1 sigma) used when noise is switched on.
        azimuth_offsets_deg: optional per-beam azimuth offset (degrees) added to the column azimuth.
        drop_at_zero_range, drop_per_m: the range drop model (with ``Realism.drop_range``): a return at
            range r is lost with probability ``clip(drop_at_zero_range + drop_per_m * r, 0, 1)``; both 0 (the
            default) turn it off.
    """

    name: str
    elevations_deg: tuple[float, ...]
    columns: int
    min_range: float = 0.5
    max_range: float = 120.0
    rotation_hz: float = 10.0
    scan_start_deg: float = 180.0
    direction: int = 1
    range_noise_sigma: float = 0.02
    azimuth_offsets_deg: tuple[float, ...] | None = field(default=None)
    drop_at_zero_range: float = 0.0
    drop_per_m: float = 0.0

    def __post_init__(self) -> None:
        if len(self.elevations_deg) == 0:
            raise ValueError("a sensor needs at least one beam")
        if self.columns < 1:
            raise ValueError("columns must be >= 1")
        if self.azimuth_offsets_deg is not None and len(self.azimuth_offsets_deg) != len(self.elevations_deg):
            raise ValueError("azimuth_offsets_deg must have one entry per beam")
        if not 0.0 <= self.drop_at_zero_range <= 1.0 or self.drop_per_m < 0:
            raise ValueError("drop_at_zero_range must be in [0, 1] and drop_per_m >= 0")

    @property
    def beams(self) -> int:
        return len(self.elevations_deg)

    @property
    def num_rays(self) -> int:
        return self.beams * self.columns

    @property
    def period_s(self) -> float:
        return 1.0 / self.rotation_hz

    @property
    def azimuth_resolution_deg(self) -> float:
        return 360.0 / self.columns

    @property
    def has_range_drop(self) -> bool:
        return self.drop_at_zero_range > 0 or self.drop_per_m > 0

    def range_drop_probability(self, distance: np.ndarray) -> np.ndarray:
        """Probability that a return at ``distance`` (m) is lost (the range drop model; zeros when off)."""
        return np.clip(self.drop_at_zero_range + self.drop_per_m * np.asarray(distance, dtype=np.float64), 0.0, 1.0)

    def elevations(self) -> np.ndarray:
        """(B,) beam elevations in radians."""
        return np.radians(np.asarray(self.elevations_deg, dtype=np.float64))

    def column_azimuths(self) -> np.ndarray:
        """(C,) azimuth of each column (radians, wrapped to [-pi, pi))."""
        j = np.arange(self.columns, dtype=np.float64)
        az = math.radians(self.scan_start_deg) + self.direction * 2.0 * math.pi * j / self.columns
        return (az + math.pi) % (2.0 * math.pi) - math.pi

    def column_time_offsets_ns(self) -> np.ndarray:
        """(C,) firing time of each column relative to the frame timestamp (end of sweep), int64 ns."""
        j = np.arange(self.columns, dtype=np.float64)
        return np.round((-1.0 + (j + 0.5) / self.columns) * self.period_s * 1e9).astype(np.int64)

    def ray_grid(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Unit ray directions of a full sweep, beam-major: (B*C, 3) float64, plus beam and column indices.

        Ray ``b * C + c`` is beam ``b`` at column ``c`` (so a range image is ``values.reshape(B, C)``).
        Cached per sensor: do not modify the returned arrays.
        """
        return _ray_grid_cached(self)

    def _ray_grid(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        el = self.elevations()[:, None]
        az = np.broadcast_to(self.column_azimuths()[None, :], (self.beams, self.columns))
        if self.azimuth_offsets_deg is not None:
            az = az + np.radians(np.asarray(self.azimuth_offsets_deg, dtype=np.float64))[:, None]
        cos_el = np.cos(el)
        dirs = np.stack([cos_el * np.cos(az), cos_el * np.sin(az), np.broadcast_to(np.sin(el), az.shape)], axis=-1)
        beam = np.repeat(np.arange(self.beams, dtype=np.int32), self.columns)
        column = np.tile(np.arange(self.columns, dtype=np.int32), self.beams)
        # (not flagged read-only: numpy's matmul falls off its BLAS path for read-only operands)
        return np.ascontiguousarray(dirs.reshape(-1, 3)), beam, column

    def to_dict(self) -> dict:
        data = asdict(self)
        data["elevations_deg"] = list(self.elevations_deg)
        if self.azimuth_offsets_deg is None:
            data.pop("azimuth_offsets_deg")
        else:
            data["azimuth_offsets_deg"] = list(self.azimuth_offsets_deg)
        if not self.has_range_drop:  # the JSON of sensors without one is unchanged
            data.pop("drop_at_zero_range")
            data.pop("drop_per_m")
        return {"version": 1, **data}


@functools.lru_cache(maxsize=16)
def _ray_grid_cached(sensor: Sensor) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    return sensor._ray_grid()


_PANDAR64 = (
    14.882, 11.032, 8.059, 5.057, 3.040, 2.028, 1.860, 1.688, 1.522, 1.351, 1.184, 1.013, 0.846, 0.675,
    0.508, 0.337, 0.169, 0.000, -0.169, -0.337, -0.508, -0.675, -0.845, -1.013, -1.184, -1.351, -1.522,
    -1.688, -1.860, -2.028, -2.198, -2.365, -2.536, -2.700, -2.873, -3.040, -3.210, -3.375, -3.548, -3.712,
    -3.884, -4.050, -4.221, -4.385, -4.558, -4.720, -4.892, -5.057, -5.229, -5.391, -5.565, -5.726, -5.898,
    -6.061, -7.063, -8.059, -9.060, -9.885, -11.032, -12.006, -12.974, -13.930, -18.889, -24.897,
)

_HDL32E = (
    -30.67, -9.33, -29.33, -8.00, -28.00, -6.67, -26.67, -5.33, -25.33, -4.00, -24.00, -2.67, -22.67, -1.33,
    -21.33, 0.00, -20.00, 1.33, -18.67, 2.67, -17.33, 4.00, -16.00, 5.33, -14.67, 6.67, -13.33, 8.00, -12.00,
    9.33, -10.67, 10.67,
)

_VLP16 = (-15.0, 1.0, -13.0, 3.0, -11.0, 5.0, -9.0, 7.0, -7.0, 9.0, -5.0, 11.0, -3.0, 13.0, -1.0, 15.0)

_WAYMO_TOP = tuple(float(v) for v in np.linspace(2.4, -17.6, 64))

_HDL64E = tuple(float(v) for v in np.linspace(2.0, -8.33, 32)) + tuple(float(v) for v in np.linspace(-8.83, -24.33, 32))

PRESETS: dict[str, Sensor] = {
    "waymo_top": Sensor("waymo_top", _WAYMO_TOP, columns=2650, min_range=0.5, max_range=75.0,
                        rotation_hz=10.0, range_noise_sigma=0.02),
    "hdl64e": Sensor("hdl64e", _HDL64E, columns=2083, min_range=0.9, max_range=120.0, rotation_hz=10.0,
                     direction=-1, range_noise_sigma=0.02),
    "vlp16": Sensor("vlp16", _VLP16, columns=1800, min_range=0.5, max_range=100.0, rotation_hz=10.0,
                    direction=-1, range_noise_sigma=0.03),
    "hdl32e": Sensor("hdl32e", _HDL32E, columns=1084, min_range=0.9, max_range=100.0, rotation_hz=20.0,
                     direction=-1, range_noise_sigma=0.02),
    "pandar64": Sensor("pandar64", _PANDAR64, columns=1800, min_range=0.3, max_range=200.0, rotation_hz=10.0,
                       direction=-1, range_noise_sigma=0.02),
    # PandaSet's Pandar64 as its sweeps show it: the same beam table (every beam from -8.1 to +15 deg within
    # 0.12 deg of a measured ring; tests/sensor), and returns on vehicles lost with a probability growing
    # with range, fitted on 37 parked and other non-dev vehicles of pandaset_002 (docs/lidar_sim.md)
    "pandaset_pandar64": Sensor("pandaset_pandar64", _PANDAR64, columns=1800, min_range=0.3, max_range=200.0,
                                rotation_hz=10.0, direction=-1, range_noise_sigma=0.02, drop_at_zero_range=0.05,
                                drop_per_m=0.005),
}


def preset(name: str) -> Sensor:
    try:
        return PRESETS[name]
    except KeyError:
        raise InputError(None, f"unknown sensor preset {name!r}; choose one of {', '.join(PRESETS)} "
                               "or give a sensor JSON file") from None


def sensor_from_dict(data: dict, path: str | Path | None = None) -> Sensor:
    """A sensor from its JSON form (schema ``sensor``)."""
    from ..schemas import validate

    validate("sensor", data, path)
    kwargs = {k: v for k, v in data.items() if k != "version"}
    kwargs["elevations_deg"] = tuple(float(v) for v in kwargs["elevations_deg"])
    if kwargs.get("azimuth_offsets_deg") is not None:
        kwargs["azimuth_offsets_deg"] = tuple(float(v) for v in kwargs["azimuth_offsets_deg"])
    try:
        return Sensor(**kwargs)
    except (TypeError, ValueError) as exc:
        raise InputError(path, f"invalid sensor: {exc}") from exc


def load_sensor(spec: str | Path | dict | Sensor) -> Sensor:
    """A preset name, a sensor JSON path, a dict, or a Sensor."""
    if isinstance(spec, Sensor):
        return spec
    if isinstance(spec, dict):
        return sensor_from_dict(spec)
    text = str(spec)
    if text in PRESETS:
        return PRESETS[text]
    path = Path(text)
    if not path.is_file():
        if path.suffix.lower() == ".json":
            raise InputError(path, "sensor file is missing")
        return preset(text)
    try:
        data = json.loads(path.read_text(encoding="utf-8"))
    except (json.JSONDecodeError, UnicodeDecodeError) as exc:
        raise InputError(path, f"not valid JSON ({exc})") from exc
    if not isinstance(data, dict):
        raise InputError(path, "a sensor file must hold a JSON object")
    return sensor_from_dict(data, path)


def sensor_to_json(sensor: Sensor) -> dict:
    return sensor.to_dict()


def with_name(sensor: Sensor, name: str) -> Sensor:
    return replace(sensor, name=name)
