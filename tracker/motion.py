"""The moving-average motion prior: prior <- alpha * prior + (1 - alpha) * delta, initialised with delta_1."""

from __future__ import annotations

import numpy as np

from .geometry import wrap_angle

__all__ = ["MotionPrior"]


class MotionPrior:
    """Predicted per-frame motion [dx, dy, dz, dtheta] (zero until the first update)."""

    def __init__(self, alpha: float = 0.5) -> None:
        self.alpha = alpha
        self.delta = np.zeros(4)
        self.initialised = False

    def update(self, delta: np.ndarray) -> np.ndarray:
        delta = np.asarray(delta, dtype=np.float64).copy()
        delta[3] = wrap_angle(delta[3])
        if not self.initialised:
            self.delta = delta
            self.initialised = True
        else:
            self.delta = self.alpha * self.delta + (1.0 - self.alpha) * delta
        return self.delta.copy()
