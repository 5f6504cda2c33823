"""All SOTracker parameters in one frozen dataclass, plus the named presets of the paper's ablations.

Defaults are the paper's / the authors' implementation's values (see docs/tracker.md for where we
deviate and why). ``full`` is the complete method tuned for speed (few outer iterations with an
early stop); ``faithful`` reproduces the authors' implementation (whole-sweep ground removal, their
frame-1 Finder, crop association, their RANSAC and iteration counts; docs/tracker.md compares the three).
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from typing import Any

from .ground import GroundParams

__all__ = ["TrackerConfig", "PRESETS", "DETECTION_PRESETS", "get_preset", "preset_names"]


@dataclass(frozen=True)
class TrackerConfig:
    """Parameters of one tracking run. Lengths in metres, angles in radians."""

    # --- loss weights (paper: ICP 1, Shape 1, MC 0.1, MP 0.1); a zero weight disables the term
    weight_icp: float = 1.0
    weight_shape: float = 1.0
    weight_mc: float = 0.1
    weight_mp: float = 0.1
    # --- Detection term (Det+SOT, docs/detection.md); weight 0 = off. ``method="det"``: no point
    # registration at all, the detections associated with a constant-velocity Kalman filter (the paper's Det row)
    weight_det: float = 0.0
    det_min_score: float = 0.5           # a detection below this score is never used
    det_min_iou: float = 0.1             # BEV IoU with the motion model's prediction needed to associate
    det_max_distance: float = 0.0        # > 0: no detection passes min_iou -> the nearest centre within this (m)
    method: str = "sot"                  # "sot" (SOTracker, with Det when weight_det > 0) or "det" (baseline)
    # --- search regions (box size factors, applied to length, width AND height)
    search_scale: float = 1.5            # gamma_in
    first_search_scale: float = 3.0      # frame-1 wide search
    first_icp_iterations: int = 50       # ICP-only outer iterations of the frame-1 search
    first_search: str = "moving"         # "moving": the crop follows the estimate, source = previous points +
                                         # sub-shape; "finder" (upstream): start-box points (x1.0) against a
                                         # fixed crop of the start box x first_search_scale (tracker/finder.py)
    crop_scale: float = 1.1              # gamma_aft: previous-frame points for the ICP term
    shape_crop_scale: float = 1.0        # points added to the shape / sub-shape
    # --- shape model
    use_shape: bool = True               # shape term at all
    shape_update: bool = True            # S(All): aggregate at key frames; False = S(1)
    keyframe_interval: int = 5
    voxel_size: float = 0.05
    use_subshape: bool = True
    subshape_frames: int = 2
    # --- association / RANSAC for the shape term
    use_ransac: bool = True
    ransac_max_iterations: int = 200
    ransac_confidence: float = 0.99
    ransac_sample_size: int = 3
    ransac_inlier_threshold: float = 0.2
    ransac_min_inliers: int = 10
    ransac_score_pairs: int = 300        # hypotheses are scored on at most this many random pairs
    max_points: int = 1000               # random subsample of each point set
    min_points: int = 10                 # a term with fewer pairs contributes 0
    data_norm_min: int = 0               # > 0: data terms are sums / max(pairs, this) when the crop is sparse
    min_target_points: int = 5           # a search region with fewer points: the frame runs on the prior
    data_free_frames: str = "prior"      # a frame without data terms: "prior" keeps the prediction (flag
                                         # prior_only); "motion_terms" (upstream) still minimises MP + MC
    icp_metric: str = "point"            # "point" (paper) or "plane": point-to-plane + plane_point_weight * point
    plane_point_weight: float = 0.1
    normal_neighbors: int = 8
    normal_radius: float = 0.5
    max_pair_distance: float = 0.0       # > 0: ICP pairs farther than this are dropped (0 = keep all, upstream)
    association: str = "global"          # "global": one kd-tree over the local points, pairs whose target is
                                         # outside the crop dropped, subsets drawn once per frame; "crop"
                                         # (upstream): 1-NN among the crop's points, source and crop resampled
                                         # (<= max_points, with replacement) every outer iteration
    ransac_mode: str = "fixed"           # "fixed": the same hypotheses every outer iteration, < ransac_min_inliers
                                         # inliers drops the shape term; "upstream": the estimate itself is the
                                         # first hypothesis, new draws every outer iteration, too few inliers
                                         # keeps all pairs
    # --- motion prior
    alpha: float = 0.5                   # prior <- alpha * prior + (1 - alpha) * delta
    prior_frame: str = "world"           # "world" (paper); "object": average the motion in the box frame;
                                         # "turn": world frame, turned by the averaged turn rate (tracker/motion.py)
    z_mode: str = "icp"                  # "icp": dz from the loss like dx, dy; "ground": the box keeps its start
                                         # height above the local road plane; "fixed": dz = 0; "filter": slow
                                         # estimate from the registration's z with the road as a prior
    max_speed_change: float = 0.0        # > 0: |dx, dy - predicted| capped at this along / half across (m/frame)
    min_quality: float = 0.0             # > 0: a frame whose fit quality is below this continues on the prior
    max_yaw_change: float = 0.0          # > 0: |dtheta - predicted dtheta| is capped at this per frame (rad)
    coast_yaw_decay: float = 0.5         # frames without data: the predicted turn rate decays by this per frame
    # --- robust online tracking (issue 12); the defaults keep the paper's behaviour
    motion_model: str = "average"        # "average": moving-average prior (paper); "ctrv": CTRV Kalman filter over
                                         # [x, y, heading, speed, turn rate], predicted with the elapsed time (s);
                                         # the box heading is the filtered one (the box turns about its points)
    prior_per_second: bool = False       # "average": the prior is a velocity (motion / elapsed time), predicted
                                         # for the elapsed time (frame gaps); False = per frame (paper)
    ctrv_accel_sigma: float = 4.0        # m/s^2, acceleration noise of the CTRV filter
    ctrv_yaw_accel_sigma: float = 3.0    # rad/s^2, turn-rate noise (abrupt steering)
    ctrv_position_sigma: float = 0.1     # m, noise of the registered centre as a measurement
    ctrv_heading_sigma: float = 0.05     # rad, noise of the registered heading as a measurement
    travel_heading_sigma: float = 0.0    # > 0 (ctrv): the direction of travel of the object's points is a heading
                                         # measurement with this noise floor (rad) (+ position noise / distance)
    travel_min_distance: float = 0.2     # m: shorter displacements give no travel heading
    first_motion_along_heading: bool = False  # "average": the first motion (frame 1's, or start()'s initial_motion)
                                         # seeds the prior with only its part along the start box's heading (its
                                         # sideways part would be predicted on as a sideways velocity)
    first_hypotheses: int = 0            # > 0: frame-1 search from this many motions along the heading (scored by
                                         # the points they explain) in the normal search box; 0 = one wide search
    first_max_speed: float = 30.0        # m/s: the frame-1 hypotheses reach this far forward (a third backwards)
    first_max_yaw: float = 0.0           # > 0: frame-1 heading change cap (rad)
    height_drift_sigma: float = 0.02     # z_mode "filter": z random walk per frame (m)
    height_fit_sigma: float = 0.15       # z_mode "filter": noise of the registration's z (m)
    height_road_sigma: float = 0.05      # z_mode "filter": noise of road height + offset (m)
    height_offset_gain: float = 0.05     # z_mode "filter": the height above the road follows the estimate this slowly
    height_road: str = "local"           # z_mode "filter"/"ground": the road under the box from "local" per-cell
                                         # planes (tracker/ground.py, fitted for this even when ground_scope is
                                         # "sweep"), from the points the ground "removal" took, or "none"
    reacquire: bool = False              # a start box holding fewer than min_target_points points: hold it and
                                         # search ahead (first_max_speed x time since the start) and a third
                                         # back along its heading; once min_target_points are found, restart
                                         # there with the travelled motion as the prior (see docs/tracker.md)
    search_growth: float = 0.0           # > 0 (ctrv): the search box grows by this many sigmas of the predicted centre
    max_search_scale: float = 4.0        # cap of the grown search scale
    mp_reference: str = "prior"          # "prior" (paper) or "iteration" (upstream: previous outer iteration)
    symmetric_mc: bool = True            # MC on both components; False = upstream's x-only form
    # --- ground removal (GPF, Zermas et al. 2017)
    ground_removal: bool = True
    ground_scope: str = "local"          # "local": per-cell planes on the tracker's local region (tracker/ground.py);
                                         # "sweep" (upstream): one plane for the whole sweep in the ego (sensor)
                                         # frame (tracker/sweep_ground.py)
    gpf_lpr_count: int = 20              # lowest-point representative: mean z of this many lowest points
    gpf_seed_threshold: float = 1.2      # seeds: points lower than LPR + this
    gpf_distance_threshold: float = 0.3  # ground: distance to the plane below this
    gpf_iterations: int = 10
    gpf_segment_length: float = 8.0      # per-segment planes along the principal direction
    gpf_outlier_depth: float = 0.5       # drop points this far below the robust lowest level (sub-ground noise)
    gpf_margin: float = 1.5              # ground is fitted on the search box grown by this much (BEV)
    # --- solver
    outer_iterations: int = 20           # max outer iterations (correspondences recomputed each)
    solver_iterations: int = 10          # max Gauss-Newton/LM steps per outer iteration
    anderson_depth: int = 0              # > 0: Anderson acceleration of the outer loop with this history
    convergence_tolerance: float = 1e-4  # stop the outer loop when the update is smaller (m / rad)
    # --- misc
    seed: int = 0
    deskew: bool = False                 # de-skew ego motion with per-point times (needs the previous pose)
    preset: str = "custom"

    def replace(self, **changes: Any) -> "TrackerConfig":
        return dataclasses.replace(self, **changes)

    def to_dict(self) -> dict[str, Any]:
        return dataclasses.asdict(self)

    def sweep_ground_args(self) -> tuple[int, float, float, int]:
        """The whole-sweep ground's settings, in the order of :func:`~tracker.sweep_ground.sweep_ground_mask`
        (and of its cache key: every user of one sweep's mask passes the same tuple)."""
        return (self.gpf_lpr_count, self.gpf_seed_threshold, self.gpf_distance_threshold, self.gpf_iterations)

    def ground_params(self) -> GroundParams:
        """The ground-removal settings (the ``gpf_*`` fields) as :class:`~tracker.ground.GroundParams`."""
        return GroundParams(lpr_count=self.gpf_lpr_count, seed_threshold=self.gpf_seed_threshold,
                            distance_threshold=self.gpf_distance_threshold, iterations=self.gpf_iterations,
                            segment_length=self.gpf_segment_length, outlier_depth=self.gpf_outlier_depth)

    @classmethod
    def from_dict(cls, data: dict[str, Any]) -> "TrackerConfig":
        """Config from a dict; unknown keys are an error (ValueError)."""
        names = {f.name for f in dataclasses.fields(cls)}
        unknown = sorted(set(data) - names)
        if unknown:
            raise ValueError(f"unknown tracker config keys: {', '.join(unknown)}")
        base = cls()
        values = {}
        for f in dataclasses.fields(cls):
            if f.name in data:
                default = getattr(base, f.name)
                value = data[f.name]
                if isinstance(default, bool):
                    value = bool(value)
                elif isinstance(default, int):
                    value = int(value)
                elif isinstance(default, float):
                    value = float(value)
                values[f.name] = value
        return cls(**values)

    def __post_init__(self) -> None:
        if self.icp_metric not in ("point", "plane"):
            raise ValueError(f"icp_metric must be 'point' or 'plane', not {self.icp_metric!r}")
        if self.z_mode not in ("icp", "ground", "fixed", "filter"):
            raise ValueError(f"z_mode must be 'icp', 'ground', 'fixed' or 'filter', not {self.z_mode!r}")
        if self.motion_model not in ("average", "ctrv"):
            raise ValueError(f"motion_model must be 'average' or 'ctrv', not {self.motion_model!r}")
        if self.prior_frame not in ("world", "object", "turn"):
            raise ValueError(f"prior_frame must be 'world', 'object' or 'turn', not {self.prior_frame!r}")
        if self.method not in ("sot", "det"):
            raise ValueError(f"method must be 'sot' or 'det', not {self.method!r}")
        if self.mp_reference not in ("prior", "iteration"):
            raise ValueError(f"mp_reference must be 'prior' or 'iteration', not {self.mp_reference!r}")
        choices = {"association": ("global", "crop"), "ransac_mode": ("fixed", "upstream"),
                   "first_search": ("moving", "finder"), "ground_scope": ("local", "sweep"),
                   "height_road": ("local", "removal", "none"),
                   "data_free_frames": ("prior", "motion_terms")}
        for name, allowed in choices.items():
            if getattr(self, name) not in allowed:
                raise ValueError(f"{name} must be one of {', '.join(allowed)}, not {getattr(self, name)!r}")
        if self.association == "crop" and self.icp_metric != "point":
            raise ValueError("association='crop' supports icp_metric='point' only")
        for name in ("search_scale", "first_search_scale", "crop_scale", "voxel_size", "keyframe_interval",
                     "max_points", "ransac_max_iterations", "outer_iterations"):
            if not getattr(self, name) > 0:
                raise ValueError(f"{name} must be positive")


DET_WEIGHT = 0.03  # Detection-term weight of det_sot: ~ (sigma_ICP / sigma_Det)^2, docs/detection.md

_FULL_V1 = TrackerConfig(outer_iterations=10, first_icp_iterations=20, solver_iterations=6, convergence_tolerance=2e-3,
                      anderson_depth=3, symmetric_mc=False, prior_frame="object", alpha=0.6, max_yaw_change=0.03,
                      min_target_points=3, max_points=600, gpf_seed_threshold=0.3, gpf_distance_threshold=0.2,
                      z_mode="ground",
                      preset="full_v1")
# full_v2 = full_v1 + the robust online pieces of issue 12 (each one a field)
_FULL_V2 = _FULL_V1.replace(first_hypotheses=9, first_max_yaw=0.1, z_mode="filter", prior_per_second=True,
                            preset="full_v2")
# full_v3 = full_v2 with one ground plane per sweep, whose ground near the box is the height's road (chosen on the
# generated benchmark and the synthetic worlds, docs/tracker.md "Choosing full on the generated benchmark")
_FULL_V3 = _FULL_V2.replace(ground_scope="sweep", height_road="removal", preset="full_v3")
# full_v4 = full_v3 with the turn-rate prior: the world-frame average motion turned by the averaged turn rate, so
# the box's heading error never steers the prediction (chosen on the generated benchmark and the synthetic
# worlds with 3 seeds, docs/tracker.md "The motion prior's frame, again"; `full` of 2026-11-26)
_FULL_V4 = _FULL_V3.replace(prior_frame="turn", preset="full_v4")
# full = full_v4 with frame 1's motion seeding the prior only along the start box's heading (chosen on the generated
# benchmark and the synthetic worlds with 3 seeds, docs/tracker.md "A rear view")
_FULL = _FULL_V4.replace(first_motion_along_heading=True, preset="full")
_FAITHFUL = TrackerConfig(outer_iterations=20, first_icp_iterations=50, solver_iterations=50,
                          convergence_tolerance=0.0, mp_reference="iteration", symmetric_mc=False,
                          ground_scope="sweep", first_search="finder", association="crop", ransac_mode="upstream",
                          ransac_score_pairs=1000, min_target_points=10, coast_yaw_decay=1.0,
                          data_free_frames="motion_terms",
                          preset="faithful")

PRESETS: dict[str, TrackerConfig] = {
    "full": _FULL,
    "full_v1": _FULL_V1,
    "full_v2": _FULL_V2,
    "full_v3": _FULL_V3,
    "full_v4": _FULL_V4,
    "faithful": _FAITHFUL,
    "icp_mp": _FULL.replace(use_shape=False, weight_mc=0.0, preset="icp_mp"),
    "icp_mp_s1": _FULL.replace(shape_update=False, weight_mc=0.0, preset="icp_mp_s1"),
    "icp_mp_sall": _FULL.replace(weight_mc=0.0, preset="icp_mp_sall"),
    "no_ground_removal": _FULL.replace(ground_removal=False, preset="no_ground_removal"),
    "no_ransac": _FULL.replace(use_ransac=False, preset="no_ransac"),
    "no_subshape": _FULL.replace(use_subshape=False, preset="no_subshape"),
    # the paper's Det+SOT row: full + the Detection term (weight: docs/detection.md)
    "det_sot": _FULL.replace(weight_det=DET_WEIGHT, preset="det_sot"),
    # the paper's Det row: detections + a constant-velocity Kalman filter, no point registration
    "det": _FULL.replace(method="det", preset="det"),
}


# presets that need per-frame detections (track(..., detections=...))
DETECTION_PRESETS: tuple[str, ...] = ("det_sot", "det")


def preset_names() -> list[str]:
    return list(PRESETS)


def get_preset(name: str, **overrides: Any) -> TrackerConfig:
    """A named preset (see PRESETS), optionally with fields replaced. Unknown name: ValueError."""
    if name not in PRESETS:
        raise ValueError(f"unknown tracker preset {name!r}; known: {', '.join(PRESETS)}")
    config = PRESETS[name]
    return config.replace(**overrides) if overrides else config
