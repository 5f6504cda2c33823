"""The containment check (``footprint.containment``; ``min_points`` 0 = off): a box holds its object's points.

On a vehicle seen broadside, the points along its length pin the box only at the two ends of its side. When the
registration stops short along the length (a motion prior that starts at zero speed, an early stop), the box falls
behind the car a little each frame; the points beyond the box's front never join the shape, the shape's rear edge
moves forward in the box, and the lag holds: the shape and the box agree, the car does not.

The check looks along the box's length in the band of the box's width (``margin`` wider each side: the visible
side's points lie on the box's side face) and height (above ``floor`` from its bottom, where road points left by
the ground removal lie). The object's points run from the box's inside with no gap wider than ``gap``. Where they
run beyond the end the object moves towards (at ``min_speed`` or faster) while the other end of the box is empty,
the box moves along its length by the smaller of the two (the points then fit in it), at most ``max_shift``.
Points beyond both ends, none beyond either, or beyond the end the object moves away from (a stray part of its
scan, a neighbour close behind) leave it where it is; so do points that line up sharpest (tracker/footprint.py
``fit_heading``) at a heading more than ``max_turn`` from the box's: a box turned away from the object spills its
points at one end too, and sliding it along its wrong length would move it sideways.

For ``settle_frames`` frames after a re-lock (tracker/sotracker.py ``_relock``) the box slides either way: the
search's candidate is a part of the object (its front emerging from behind an occluder, the half in view), the
box was placed on that part by a guess, and the track's shape starts from it, so the registration holds the box
where the guess put it; the points that come into view beyond the end the object moves away from are the rest of
it.
"""

from __future__ import annotations

import numpy as np

from .config import ContainmentConfig
from .footprint import fit_heading
from .geometry import Box, wrap_angle

__all__ = ["containment_shift"]

_SEARCH_RANGE = 0.35   # rad: the heading the points line up sharpest at is searched this far each way


def containment_shift(points: np.ndarray, box: Box, config: ContainmentConfig, speed: float,
                      either_way: bool = False) -> float:
    """How far (m, along the box's heading; negative: backwards) ``box`` should move to hold its object's points
    (``points``: world (N, 3), e.g. the step's non-ground region points), the object moving at ``speed`` (m/s)
    along the box's heading. 0 when the check is off, the object moves slower than ``config.min_speed``, is
    sparser than ``config.min_points`` in the box, or its points do not spill out of exactly the end it moves
    towards (with ``either_way``: out of exactly one end)."""
    if config.min_points <= 0 or len(points) == 0 or abs(speed) < config.min_speed:
        return 0.0
    c, s = np.cos(box.heading), np.sin(box.heading)
    d = points - np.array([box.x, box.y, box.z])
    along = c * d[:, 0] + s * d[:, 1]
    across = -s * d[:, 0] + c * d[:, 1]
    half_l, half_h = 0.5 * box.length, 0.5 * box.height
    band = (np.abs(across) <= 0.5 * box.width + config.margin) & (d[:, 2] >= -half_h + config.floor) & (d[:, 2] <= half_h)
    x, xy = along[band], points[band, :2]
    inside = x[np.abs(x) <= half_l]
    if len(inside) < config.min_points:
        return 0.0
    front = _run_end(x, inside.max(), config.gap) - half_l
    rear = _run_end(-x, -inside.min(), config.gap) - half_l
    room_rear, room_front = inside.min() + half_l, half_l - inside.max()
    if front > 0.0 >= rear:
        shift = min(front, room_rear)
    elif rear > 0.0 >= front:
        shift = -min(rear, room_front)
    else:
        return 0.0
    if abs(shift) < config.min_shift or (shift * speed < 0.0 and not either_way):
        return 0.0
    run = (x >= -half_l - max(rear, 0.0)) & (x <= half_l + max(front, 0.0))
    fit = fit_heading(xy[run], box.heading, _SEARCH_RANGE)
    if abs(float(wrap_angle(fit.heading - box.heading))) > config.max_turn:
        return 0.0   # the points line up with a box turned away: its length is no line to slide along
    return float(np.clip(shift, -config.max_shift, config.max_shift))


def _run_end(x: np.ndarray, start: float, gap: float) -> float:
    """Where the points ``x`` (1-D) that run on from ``start`` upwards, each within ``gap`` of the one before,
    end."""
    ahead = np.sort(x[x > start])
    steps = np.diff(np.concatenate([[start], ahead]))
    breaks = np.flatnonzero(steps > gap)
    run = ahead if len(breaks) == 0 else ahead[: breaks[0]]
    return float(run[-1]) if len(run) else start
