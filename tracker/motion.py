"""The moving-average motion prior: prior <- alpha * prior + (1 - alpha) * delta, initialised with delta_1.

``frame="world"`` averages the motion [dx, dy, dz, dtheta] as the paper does. ``frame="object"`` averages
(dx, dy) expressed in the previous box's frame (forward / left) and predicts by rotating them with the
current heading: identical on straight roads, and without lag in a steady turn, but a heading error of the box
turns the predicted motion with it. ``frame="turn"`` averages in the world frame, but before each update the
average velocity is turned by the averaged turn rate (and predicted turned by it once more): no lag in a steady
turn, and the box's own heading never enters, so on a straight road it stays anchored to the displacements
like ``"world"``.

``trend`` (beta > 0): beside the average, Holt's linear trend (double exponential smoothing, the same ``alpha``): a
level and its change per unit of ``interval`` (the trend, averaged with weight ``beta``; turned with the velocity
in the ``"turn"`` frame). A frame with data is predicted as level + trend, so a steady turn-rate or speed ramp
(entering a turn, braking, accelerating) is followed without the average's lag of ``alpha / (1 - alpha)``
frames. A coasting frame (:meth:`predict` with ``trend_share=0``) is predicted on the plain average: the
motions just before a loss are often a partial view sliding, and neither a ramp nor a level that followed them
closely is carried over frames without data. beta = 0: the plain average only. ``trend_velocity=False``: the
trend acts on the turn rate only (the velocity's level and trend stay the average's).
"""

from __future__ import annotations

import numpy as np

from .geometry import wrap_angle

__all__ = ["MotionPrior"]


def _rotate(xy: np.ndarray, angle: float) -> np.ndarray:
    c, s = np.cos(angle), np.sin(angle)
    return np.array([c * xy[0] - s * xy[1], s * xy[0] + c * xy[1]])


class MotionPrior:
    """Predicted per-frame motion [dx, dy, dz, dtheta] (zero until the first update)."""

    def __init__(self, alpha: float = 0.5, frame: str = "world", trend: float = 0.0,
                 trend_velocity: bool = True) -> None:
        if frame not in ("world", "object", "turn"):
            raise ValueError(f"motion prior frame must be 'world', 'object' or 'turn', not {frame!r}")
        self.alpha = alpha
        self.frame = frame
        self.trend = trend
        self._trended = np.array([trend_velocity] * 3 + [True])  # the components the trend acts on
        self._mean = np.zeros(4)  # in the averaging frame
        self._level = np.zeros(4)  # Holt's level and trend (its change per unit of interval), trend > 0
        self._slope = np.zeros(4)
        self.initialised = False

    def update(self, delta: np.ndarray, heading: float = 0.0, interval: float = 1.0, support: float = 1.0) -> None:
        """Add the motion ``delta`` (world frame) made from a box with ``heading``. ``interval``: the time the
        motion took in the units of the average (1 for per-frame averages; seconds for per-second ones).
        ``support`` (0..1): how much of the level's change the trend takes (it decays by ``1 - trend`` either
        way: a motion the data pin weakly adds little trend)."""
        delta = np.asarray(delta, dtype=np.float64).copy()
        delta[3] = wrap_angle(delta[3])
        if self.frame == "object":
            delta[:2] = _rotate(delta[:2], -heading)
        if not self.initialised:
            self._mean = delta
            self._level = delta.copy()
            self.initialised = True
            return
        if self.frame == "turn":  # the average velocity as it points now: turned by the average turn
            self._mean[:2] = _rotate(self._mean[:2], self._mean[3] * interval)
        self._mean = self.alpha * self._mean + (1.0 - self.alpha) * delta
        if self.trend > 0 and interval > 0:
            if self.frame == "turn":
                turn = self._level[3] * interval
                self._level[:2], self._slope[:2] = _rotate(self._level[:2], turn), _rotate(self._slope[:2], turn)
            level = self.alpha * (self._level + self._slope * interval) + (1.0 - self.alpha) * delta
            level[:3] = np.where(self._trended[:3], level[:3], self._mean[:3])
            change = (level - self._level) / interval
            self._slope = (self.trend * support * change + (1.0 - self.trend) * self._slope) * self._trended
            self._level = level

    def predict(self, heading: float = 0.0, interval: float = 1.0, trend_share: float = 1.0) -> np.ndarray:
        """The predicted motion (world frame) from a box with ``heading`` over ``interval`` (see update):
        the average moved ``trend_share`` (0..1; trend > 0) of the way to Holt's level + trend."""
        out = self._mean.copy()
        if trend_share > 0 and self.trend > 0:
            ahead = self._level + self._slope * interval
            if ahead[:2] @ self._level[:2] < 0:  # a speed ramp is not extrapolated through a stop into reversing
                ahead[:2] = 0.0
            out += trend_share * (ahead - out)
        if self.frame == "object":
            out[:2] = _rotate(out[:2], heading)
        elif self.frame == "turn":
            out[:2] = _rotate(out[:2], out[3] * interval)
        return out

    @property
    def delta(self) -> np.ndarray:
        """The averaged motion in the averaging frame (world frame when ``frame="world"``)."""
        return self._mean.copy()
