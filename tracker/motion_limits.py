"""Physical limits on a registered motion: a vehicle cannot turn or change its velocity that suddenly in one frame.

``motion.max_yaw_change``, ``motion.max_speed_change``: the change against the motion model's prediction (the
yaw cap only below ``motion.max_yaw_change_points`` object points, where a few clutter points can swing a fit;
frame 1, whose prediction has no turn at a start, only with ``motion.first_yaw_capped``).
``motion.max_lateral_accel``: the heading change itself, at most the yaw rate a vehicle at the frame's speed can
drive, min(speed / ``min_turn_radius``, ``max_lateral_accel`` / speed) + ``yaw_rate_margin``, per second."""

from __future__ import annotations

import numpy as np

from .config import MotionConfig

__all__ = ["limit_motion"]


def max_yaw_rate(speed: float, params: MotionConfig) -> float:
    """The largest yaw rate (rad/s) of a vehicle driving at ``speed`` (m/s): steering-limited below
    sqrt(max_lateral_accel x min_turn_radius), grip-limited above, plus ``yaw_rate_margin``."""
    steering = speed / params.min_turn_radius
    grip = params.max_lateral_accel / speed if speed > 0 else np.inf
    return float(min(steering, grip) + params.yaw_rate_margin)


def limit_motion(x: np.ndarray, prior: np.ndarray, heading: float, first: bool, steps: int, params: MotionConfig,
                 flags: list[str], dt: float = 0.1, points: int = 0) -> np.ndarray:
    """``x`` with the change of turn rate and velocity against ``prior`` capped and the heading change capped at the
    physical yaw rate over ``dt`` seconds (flags ``yaw_clamped``, ``motion_clamped``); a non-finite ``x`` gives the
    prior (flag ``prior_only``). ``heading``: the box's; ``points``: the object's points in the previous frame."""
    if not np.isfinite(x).all():
        flags.append("prior_only")
        return prior.copy()
    if params.max_lateral_accel > 0 and not first:
        # the box turns at most as fast as a vehicle at the speed this frame's motion gives it (no prior involved)
        cap = max_yaw_rate(float(np.hypot(x[0], x[1])) / dt, params) * dt
        if abs(x[3]) > cap:
            flags.append("yaw_clamped")
            x[3] = np.sign(x[3]) * cap
    sparse = params.max_yaw_change_points <= 0 or points < params.max_yaw_change_points
    yaw_capped = not first or params.first_yaw_capped
    if params.max_yaw_change > 0 and yaw_capped and sparse and abs(x[3] - prior[3]) > params.max_yaw_change:
        if "yaw_clamped" not in flags:  # a vehicle cannot turn that suddenly: the prior's turn rate +- the cap
            flags.append("yaw_clamped")
        x[3] = prior[3] + np.sign(x[3] - prior[3]) * params.max_yaw_change
    if params.max_speed_change > 0 and not first and steps > 2:
        # a vehicle's velocity changes little in 0.1 s: cap the deviation from the prediction in the box frame
        ch, sh = np.cos(heading), np.sin(heading)
        dev = x[:2] - prior[:2]
        along, across = ch * dev[0] + sh * dev[1], -sh * dev[0] + ch * dev[1]
        cap_along, cap_across = params.max_speed_change, 0.5 * params.max_speed_change
        if abs(along) > cap_along or abs(across) > cap_across:
            flags.append("motion_clamped")
            along, across = np.clip(along, -cap_along, cap_along), np.clip(across, -cap_across, cap_across)
            x[:2] = prior[:2] + np.array([ch * along - sh * across, sh * along + ch * across])
    return x
