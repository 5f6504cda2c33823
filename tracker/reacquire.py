"""The empty start's search (``first_frame.reacquire``): where along its heading a held start box finds points.

The start box had too few points to follow. A region along its heading that grows with the time since the start
is searched: ``max_speed`` x elapsed ahead, a third of that behind, the box's width + 0.5 m each side across.
Once one box length of it holds ``min_points`` non-ground points, the box slides along its heading to where it
holds the most of them (among equals, where its face toward the sensor meets the points: that face is the
visible one).
"""

from __future__ import annotations

import numpy as np

from .geometry import Box, points_in_box
from .shape import to_object_frame

__all__ = ["search_region", "start_shift"]


def search_region(box: Box, ahead: float, behind: float) -> Box:
    """The box stretched ``ahead`` along its heading and ``behind`` against it, 0.5 m wider each side."""
    return Box(box.x + 0.5 * (ahead - behind) * np.cos(box.heading),
               box.y + 0.5 * (ahead - behind) * np.sin(box.heading), box.z, box.heading,
               box.length + ahead + behind, box.width + 1.0, box.height)


def start_shift(local: np.ndarray, box: Box, ahead: float, behind: float, min_points: int,
                sensor: np.ndarray) -> float | None:
    """The shift along ``box``'s heading where it holds the most of ``local``'s points (at least ``min_points``),
    or None; ``sensor``: the sensor's world position."""
    reach = search_region(box, ahead, behind)
    obj = to_object_frame(local[points_in_box(local, reach, 1.0)], reach)
    u = np.sort(obj[:, 0] + 0.5 * (ahead - behind))      # along the heading, from the start box's centre
    shifts = np.arange(-behind, ahead + 0.05, 0.1)
    half = 0.5 * box.length                              # points within a box length of each shift
    counts = np.searchsorted(u, shifts + half, side="right") - np.searchsorted(u, shifts - half, side="left")
    if counts.max(initial=0) < min_points:
        return None
    best = shifts[counts == counts.max()]
    sensor_u = float(np.dot(sensor[:2] - box.center[:2], [np.cos(box.heading), np.sin(box.heading)]))
    return float(best.min() if sensor_u > best.mean() else best.max())  # the visible face meets the points
