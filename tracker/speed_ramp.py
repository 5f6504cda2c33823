"""A speed ramp the moving average lags: the track's acceleration along its path, taken only where consistent.

The moving average of the registered motions lags a steady speed ramp (accelerating, braking) by
alpha / (1 - alpha) + 1 frames. :class:`SpeedRamp` keeps the speeds of the last ``frames`` registered motions
(each at the middle of its interval) and fits a line to them: its slope is the acceleration, and its value at the
middle of the next interval the speed the next motion is predicted to have. The line is trusted only as far as
the speeds lie on it: with t = |slope| / (its standard error) the weight is 0 up to t = ``min_t`` and 1 from
2 ``min_t`` (linear between), and 0 where |slope| < ``min_accel``; it is then scaled by how much of the slope the
recent half of the window still shows (a ramp that ends is let go within a few frames). With
``accelerating_only`` a falling line (braking) has no weight: the prediction stays the average's. A steady
track's speeds scatter about a flat line (t small): its prediction stays the average's. A sparse or partly seen
object's registered speeds scatter widely: the same. A run of motions that is broken (a frame without data) starts the
ramp afresh.
"""

from __future__ import annotations

import numpy as np

__all__ = ["SpeedRamp"]


def _line(t: np.ndarray, s: np.ndarray) -> tuple[float, float]:
    """The least-squares slope of s over t and its standard error (0 through 3 or more exact points)."""
    tc, sc = t - t.mean(), s - s.mean()
    sxx = float(tc @ tc)
    slope = float(tc @ sc) / sxx
    residual = sc - slope * tc
    return slope, float(np.sqrt(float(residual @ residual) / (len(t) - 2) / sxx))


class SpeedRamp:
    """The speeds of the last ``frames`` motions, in the units of the motion average (per second or per frame)."""

    def __init__(self, frames: int, min_t: float = 4.0, min_accel: float = 1.0,
                 accelerating_only: bool = False) -> None:
        if frames < 3:
            raise ValueError(f"a speed ramp needs at least 3 motions, got {frames}")
        self.frames = frames
        self.min_t = min_t
        self.min_accel = min_accel
        self.accelerating_only = accelerating_only
        self._times: list[float] = []
        self._speeds: list[float] = []
        self._clock = 0.0

    def reset(self) -> None:
        """Forget the motions (a frame without data broke the run)."""
        self._times.clear()
        self._speeds.clear()

    def add(self, speed: float, interval: float) -> None:
        """A motion of ``speed`` over the ``interval`` that ends now."""
        self._times.append(self._clock + 0.5 * interval)
        self._speeds.append(float(speed))
        self._clock += interval
        if len(self._times) > self.frames:
            del self._times[0], self._speeds[0]

    def ramp(self) -> tuple[float, float]:
        """(acceleration, weight in 0..1) of the line through the speeds; (0, 0) before ``frames`` motions.

        The weight is also the share of the acceleration the recent half of the window still shows (its own line's
        slope over the whole window's, clipped to 0..1): where a ramp ends (the vehicle stops accelerating, or
        comes to a stop and creeps), the whole window's line would drive on for half a window; the recent half's
        flat line takes the weight away within a few frames. With ``accelerating_only`` a falling line's weight is
        0 (a braking vehicle keeps the average's prediction)."""
        if len(self._times) < self.frames:
            return 0.0, 0.0
        t = np.asarray(self._times) - self._times[-1]
        s = np.asarray(self._speeds)
        slope, se = _line(t, s)
        if abs(slope) < self.min_accel or slope == 0.0 or (self.accelerating_only and slope < 0.0):
            return slope, 0.0
        stat = abs(slope) / se if se > 0 else np.inf
        weight = float(np.clip((stat - self.min_t) / self.min_t, 0.0, 1.0)) if self.min_t > 0 else 1.0
        half = max(self.frames // 2, 3)
        recent, _ = _line(t[-half:], s[-half:])
        return slope, weight * float(np.clip(recent / slope, 0.0, 1.0))

    def speed(self, interval: float) -> tuple[float, float]:
        """(speed, weight): the line's speed at the middle of the next ``interval`` (never below 0: a ramp is not
        extrapolated through a stop into reversing) and how far it is trusted."""
        slope, weight = self.ramp()
        if weight <= 0:
            return 0.0, 0.0
        t_next = self._clock + 0.5 * interval
        mean_t, mean_s = float(np.mean(self._times)), float(np.mean(self._speeds))
        return max(mean_s + slope * (t_next - mean_t), 0.0), weight
