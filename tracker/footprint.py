"""A dense object's heading from its footprint (``footprint``; ``footprint.min_points`` 0 = off).

A track whose shape was aggregated while the object was sparse, or while its box stood on something else, can keep
a wrong heading once the object is dense: the registration aligns the points to a shape that was built rotated, so
hundreds of points hold the box 10-20 degrees off. The footprint check tests the box's heading against the object's
own points in the bird's-eye view: a vehicle's visible side and back are straight lines, so its points, projected on
the axes of a box turned to its true heading, pile up in a few narrow bands (roof and interior points spread either
way). A frame votes when the sharpest heading, searched within ``search_range`` of the box's, is a peak inside that
range, lines the points up at least ``min_gain`` times as sharply as the box's heading, and differs from it by more
than ``min_offset``. After ``frames`` dense frames in a row vote (by amounts within ``agreement`` of each other)
the aggregated shape is asked the same in the box's frame: if it lines up sharpest turned by the same amount (it
was built turned), the box turns there about its centre, once per (re)start, and the shape turns back by as much in
the box's frame (it stays where it lies in the world). A shape that lines up with the box says the registration
has turned box and shape together away from the points for a while (a partial view); it turns them back itself, and
turning the box alone would overshoot then: no turn. The offline solve carries a turn back over the frames before it
that were held turned too (:func:`held_turned`; tracker/offline.py ``footprint_carried_back``). With
``after_relock`` > 0 the check runs only on the first that many measured frames after a re-lock (of a lost track
or a lost start; tracker/sotracker.py ``_relock``), whose box takes the held heading and whose shape restarts at it.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .config import FootprintConfig
from .geometry import Box, points_in_box, wrap_angle

__all__ = ["HeadingFit", "fit_heading", "FootprintCheck", "held_turned"]

_COARSE = np.radians(2.0)    # the heading grid of the search ...
_STEP = np.radians(0.5)      # ... refined around its best
_MAX_POINTS = 256
_BIN = 0.1                   # m: the bins of the points' projections (the lines' width)


@dataclass(frozen=True)
class HeadingFit:
    """The sharpest heading (rad), and how much sharper the points line up there than at the heading searched
    around (>= 1); ``interior``: the best lies inside the search range, not at its end (a rise towards the range's
    end is no peak)."""

    heading: float
    gain: float
    interior: bool


def fit_heading(points: np.ndarray, heading: float, search_range: float) -> HeadingFit:
    """The heading within ``search_range`` (rad) of ``heading`` at which the (N, >= 2) world ``points`` line up
    sharpest along a box's two axes (the largest sum of squared counts of their binned projections): a 2 degree
    grid, then 0.5 degree steps around its best, on at most ``_MAX_POINTS`` of the points (every k-th). Fewer than
    2 points: ``heading`` itself, gain 1."""
    xy = np.asarray(points, dtype=np.float64)[:, :2]
    if len(xy) < 2:
        return HeadingFit(float(heading), 1.0, False)
    xy = xy[::-(-len(xy) // _MAX_POINTS)]
    xy = xy - xy.mean(axis=0)
    coarse = heading + np.arange(-search_range, search_range + _COARSE / 2, _COARSE)
    scores = _sharpness_at(xy, coarse)
    i = int(np.argmax(scores))
    fine = coarse[i] + np.arange(-_COARSE, _COARSE + _STEP / 2, _STEP)
    fine = fine[np.abs(fine - heading) <= search_range + 1e-9]
    fine_scores = _sharpness_at(xy, fine)
    j = int(np.argmax(fine_scores))
    at_heading = float(_sharpness_at(xy, np.array([heading]))[0])
    return HeadingFit(float(fine[j]), float(fine_scores[j]) / max(at_heading, 1e-12), 0 < i < len(coarse) - 1)


def _sharpness_at(xy: np.ndarray, angles: np.ndarray) -> np.ndarray:
    """:func:`_sharpness` of the projections of the centred (N, 2) ``xy`` on both axes of each of ``angles``."""
    c, s = np.cos(angles)[:, None], np.sin(angles)[:, None]
    return _sharpness(c * xy[:, 0] + s * xy[:, 1]) + _sharpness(-s * xy[:, 0] + c * xy[:, 1])


def _bins(values: np.ndarray, shift: float) -> tuple[np.ndarray, int]:
    """Per row of ``values`` (A, N): bin indices of width ``_BIN`` (offset by ``shift`` bins), flattened with a
    row offset, and the bins per row."""
    lo = values.min() - _BIN
    idx = np.floor((values - lo) / _BIN + shift).astype(np.int64)
    width = int(idx.max()) + 1
    return (idx + width * np.arange(values.shape[0])[:, None]).ravel(), width


def _sharpness(values: np.ndarray) -> np.ndarray:
    """Per row: the sum of squared bin counts of its values, averaged over two bin grids half a bin apart."""
    total = np.zeros(values.shape[0])
    for shift in (0.0, 0.5):
        flat, width = _bins(values, shift)
        counts = np.bincount(flat, minlength=width * values.shape[0]).reshape(values.shape[0], width)
        total += (counts.astype(np.float64) ** 2).sum(axis=1)
    return total / values.shape[1] ** 2


def held_turned(points: np.ndarray, heading: float, turn: float, config: FootprintConfig) -> bool:
    """Whether a frame before a footprint turn was held turned too: its object ``points`` (world; at least
    ``min_points``) line up sharpest nearer ``heading`` + ``turn`` than its box's ``heading``."""
    if len(points) < max(config.min_points, 2):
        return False
    offset = float(wrap_angle(fit_heading(points, heading, config.search_range).heading - heading))
    return abs(offset - turn) < abs(offset)


class FootprintCheck:
    """The footprint check of one track (see the module docstring): its settings and the votes in a row."""

    def __init__(self, config: FootprintConfig, relocked: bool = False) -> None:
        self.config = config
        self._offsets: list[float] = []
        self.done = False
        # the measured frames left in which the check runs, -1: every frame (``after_relock`` 0); else only a
        # re-locked track's first ``after_relock`` (its heading is the one it held, e.g. the coast's guess)
        self._left = -1
        if config.after_relock > 0:
            self._left = config.after_relock if relocked else 0

    def turn(self, local: np.ndarray, box: Box, shape: np.ndarray) -> float | None:
        """How far to turn ``box`` (rad), or None: :meth:`test` on the non-ground world points ``local`` in the
        box grown by ``crop_length`` x ``crop_width``, with the aggregated ``shape`` (object frame)."""
        c = self.config
        if c.min_points <= 0 or self._left == 0:
            return None
        if self._left > 0:
            self._left -= 1
        heading = self.test(local[points_in_box(local, box, (c.crop_length, c.crop_width, 1.0))], box.heading, shape)
        return None if heading is None else float(wrap_angle(heading - box.heading))

    def test(self, points: np.ndarray, heading: float, shape: np.ndarray) -> float | None:
        """The heading to turn the box to when this frame completes the run of agreeing frames and the shape
        confirms it, else None. ``points``: the object's non-ground points around the box (world); ``heading``:
        the box's; ``shape``: the aggregated shape (object frame)."""
        c = self.config
        if self.done or c.min_points <= 0:
            return None
        offset = self._vote(points, heading) if len(points) >= c.min_points else None
        if offset is None:
            self._offsets.clear()
            return None
        if self._offsets and abs(offset - self._offsets[-1]) > c.agreement:
            self._offsets.clear()
        self._offsets.append(offset)
        if len(self._offsets) < c.frames:
            return None
        built_turned = self._vote(shape, 0.0)
        if built_turned is None or abs(built_turned - offset) > c.agreement:
            self._offsets.clear()   # the box turned away from a shape that lines up with it: the registration's
            return None             # own error, which it undoes with the shape (turning the box alone overshoots)
        self.done = True
        return float(wrap_angle(heading + offset))

    def _vote(self, points: np.ndarray, heading: float) -> float | None:
        """The offset from ``heading`` at which ``points`` line up sharpest, when it is a vote (see the module
        docstring), else None."""
        c = self.config
        fit = fit_heading(points, heading, c.search_range)
        offset = float(wrap_angle(fit.heading - heading))
        if abs(offset) <= c.min_offset or not fit.interior or fit.gain < c.min_gain:
            return None
        return offset
