"""The moving-average motion prior: prior <- alpha * prior + (1 - alpha) * delta, initialised with delta_1.

``frame="world"`` averages the motion [dx, dy, dz, dtheta] as the paper does. ``frame="object"`` averages
(dx, dy) expressed in the previous box's frame (forward / left) and predicts by rotating them with the
current heading: identical on straight roads, and without lag in a steady turn, but a heading error of the box
turns the predicted motion with it. ``frame="turn"`` averages in the world frame, but before each update the
average velocity is turned by the averaged turn rate (and predicted turned by it once more): no lag in a steady
turn, and the box's own heading never enters, so on a straight road it stays anchored to the displacements
like ``"world"``.
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

    def __init__(self, alpha: float = 0.5, frame: str = "world") -> None:
        if frame not in ("world", "object", "turn"):
            raise ValueError(f"motion prior frame must be 'world', 'object' or 'turn', not {frame!r}")
        self.alpha = alpha
        self.frame = frame
        self._mean = np.zeros(4)  # in the averaging frame
        self.initialised = False

    def update(self, delta: np.ndarray, heading: float = 0.0, interval: float = 1.0) -> None:
        """Add the motion ``delta`` (world frame) made from a box with ``heading``. ``interval``: the time the
        motion took in the units of the average (1 for per-frame averages; seconds for per-second ones)."""
        delta = np.asarray(delta, dtype=np.float64).copy()
        delta[3] = wrap_angle(delta[3])
        if self.frame == "object":
            delta[:2] = _rotate(delta[:2], -heading)
        if not self.initialised:
            self._mean = delta
            self.initialised = True
        else:
            if self.frame == "turn":  # the average velocity as it points now: turned by the average turn
                self._mean[:2] = _rotate(self._mean[:2], self._mean[3] * interval)
            self._mean = self.alpha * self._mean + (1.0 - self.alpha) * delta

    def predict(self, heading: float = 0.0, interval: float = 1.0) -> np.ndarray:
        """The predicted motion (world frame) from a box with ``heading`` over ``interval`` (see update)."""
        out = self._mean.copy()
        if self.frame == "object":
            out[:2] = _rotate(out[:2], heading)
        elif self.frame == "turn":
            out[:2] = _rotate(out[:2], out[3] * interval)
        return out

    @property
    def delta(self) -> np.ndarray:
        """The averaged motion in the averaging frame (world frame when ``frame="world"``)."""
        return self._mean.copy()
