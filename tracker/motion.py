"""The moving-average motion prior: prior <- alpha * prior + (1 - alpha) * delta, initialised with delta_1.

``frame="world"`` averages the motion [dx, dy, dz, dtheta] as the paper does. ``frame="object"`` averages
(dx, dy) expressed in the previous box's frame (forward / left) and predicts by rotating them with the
current heading: identical on straight roads, and without lag in a steady turn.
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
        if frame not in ("world", "object"):
            raise ValueError(f"motion prior frame must be 'world' or 'object', not {frame!r}")
        self.alpha = alpha
        self.frame = frame
        self._mean = np.zeros(4)  # in the averaging frame
        self.initialised = False

    def update(self, delta: np.ndarray, heading: float = 0.0) -> None:
        """Add the motion ``delta`` (world frame) made from a box with ``heading``."""
        delta = np.asarray(delta, dtype=np.float64).copy()
        delta[3] = wrap_angle(delta[3])
        if self.frame == "object":
            delta[:2] = _rotate(delta[:2], -heading)
        if not self.initialised:
            self._mean = delta
            self.initialised = True
        else:
            self._mean = self.alpha * self._mean + (1.0 - self.alpha) * delta

    def predict(self, heading: float = 0.0) -> np.ndarray:
        """The predicted motion (world frame) from a box with ``heading``."""
        out = self._mean.copy()
        if self.frame == "object":
            out[:2] = _rotate(out[:2], heading)
        return out

    @property
    def delta(self) -> np.ndarray:
        """The averaged motion in the averaging frame (world frame when ``frame="world"``)."""
        return self._mean.copy()
