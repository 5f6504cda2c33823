"""Heading from travel (``motion.travel_weight`` > 0): a vehicle moving faster than a few m/s moves along its
heading, so the direction of travel of the track's own recent box centres is a target for the per-frame
heading.

:class:`TravelHeading` keeps the last ``motion.travel_frames`` + 1 centres with their times (at least 3). The
direction of travel is the chord from the first to the last: in a steady turn, the heading at the window's middle
time. The half-chords' directions (headings half a span apart) give the window's turn rate, which carries the
chord's direction to the next frame's time (a turn measured from the positions only: the motion model's turn
rate, which a rotating box feeds, would feed the rotation back); the term still fades out as the window turns
(x (1 - the half-chords' turn / ``travel_max_turn``), none beyond): entering or leaving a turn the rate changes
within the window. Its
weight is ``travel_weight`` x a speed factor (0 below ``travel_min_speed``, rising to 1 at twice that speed) x a
sparseness factor ``travel_points`` / (``travel_points`` + the previous frame's object points): few points (a far
or partial view) pin the heading weakly; and, with ``travel_scatter`` = s > 0, a scatter factor s^2 / (s^2 +
sigma^2), sigma the chord direction's standard error: the centres' scatter across the straight line fitted to them
over time (the residuals' RMS with n - 2 degrees of freedom), times sqrt(2) over the chord's length. A sparse car's
centres that jump a few decimetres across its path give a direction a few degrees off, which the term would
otherwise hold the heading to. In
the solve it is a quadratic term on the heading (tracker/terms.py ``travel_heading_block``) beside the data terms:
where the points pin the heading (a curved loss in dtheta) they decide, where they pin it weakly (a partial view)
the travel does. A direction more than ``_MAX_OFFSET`` from the previous heading (a reversal, a re-lock) is not
used. :class:`NoTravel`: off (the paper, ``faithful``)."""

from __future__ import annotations

from collections import deque

import numpy as np

from ..config import MotionConfig
from ..geometry import Box, wrap_angle

__all__ = ["NoTravel", "TravelHeading", "choose_travel"]

_MAX_OFFSET = 0.5  # rad


class NoTravel:
    def reset(self) -> None:
        pass

    def record(self, box: Box, time_s: float) -> None:
        pass

    def target(self, heading: float, points: int) -> tuple[float, float] | None:
        """(the heading to pull toward, the term's weight) for the frame after a box with ``heading``; ``points``:
        the previous frame's object points (how well the points can pin the heading)."""
        return None


class TravelHeading(NoTravel):
    def __init__(self, config: MotionConfig) -> None:
        self.weight = config.travel_weight
        self.min_speed = config.travel_min_speed
        self.points = config.travel_points
        self.max_turn = config.travel_max_turn
        self.scatter = config.travel_scatter
        self._track: deque[tuple[float, float, float]] = deque(maxlen=max(config.travel_frames, 2) + 1)

    def reset(self) -> None:
        self._track.clear()

    def record(self, box: Box, time_s: float) -> None:
        self._track.append((time_s, box.x, box.y))

    def target(self, heading: float, points: int) -> tuple[float, float] | None:
        if len(self._track) < 3:
            return None
        track = np.array(self._track)
        span = track[-1, 0] - track[0, 0]
        chord = track[-1, 1:] - track[0, 1:]
        if span <= 0:
            return None
        speed = float(np.linalg.norm(chord)) / span
        factor = min(1.0, max(0.0, speed / self.min_speed - 1.0))
        if factor <= 0:
            return None
        # a turn: the chord is the heading at the window's middle time; the half-chords (headings a half span
        # apart) give the turn rate, which carries it to the next frame's time; the term fades out as they turn
        mid = track[len(track) // 2, 1:]
        first, second = mid - track[0, 1:], track[-1, 1:] - mid
        turn = float(wrap_angle(np.arctan2(second[1], second[0]) - np.arctan2(first[1], first[0])))
        factor *= max(0.0, 1.0 - abs(turn) / self.max_turn)
        if factor <= 0:
            return None
        ahead = 0.5 * span + span / (len(track) - 1)      # the window's middle to the next frame (mean interval)
        direction = float(np.arctan2(chord[1], chord[0])) + turn * ahead / (0.5 * span)
        offset = float(wrap_angle(direction - heading))
        if abs(offset) > 0.5 * np.pi:                  # driving backwards: the heading is the other way
            offset = float(wrap_angle(offset + np.pi))
        if abs(offset) > _MAX_OFFSET:
            return None
        if self.scatter > 0:
            sigma = _chord_direction_sigma(track)
            factor *= self.scatter**2 / (self.scatter**2 + sigma**2)
        return heading + offset, self.weight * factor * self.points / (self.points + points)


def _chord_direction_sigma(track: np.ndarray) -> float:
    """The standard error (rad) of the direction of the chord through rows (time, x, y) of ``track`` (>= 3 rows,
    a positive chord): the rows' scatter across the straight line fitted to x(t), y(t) by least squares."""
    t = track[:, 0] - track[:, 0].mean()
    xy = track[:, 1:] - track[:, 1:].mean(axis=0)
    velocity = t @ xy / (t @ t)
    speed = float(np.linalg.norm(velocity))
    if speed == 0.0:                       # out and back: no direction
        return float("inf")
    across = np.array([-velocity[1], velocity[0]]) / speed
    residual = (xy - np.outer(t, velocity)) @ across
    rms = float(np.sqrt(residual @ residual / (len(track) - 2)))
    return float(np.sqrt(2.0) * rms / np.linalg.norm(track[-1, 1:] - track[0, 1:]))


def choose_travel(config: MotionConfig) -> NoTravel:
    return TravelHeading(config) if config.travel_weight > 0 else NoTravel()
