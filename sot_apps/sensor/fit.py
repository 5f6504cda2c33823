"""Estimate a spinning LiDAR's beam table and azimuth resolution from real sweeps (``sot-apps sensor fit``).

Points must be in the sensor frame (origin at the optical centre, z along the spin axis).

1. Elevation ``atan2(z, hypot(x, y))`` of every point beyond ``min_range`` (all given sweeps) is
   histogrammed in 0.01-degree bins and smoothed (Gaussian, 1.5 bins).
2. Beams are the histogram's peaks: local maxima holding at least ``min_peak_fraction`` of the average
   per-beam count, greedily kept from the highest down when at least ``min_separation_deg`` from a kept
   one; each is refined to the median elevation of the points within half that separation.
3. Points are assigned to the nearest beam; the azimuth step is the median gap between consecutive
   azimuths of a beam's points (gaps up to 2 degrees, per sweep), and ``columns = round(360 / step)``.
4. With per-point times, the spin rate and direction come from the median azimuth rate of consecutive
   (in time) points of one beam; ``scan_start_deg`` is the azimuth of the earliest point.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy.ndimage import gaussian_filter1d

from .model import Sensor

__all__ = ["FitResult", "fit_sensor", "elevation_peaks", "align_sensor_frame", "points_at_capture_pose", "ring_sharpness"]


@dataclass
class FitResult:
    sensor: Sensor
    beam_counts: list[int]
    azimuth_step_deg: float
    points_used: int

    def to_json(self) -> dict:
        doc = self.sensor.to_dict()
        doc["fit"] = {"beam_counts": self.beam_counts, "azimuth_step_deg": self.azimuth_step_deg,
                      "points_used": self.points_used}
        return doc


def elevation_peaks(elev_deg: np.ndarray, bin_deg: float = 0.01, min_separation_deg: float = 0.09,
                    min_peak_fraction: float = 0.05, max_beams: int = 256) -> np.ndarray:
    """Sorted (descending) beam elevations (degrees) found as peaks of the elevation histogram."""
    lo, hi = float(elev_deg.min()) - 0.1, float(elev_deg.max()) + 0.1
    edges = np.arange(lo, hi + bin_deg, bin_deg)
    hist, _ = np.histogram(elev_deg, bins=edges)
    smooth = gaussian_filter1d(hist.astype(np.float64), 1.5)
    centres = (edges[:-1] + edges[1:]) / 2
    is_max = np.r_[False, (smooth[1:-1] >= smooth[:-2]) & (smooth[1:-1] > smooth[2:]), False]
    cand = np.flatnonzero(is_max)
    order = cand[np.argsort(-smooth[cand], kind="stable")]
    kept: list[int] = []
    for i in order:
        if all(abs(centres[i] - centres[j]) >= min_separation_deg for j in kept):
            kept.append(int(i))
        if len(kept) >= max_beams:
            break
    kept_arr = np.array(sorted(kept, key=lambda j: -centres[j]), dtype=int)
    # drop weak peaks (noise, sparse structure): below a fraction of the mean points per kept beam
    support = np.array([np.sum(np.abs(elev_deg - centres[j]) < min_separation_deg / 2) for j in kept_arr])
    strong = support >= min_peak_fraction * np.mean(support) if len(support) else support.astype(bool)
    peaks = centres[kept_arr[strong]]
    refined = np.array([np.median(elev_deg[np.abs(elev_deg - p) < min_separation_deg / 2]) for p in peaks])
    return np.sort(refined)[::-1]


def _azimuth_step(az_deg: np.ndarray, beam: np.ndarray, sweep_id: np.ndarray) -> float:
    gaps = []
    for b in np.unique(beam):
        for s in np.unique(sweep_id):
            a = np.sort(az_deg[(beam == b) & (sweep_id == s)])
            if len(a) > 10:
                d = np.diff(a)
                gaps.append(d[(d > 1e-4) & (d < 2.0)])
    all_gaps = np.concatenate(gaps) if gaps else np.array([])
    if all_gaps.size == 0:
        raise ValueError("cannot estimate the azimuth step: too few points per beam")
    # the smallest frequent gap is one column: take the median of gaps within 1.5x the 10th percentile
    base = np.percentile(all_gaps, 10)
    return float(np.median(all_gaps[all_gaps < 1.5 * base]))


def fit_sensor(sweeps: list[np.ndarray], times_ns: list[np.ndarray | None] | None = None, name: str = "fitted",
               min_range: float = 2.0, min_separation_deg: float = 0.09, range_noise_sigma: float = 0.02
               ) -> FitResult:
    """Fit a :class:`Sensor` to sweeps given in the sensor frame."""
    xyz = np.vstack([np.asarray(s, dtype=np.float64) for s in sweeps])
    sweep_id = np.concatenate([np.full(len(s), i) for i, s in enumerate(sweeps)])
    r_xy = np.hypot(xyz[:, 0], xyz[:, 1])
    rng = np.linalg.norm(xyz, axis=1)
    use = rng > min_range
    elev = np.degrees(np.arctan2(xyz[use, 2], r_xy[use]))
    az = np.degrees(np.arctan2(xyz[use, 1], xyz[use, 0]))
    peaks = elevation_peaks(elev, min_separation_deg=min_separation_deg)
    beam = np.argmin(np.abs(elev[:, None] - peaks[None, :]), axis=1)
    counts = np.bincount(beam, minlength=len(peaks)).tolist()
    step = _azimuth_step(az, beam, sweep_id[use])
    columns = int(round(360.0 / step))
    rotation_hz, direction, start = 10.0, 1, 0.0
    if times_ns is not None and all(t is not None for t in times_ns):
        t = np.concatenate([np.asarray(x, dtype=np.float64) for x in times_ns])[use]
        b0 = int(np.argmax(counts))
        sel = (beam == b0) & (sweep_id[use] == 0)
        order = np.argsort(t[sel], kind="stable")
        dt = np.diff(t[sel][order]) * 1e-9
        da = np.diff(np.unwrap(np.radians(az[sel][order])))
        ok = (dt > 0) & (np.abs(da) < math.radians(5))
        if ok.sum() > 10:
            omega = float(np.median(da[ok] / dt[ok]))
            rotation_hz = round(abs(omega) / (2 * math.pi), 3)
            direction = 1 if omega > 0 else -1
        first = np.argmin(t[sweep_id[use] == 0])
        start = float(az[sweep_id[use] == 0][first])
    sensor = Sensor(name=name, elevations_deg=tuple(round(float(p), 4) for p in peaks), columns=columns,
                    min_range=round(float(np.percentile(rng[use], 0.1)), 2) if use.any() else 0.5,
                    max_range=round(float(rng.max()), 1), rotation_hz=rotation_hz, scan_start_deg=round(start, 3),
                    direction=direction, range_noise_sigma=range_noise_sigma)
    return FitResult(sensor, counts, round(step, 5), int(use.sum()))


def compare_to_preset(fitted: Sensor, preset: Sensor) -> dict:
    """Match fitted beams to a preset's (nearest) and summarise the differences (degrees)."""
    table = np.sort(np.asarray(preset.elevations_deg))[::-1]
    fit = np.asarray(fitted.elevations_deg)
    nearest = np.abs(fit[:, None] - table[None, :]).argmin(axis=1)
    diff = fit - table[nearest]
    return {"preset": preset.name, "preset_beams": len(table), "fitted_beams": len(fit),
            "matched_preset_beams": int(len(np.unique(nearest))),
            "median_abs_diff_deg": float(np.median(np.abs(diff))) if len(diff) else None,
            "max_abs_diff_deg": float(np.max(np.abs(diff))) if len(diff) else None,
            "preset_columns": preset.columns, "fitted_columns": fitted.columns}


def points_at_capture_pose(points_frame: np.ndarray, offsets_ns: np.ndarray, timestamp_ns: int,
                           world_from_frame: np.ndarray, other_timestamp_ns: int, other_world_from_frame: np.ndarray
                           ) -> np.ndarray:
    """Points given in the sensor pose at ``timestamp_ns``, re-expressed in the sensor pose at each point's own
    capture time (``timestamp_ns + offsets_ns``).

    A spinning sensor on a moving car sees every point from a different place. Beams are cones about the
    sensor at the time it fired, so elevations must be measured from there. The pose at time t is interpolated
    between this frame's pose and another frame's (usually the previous one): the rotation turns about one
    axis and the translation is linear. Times outside the interval extrapolate.
    """
    from scipy.spatial.transform import Rotation

    dt = float(timestamp_ns - other_timestamp_ns)
    if dt == 0:
        return np.asarray(points_frame, dtype=np.float64)
    # s = (t - t_other) / (t_this - t_other): 0 at the other frame, 1 at this one (either order)
    s = 1.0 + np.asarray(offsets_ns, dtype=np.float64) / dt
    r0, t0 = other_world_from_frame[:3, :3], other_world_from_frame[:3, 3]
    r1, t1 = world_from_frame[:3, :3], world_from_frame[:3, 3]
    world = np.asarray(points_frame, dtype=np.float64) @ r1.T + t1
    rotvec = Rotation.from_matrix(r0.T @ r1).as_rotvec()
    translation = t0 + s[:, None] * (t1 - t0)
    in_other = (world - translation) @ r0                                   # r0^T (world - t(s))
    return Rotation.from_rotvec(s[:, None] * rotvec).inv().apply(in_other)


def _elevations(points: np.ndarray, params: np.ndarray) -> np.ndarray:
    """Elevations (degrees) seen from origin (dx, dy, dz) after roll, pitch: params = roll, pitch, dx, dy, dz."""
    from scipy.spatial.transform import Rotation

    q = points - params[2:5]
    if params[0] or params[1]:
        q = q @ Rotation.from_euler("xy", params[:2], degrees=True).as_matrix().T
    return np.degrees(np.arctan2(q[:, 2], np.hypot(q[:, 0], q[:, 1])))


def _sharpness(points: np.ndarray, params: np.ndarray) -> float:
    """How much the elevations concentrate on fine peaks (beams), relative to their coarse spread.

    The ratio of the concentration (sum of squared bin fractions) in 0.02-degree bins to that in 0.5-degree
    bins, times 25. Dividing by the coarse concentration makes it scale-free: moving the origin far away
    squeezes every elevation together, which raises the fine concentration but not this ratio. 1 means
    no structure finer than 0.5 degrees.
    """
    elev = _elevations(points, params)
    bins = np.floor((elev + 45.0) / 0.02).astype(np.int64)          # 0.02-degree bins over [-45, 45)
    fine = np.bincount(bins[(bins >= 0) & (bins < 4500)], minlength=4500).astype(np.float64)
    coarse = fine.reshape(180, 25).sum(axis=1)                         # 0.5-degree bins
    return float((fine ** 2).sum() / max((coarse ** 2).sum(), 1.0) * 25.0)


def ring_sharpness(points: np.ndarray) -> float:
    """How sharply the elevations of points (sensor frame) concentrate on beams: the criterion
    :func:`align_sensor_frame` maximises (1 = no structure finer than 0.5 degrees)."""
    return _sharpness(np.asarray(points, dtype=np.float64), np.zeros(5))


def align_sensor_frame(sweeps: list[np.ndarray], min_range: float = 3.0, max_points: int = 40_000,
                       horizontal_search_m: float = 3.0, vertical_search_m: tuple[float, float] = (-1.0, 3.0)
                       ) -> tuple[np.ndarray, dict]:
    """Find the optical centre and tilt that make the beams sharpest in elevation.

    For sweeps whose frame origin is not the optical centre (e.g. PandaSet's pose frame). The search covers
    the centre's offset (dx, dy within ``horizontal_search_m``, dz within ``vertical_search_m``) on a 0.4 x
    0.4 x 0.25 m grid with no tilt, then refines roll, pitch (degrees) and the offset with Nelder-Mead.
    Returns ``sensor_from_frame`` (4x4) and the parameters.
    """
    from scipy.optimize import minimize
    from scipy.spatial.transform import Rotation

    pts = np.vstack([np.asarray(s, dtype=np.float64) for s in sweeps])
    pts = pts[np.linalg.norm(pts, axis=1) > min_range]
    if len(pts) > max_points:
        pts = pts[np.linspace(0, len(pts) - 1, max_points).astype(int)]
    horizontal = np.arange(-horizontal_search_m, horizontal_search_m + 1e-9, 0.4)
    vertical = np.arange(vertical_search_m[0], vertical_search_m[1] + 1e-9, 0.25)
    offsets = [np.array([0.0, 0.0, dx, dy, dz]) for dx in horizontal for dy in horizontal for dz in vertical]
    x0 = max(offsets, key=lambda x: _sharpness(pts, x))
    simplex = np.vstack([x0, x0 + np.diag([0.5, 0.5, 0.2, 0.2, 0.1])])
    best = minimize(lambda x: -_sharpness(pts, x), x0, method="Nelder-Mead",
                    options={"xatol": 1e-3, "fatol": 1e-6, "maxiter": 1500, "initial_simplex": simplex})
    roll, pitch, dx, dy, dz = (float(v) for v in best.x)
    rot = Rotation.from_euler("xy", [roll, pitch], degrees=True).as_matrix()
    sensor_from_frame = np.eye(4)
    sensor_from_frame[:3, :3] = rot
    sensor_from_frame[:3, 3] = -rot @ np.array([dx, dy, dz])
    return sensor_from_frame, {"roll_deg": round(roll, 4), "pitch_deg": round(pitch, 4),
                               "origin_m": [round(dx, 4), round(dy, 4), round(dz, 4)],
                               "sharpness_before": round(_sharpness(pts, np.zeros(5)), 4),
                               "sharpness_after": round(-float(best.fun), 4)}
