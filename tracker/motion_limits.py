"""Physical limits on a registered motion relative to the motion model's prediction (``motion.max_yaw_change``,
``motion.max_speed_change``): a vehicle cannot turn or change its velocity that suddenly in one frame."""

from __future__ import annotations

import numpy as np

from .config import MotionConfig

__all__ = ["limit_motion"]


def limit_motion(x: np.ndarray, prior: np.ndarray, heading: float, first: bool, steps: int, params: MotionConfig,
                 flags: list[str]) -> np.ndarray:
    """``x`` with the change of turn rate and velocity against ``prior`` capped (flags ``yaw_clamped``,
    ``motion_clamped``); a non-finite ``x`` gives the prior (flag ``prior_only``). ``heading``: the box's."""
    if not np.isfinite(x).all():
        flags.append("prior_only")
        return prior.copy()
    if params.max_yaw_change > 0 and not first and abs(x[3] - prior[3]) > params.max_yaw_change:
        flags.append("yaw_clamped")  # a vehicle cannot turn that suddenly: keep the prior's turn rate +- the cap
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
