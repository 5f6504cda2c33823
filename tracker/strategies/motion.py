"""Motion-model strategies (``motion.model``): the paper's moving-average prior averaged in the world frame
("average"), in the box frame ("object") or in the world frame turned by the averaged turn rate ("turn")
(:class:`~tracker.motion_filter.AverageMotion`), or a CTRV Kalman filter ("ctrv",
:class:`~tracker.motion_filter.CTRVMotion`)."""

from __future__ import annotations

from ..config import MotionConfig
from ..geometry import Box
from ..motion_filter import AverageMotion, CTRVMotion, CTRVParams
from ..speed_ramp import SpeedRamp

__all__ = ["choose_motion_model"]

_AVERAGE_FRAMES = {"average": "world", "object": "object", "turn": "turn"}


def choose_motion_model(params: MotionConfig, box: Box) -> AverageMotion | CTRVMotion:
    """A fresh motion model for a track starting at ``box``."""
    if params.model == "ctrv":
        k = params.ctrv
        return CTRVMotion(box, CTRVParams(accel_sigma=k.accel_sigma, yaw_accel_sigma=k.yaw_accel_sigma),
                          k.position_sigma, k.heading_sigma, k.travel_heading_sigma, k.travel_min_distance)
    return AverageMotion(params.alpha, _AVERAGE_FRAMES[params.model], params.coast_yaw_decay, params.per_second,
                         params.first_motion_along_heading, params.trend, params.trend_points,
                         params.trend_velocity, params.first_turn_points,
                         params.first_turn_max,
                         SpeedRamp(params.ramp_frames, params.ramp_min_t, params.ramp_min_accel,
                                   params.ramp_accelerating_only)
                         if params.ramp_frames > 0 else None, params.coast_max_slip, params.coast_max_slide,
                         params.coast_steady_frames, params.coast_steady_max)
