"""The strategies of a :class:`~tracker.config.TrackerConfig`, chosen once (:func:`choose_strategies`)."""

from __future__ import annotations

from dataclasses import dataclass

from ..config import TrackerConfig
from ..registration import Registration
from .association import CropAssociation, GlobalAssociation
from .first_frame import FinderSearch, FirstFrameSearch, HypothesesSearch, MovingSearch
from .ground import GroundRemover, RoadPoints, choose_ground, choose_road
from .height import HeightModel, choose_height
from .inliers import AllPairs, FixedRansac, UpstreamRansac
from .loss import (IterationReference, KeepPrior, MotionTermsOnly, PriorReference, SymmetricConsistency,
                   XOnlyConsistency)
from .metric import PlaneMetric, PointMetric

__all__ = ["Strategies", "choose_strategies"]


@dataclass
class Strategies:
    ground: GroundRemover
    road: RoadPoints
    registration: Registration
    first_frame: FirstFrameSearch
    height: HeightModel


def choose_strategies(config: TrackerConfig) -> Strategies:
    c = config
    association = {"global": GlobalAssociation, "crop": CropAssociation}[c.search.association](c.search.max_points)
    ransac = c.shape.ransac
    inliers = {"none": AllPairs(), "fixed": FixedRansac(ransac), "upstream": UpstreamRansac(ransac)}[ransac.mode]
    metric = (PlaneMetric(c.registration.normal_neighbors, c.registration.normal_radius)
              if c.registration.metric == "plane" else PointMetric())
    reference = {"prior": PriorReference, "iteration": IterationReference}[c.motion.prior_reference]()
    consistency = {"symmetric": SymmetricConsistency,
                   "x_only": XOnlyConsistency}[c.motion.consistency](c.motion.consistency_weight)
    data_free = {"prior": KeepPrior, "motion_terms": MotionTermsOnly}[c.registration.data_free_frames]()
    first = {"moving": MovingSearch, "hypotheses": HypothesesSearch, "finder": FinderSearch}[c.first_frame.search]
    return Strategies(ground=choose_ground(c), road=choose_road(c),
                      registration=Registration(c, association, inliers, metric, reference, consistency, data_free),
                      first_frame=first(c), height=choose_height(c.height))
