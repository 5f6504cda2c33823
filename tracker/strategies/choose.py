"""The strategies of a :class:`~tracker.config.TrackerConfig`, chosen once (:func:`choose_strategies`)."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Callable

from ..config import TrackerConfig
from ..registration import Registration
from .association import Association, CropAssociation, GlobalAssociation
from .first_frame import FinderSearch, FirstFrameSearch, HypothesesSearch, MovingSearch
from .ground import GroundRemover, RoadPoints, choose_ground, choose_road
from .height import HeightModel, choose_height
from .inliers import AllPairs, FixedRansac, ShapeInliers, UpstreamRansac
from .loss import (
    DataFreeFrames,
    IterationReference,
    KeepPrior,
    MotionTermsOnly,
    PriorReference,
    SymmetricConsistency,
    XOnlyConsistency,
)
from .metric import Metric, PlaneMetric, PointMetric
from .reacquire import Reacquire, choose_reacquire
from .travel import NoTravel, choose_travel

__all__ = ["Strategies", "choose_strategies"]


@dataclass
class Strategies:
    ground: GroundRemover
    road: RoadPoints
    registration: Registration
    first_frame: FirstFrameSearch
    height: HeightModel
    reacquire: Reacquire
    travel: NoTravel


def choose_strategies(config: TrackerConfig) -> Strategies:
    c = config
    associations: dict[str, Callable[[int], Association]] = {"global": GlobalAssociation, "crop": CropAssociation}
    association = associations[c.search.association](c.search.max_points)
    ransac = c.shape.ransac
    choices: dict[str, ShapeInliers] = {"none": AllPairs(), "fixed": FixedRansac(ransac),
                                        "upstream": UpstreamRansac(ransac)}
    inliers = choices[ransac.mode]
    metric: Metric = (PlaneMetric(c.registration.normal_neighbors, c.registration.normal_radius)
              if c.registration.metric == "plane" else PointMetric())
    references: dict[str, type[PriorReference | IterationReference]] = {"prior": PriorReference,
                                                                         "iteration": IterationReference}
    consistencies: dict[str, type[SymmetricConsistency | XOnlyConsistency]] = {"symmetric": SymmetricConsistency,
                                                                                "x_only": XOnlyConsistency}
    data_frees: dict[str, type[DataFreeFrames]] = {"prior": KeepPrior, "motion_terms": MotionTermsOnly}
    firsts: dict[str, Callable[[TrackerConfig], FirstFrameSearch]] = {"moving": MovingSearch, "hypotheses": HypothesesSearch,
                                                 "finder": FinderSearch}
    reference = references[c.motion.prior_reference]()
    consistency = consistencies[c.motion.consistency](c.motion.consistency_weight)
    data_free = data_frees[c.registration.data_free_frames]()
    first = firsts[c.first_frame.search]
    return Strategies(ground=choose_ground(c), road=choose_road(c),
                      registration=Registration(c, association, inliers, metric, reference, consistency, data_free),
                      first_frame=first(c), height=choose_height(c.height),
                      reacquire=choose_reacquire(c.reacquire), travel=choose_travel(c.motion))
