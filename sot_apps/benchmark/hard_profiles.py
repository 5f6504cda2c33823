"""Where the profiles that provoke unseen-vehicle failures must be, relative to the sensor.

A motion profile fixes a vehicle's motion in its own frame; these profiles also need a geometry relative to
the sensor, which the placer checks for every candidate start at once (:func:`geometry_ok`, vectorised over
starts and frames, on the path's positions at the frame times):

- ``far_approach``: the box centre is >= 55 m from the sensor at the first frame and closes at 5-12 m/s
  (first-to-last range over time) without ever moving away by more than 0.2 m between frames, seen from the
  front at the first frame (the line of sight at >= 150 degrees from the heading: head-on, as a vehicle
  coming down the road, which shows the sensor its narrow front);
- ``passing``: the vehicle drives past the sensor: the sensor's coordinate along the vehicle's heading
  (relative to the box centre) changes sign over the tracklet, and the nearest range is <= 15 m;
- ``hidden``: no geometry beyond the range band; the benchmark removes every point of the vehicle for
  5-15 frames (:func:`hidden_frames`), with >= 5 frames of points before and after;
- ``oblique``: seen from behind-side: at every frame the line of sight from the sensor to the box centre
  makes 20-70 degrees with the vehicle's heading (0 = seen straight from behind, 90 = from the side).

Each starts in its own range band (:data:`PROFILE_BANDS`) instead of the band cycle of the other profiles.
What the simulated points must show is checked after simulation (:func:`points_ok`); a tracklet that fails is
not listed (``make.json`` counts them under ``unlisted``):

- ``far_approach``: <= 30 points in the ground-truth box at the first frame;
- ``hidden``: points at some frame before and at some frame after the hidden frames;
- ``oblique``: the median over frames of the points in the box is 15-120.
"""

from __future__ import annotations

import math

import numpy as np

__all__ = ["PROFILE_BANDS", "FAR_START_M", "FAR_CLOSING_MPS", "OBLIQUE_VIEW_DEG", "PASSING_MAX_RANGE_M",
           "HIDDEN_FRAMES", "NEAR_M", "FAR_MAX_START_POINTS", "OBLIQUE_POINTS", "geometry_ok", "points_ok",
           "extra_headings", "hidden_frames", "viewing_angle_deg",
           "tracklet_geometry"]

FAR_START_M = 55.0
FAR_CLOSING_MPS = (5.0, 12.0)
FAR_HEAD_ON_DEG = 150.0
PASSING_MAX_RANGE_M = 15.0
OBLIQUE_VIEW_DEG = (20.0, 70.0)
HIDDEN_FRAMES = (5, 15)           # how many frames a hidden tracklet is hidden (inclusive range)
HIDDEN_MARGIN = 5                 # frames with points before and after
FAR_MAX_START_POINTS = 30
OBLIQUE_POINTS = (15, 120)        # the median over frames of the points in the box
NEAR_M = 30.0                     # far_approach: the frame it first comes within this range is recorded

PROFILE_BANDS: dict[str, tuple[float, float]] = {
    "far_approach": (60.0, 75.0),
    "passing": (8.0, 35.0),
    "hidden": (8.0, 45.0),
    "oblique": (40.0, 75.0),
}


def viewing_angle_deg(rel_xy: np.ndarray, heading: np.ndarray) -> np.ndarray:
    """|angle| between the line of sight (sensor to box centre, ``rel_xy`` (..., 2)) and the vehicle's heading,
    in degrees: 0 seen from straight behind, 90 from the side, 180 from straight ahead."""
    sight = np.arctan2(rel_xy[..., 1], rel_xy[..., 0])
    return np.degrees(np.abs((sight - heading + np.pi) % (2 * np.pi) - np.pi))


def geometry_ok(profile: str, positions: np.ndarray, headings: np.ndarray, sensor_xyh: np.ndarray,
                times_s: np.ndarray) -> np.ndarray:
    """(M,) which of M candidate paths have the profile's geometry; ``positions`` (M, F, 2) box centres and
    ``headings`` (M, F) at the F frame times ``times_s``; ``sensor_xyh`` (F, 3)."""
    rel = positions - sensor_xyh[None, :, :2]
    r = np.hypot(rel[..., 0], rel[..., 1])
    m = len(positions)
    if profile == "far_approach":
        closing = (r[:, 0] - r[:, -1]) / max(float(times_s[-1] - times_s[0]), 1e-9)
        monotone = (np.diff(r, axis=1) <= 0.2).all(axis=1) if r.shape[1] > 1 else np.ones(m, bool)
        head_on = viewing_angle_deg(rel[:, 0], headings[:, 0]) >= FAR_HEAD_ON_DEG
        return ((r[:, 0] >= FAR_START_M) & (closing >= FAR_CLOSING_MPS[0]) & (closing <= FAR_CLOSING_MPS[1])
                & monotone & head_on)
    if profile == "passing":
        along = rel[..., 0] * np.cos(headings) + rel[..., 1] * np.sin(headings)  # the sensor along the path
        return (along[:, 0] * along[:, -1] < 0.0) & (r.min(axis=1) <= PASSING_MAX_RANGE_M)
    if profile == "oblique":
        view = viewing_angle_deg(rel, headings)
        return ((view >= OBLIQUE_VIEW_DEG[0]) & (view <= OBLIQUE_VIEW_DEG[1])).all(axis=1)
    return np.ones(m, dtype=bool)


def points_ok(profile: str, counts: np.ndarray, hidden: tuple[int, int] | None = None) -> bool:
    """Do the simulated points in the box (``counts`` (F,) per tracklet frame) show what the profile claims?"""
    if profile == "far_approach":
        return int(counts[0]) <= FAR_MAX_START_POINTS
    if profile == "oblique":
        return OBLIQUE_POINTS[0] <= float(np.median(counts)) <= OBLIQUE_POINTS[1]
    if profile == "hidden" and hidden is not None:
        return bool(counts[:hidden[0]].max(initial=0) > 0 and counts[hidden[1] + 1:].max(initial=0) > 0)
    return True


def extra_headings(profile: str, sensor_heading: float) -> list[float]:
    """Headings tried besides along, against and across the ego's direction: the diagonals for ``oblique``."""
    if profile != "oblique":
        return []
    return [sensor_heading + math.radians(d) for d in (30.0, -30.0, 45.0, -45.0, 60.0, -60.0, 135.0, -135.0)]


def hidden_frames(rng: np.random.Generator, n_frames: int) -> tuple[int, int] | None:
    """[first, last] (inclusive) frames of a hidden tracklet of ``n_frames`` frames: 5-15 frames long (at most
    what the tracklet holds), with >= 5 frames of points before and after; None if the tracklet is too short."""
    room = n_frames - 2 * HIDDEN_MARGIN
    if room < HIDDEN_FRAMES[0]:
        return None
    length = int(rng.integers(HIDDEN_FRAMES[0], min(HIDDEN_FRAMES[1], room) + 1))
    first = int(rng.integers(HIDDEN_MARGIN, n_frames - HIDDEN_MARGIN - length + 1))
    return first, first + length - 1


def tracklet_geometry(profile: str, centres: np.ndarray, headings: np.ndarray, sensor_xyh: np.ndarray,
                      hidden: tuple[int, int] | None = None) -> dict:
    """The per-tracklet figures a profile's scores need (frame indices relative to the tracklet's first frame):
    ``reappear_frame`` and ``hidden_frames`` (hidden), ``near_frame`` (far_approach: first frame within 30 m,
    or None), ``min_range_m`` (passing), ``view_deg`` (oblique: min and max viewing angle)."""
    rel = centres - sensor_xyh[:, :2]
    r = np.hypot(rel[:, 0], rel[:, 1])
    out: dict = {}
    if profile == "hidden" and hidden is not None:
        out["hidden_frames"] = [int(hidden[0]), int(hidden[1])]
        out["reappear_frame"] = int(hidden[1]) + 1
    if profile == "far_approach":
        near = np.flatnonzero(r <= NEAR_M)
        out["near_frame"] = int(near[0]) if near.size else None
    if profile == "passing":
        out["min_range_m"] = round(float(r.min()), 2)
    if profile == "oblique":
        view = viewing_angle_deg(rel, headings)
        out["view_deg"] = [round(float(view.min()), 1), round(float(view.max()), 1)]
    return out
