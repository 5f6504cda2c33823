"""Frame-1 search strategies (``first_frame.search``): the motion frame 1's regular step starts from.

Frame 1 has no motion prior. :class:`MovingSearch`: one ICP-only search from the prediction in the start box
scaled ``first_frame.scale``, the crop following the estimate. :class:`HypothesesSearch`: ICP-only searches from
motions along the heading (and an associated detection's motion) in the normal search box, the one explaining
the most points winning (tracker/first_frame.py). :class:`FinderSearch` (upstream): the start-box points against
a fixed wide crop (tracker/finder.py). ``scale`` is the search scale of frame 1's regular step.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Callable, Protocol

import numpy as np

from ..config import TrackerConfig
from ..finder import finder_icp
from ..first_frame import explained_points, motion_hypotheses
from ..geometry import Box
from ..registration import box_moved
from ..terms import apply_motion

__all__ = ["FrameOne", "FirstFrameSearch", "MovingSearch", "HypothesesSearch", "FinderSearch"]


@dataclass(frozen=True)
class FrameOne:
    """What a frame-1 search sees. ``icp(x0, scale, outer)``: an ICP-only registration from motion ``x0``."""

    box: Box                       # the start box
    local: np.ndarray              # frame 1's local points
    prior: np.ndarray              # the motion model's prediction
    det_target: np.ndarray | None  # an associated detection's motion
    dt: float                      # seconds since the start frame
    source: np.ndarray             # the start frame's points in the box scaled search.crop_scale
    start_points: np.ndarray       # the start frame's points in the start box
    rng: np.random.Generator
    icp: Callable[[np.ndarray, float, int], np.ndarray]


class FirstFrameSearch(Protocol):
    scale: float

    def motion(self, f: FrameOne) -> np.ndarray:
        """The motion frame 1's regular step starts from."""


class MovingSearch:
    def __init__(self, config: TrackerConfig) -> None:
        self.scale = config.first_frame.scale
        self.iterations = config.first_frame.icp_iterations

    def motion(self, f: FrameOne) -> np.ndarray:
        return f.icp(f.prior, self.scale, self.iterations)


class HypothesesSearch:
    def __init__(self, config: TrackerConfig) -> None:
        self.first = config.first_frame
        self.scale = config.search.scale

    def motion(self, f: FrameOne) -> np.ndarray:
        first = self.first
        best, best_score = np.zeros(4), -1
        starts = list(motion_hypotheses(f.box.heading, first.hypotheses, first.max_speed * f.dt,
                                        first.max_speed * f.dt / 3.0))
        if f.det_target is not None:  # the associated detection's motion is one more hypothesis (first: wins ties)
            starts.insert(0, f.det_target)
        for x0 in starts:
            x = f.icp(x0, self.scale, first.icp_iterations)
            if first.max_yaw > 0:
                x[3] = np.clip(x[3], -first.max_yaw, first.max_yaw)
            score = explained_points(f.local, box_moved(f.box, x), apply_motion(x, f.source, f.box.center), 0.2)
            if score > best_score:
                best, best_score = x, score
        return best


class FinderSearch:
    def __init__(self, config: TrackerConfig) -> None:
        self.config = config
        self.scale = config.first_frame.scale

    def motion(self, f: FrameOne) -> np.ndarray:
        c = self.config
        return finder_icp(f.start_points, f.local, f.box, f.rng, scale=c.first_frame.scale,
                          iterations=c.first_frame.icp_iterations, max_points=c.search.max_points,
                          min_points=c.registration.min_points, solver_iterations=c.registration.solver_iterations)
