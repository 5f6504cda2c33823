"""The per-frame registration (the paper's Algorithm 2): the outer loop of correspondences and loss minimisation.

Each outer iteration crops the local points with the box moved by the current motion and scaled ``scale``,
pairs the ICP source (previous-frame object points + sub-shape) and the shape with the crop (the association
strategy), keeps the shape pairs the inlier strategy accepts, and minimises the loss over [dx, dy, dz, dtheta]
(Levenberg–Marquardt, analytic Jacobians) with the motion terms (MC, MP towards the reference strategy's
reference, Detection); it stops when the update is below ``convergence_tolerance``.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from .association import NearestNeighbors, random_subset
from .config import TrackerConfig
from .geometry import Box, points_in_box, wrap_angle
from .shape import to_world_frame
from .solver import solve
from .strategies.association import Association, Pairs
from .strategies.inliers import ShapeInliers
from .strategies.loss import Consistency, DataFreeFrames, IterationReference, PriorReference
from .strategies.metric import FrameTarget, Metric
from .terms import (
    PairMoments,
    ResidualBlock,
    apply_motion,
    detection_block,
    motion_prior_block,
    point_pair_block,
    travel_heading_block,
)

__all__ = ["Anderson", "Registration", "box_moved", "frame_pairs", "unmove"]


def box_moved(box: Box, x: np.ndarray) -> Box:
    """``box`` moved by the motion [dx, dy, dz, dtheta]."""
    return Box(box.x + x[0], box.y + x[1], box.z + x[2], float(wrap_angle(box.heading + x[3])),
               box.length, box.width, box.height)


def unmove(x: np.ndarray, points: np.ndarray, pivot: np.ndarray) -> np.ndarray:
    """The inverse of :func:`~tracker.terms.apply_motion`: the points that ``x`` moves onto ``points``."""
    c, s = np.cos(x[3]), np.sin(x[3])
    a = points[:, :2] - pivot[:2] - x[:2]
    out = np.empty_like(points)
    out[:, 0] = c * a[:, 0] + s * a[:, 1] + pivot[0]
    out[:, 1] = -s * a[:, 0] + c * a[:, 1] + pivot[1]
    out[:, 2] = points[:, 2] - x[2]
    return out


def frame_pairs(x: np.ndarray, source: NearestNeighbors, pivot: np.ndarray, local: np.ndarray, inside: np.ndarray,
                max_distance: float) -> Pairs:
    """Frame-to-source pairs: each local point ``inside`` (indices) paired with the source point nearest to it
    once the source is moved by ``x``; pairs farther than ``max_distance`` dropped. The same tuple as
    :meth:`~tracker.strategies.association.Association.pairs`: (source, local index, distance, moved source,
    target). Where the source holds more of the object than the frame sees (the shape, or a nearer earlier
    view), every frame point has its counterpart and the source's unseen parts pull on nothing."""
    tgt = local[inside]
    dist, sidx = source.query(unmove(x, tgt, pivot))
    keep = dist <= max_distance
    src = source.target[sidx[keep]]
    return src, inside[keep], dist[keep], apply_motion(x, src, pivot), tgt[keep]


class Anderson:
    """Anderson acceleration of the outer (ICP-style) fixed-point iteration x <- F(x) (AA-ICP).

    ``step(x, F(x) - x)`` returns the next iterate: the plain step while the history is short or the
    extrapolation jumps implausibly far from the plain step (0.5 m, 0.15 rad), else the Anderson mix.
    """

    def __init__(self, depth: int) -> None:
        self.depth = depth
        self.xs: list[np.ndarray] = []
        self.fs: list[np.ndarray] = []

    def step(self, x: np.ndarray, f: np.ndarray) -> np.ndarray:
        self.xs.append(x.copy())
        self.fs.append(f.copy())
        self.xs, self.fs = self.xs[-(self.depth + 1):], self.fs[-(self.depth + 1):]
        plain = x + f
        if len(self.xs) < 2:
            return plain
        dx = np.diff(np.array(self.xs), axis=0).T   # (4, m)
        df = np.diff(np.array(self.fs), axis=0).T
        gamma, *_ = np.linalg.lstsq(df, f, rcond=None)
        mixed = plain - (dx + df) @ gamma
        jump = np.abs(mixed - plain)
        if not np.isfinite(mixed).all() or np.any(jump > np.array([0.5, 0.5, 0.3, 0.15])):
            return plain
        return mixed


@dataclass
class _FramePairing:
    """Which way each data term pairs (``registration.pairing`` / ``pairing_terms``): trees over the frame's
    source and shape for frame-to-source pairs, built once per frame and only when a term uses them. With
    "coverage" each term's direction is decided once per frame (:meth:`_decide`); its crop subsets are drawn from
    a generator of its own, so a frame paired source-to-frame is the frame "source" gives."""

    config: TrackerConfig
    trees: dict[str, NearestNeighbors]
    rng: np.random.Generator | None = None
    directions: dict[str, str] = field(default_factory=dict)

    @classmethod
    def of(cls, config: TrackerConfig, source: np.ndarray, shape: np.ndarray, seed: int) -> "_FramePairing":
        reg = config.registration
        names = ("icp", "shape") if reg.pairing_terms == "both" else (reg.pairing_terms,)
        sets = {"icp": source, "shape": shape}
        trees = {} if reg.pairing == "source" else {n: NearestNeighbors(sets[n]) for n in names if len(sets[n])}
        return cls(config, trees, np.random.default_rng(seed) if reg.pairing == "coverage" else None)

    def inside(self, mask: np.ndarray, rng: np.random.Generator) -> np.ndarray | None:
        """Indices of the local points in the search crop ``mask`` (at most ``search.max_points``)."""
        if not self.trees:
            return None
        return random_subset(np.flatnonzero(mask), self.config.search.max_points, self.rng or rng)

    def pairs(self, term: str, assoc: Association, x: np.ndarray, source: np.ndarray, pivot: np.ndarray,
              nn: NearestNeighbors, mask: np.ndarray, crop: NearestNeighbors | None, rng: np.random.Generator,
              local: np.ndarray, inside: np.ndarray | None) -> Pairs:
        """``term``'s pairs: the association's (source-to-frame), frame-to-source or both sets together."""
        tree = self.trees.get(term)
        if tree is None or inside is None:
            return assoc.pairs(x, source, pivot, nn, mask, crop, rng)
        reg = self.config.registration
        direction = reg.pairing
        if direction == "coverage":
            if term not in self.directions:
                self.directions[term] = self._decide(tree, x, pivot, local[inside])
            direction = self.directions[term]
        if direction == "source":
            return assoc.pairs(x, source, pivot, nn, mask, crop, rng)
        back = frame_pairs(x, tree, pivot, local, inside, reg.pairing_max_distance)
        if direction == "frame":
            return back
        forward = assoc.pairs(x, source, pivot, nn, mask, crop, rng)
        src, idx, dist, moved, tgt = (np.concatenate([f, b]) for f, b in zip(forward, back, strict=True))
        return src, idx, dist, moved, tgt

    def _decide(self, source: NearestNeighbors, x: np.ndarray, pivot: np.ndarray, frame: np.ndarray) -> str:
        """"frame" when the source (moved by ``x``) holds more of the object than the frame's crop points show:
        the share of source points with no frame point within ``coverage_radius`` exceeds the share of frame
        points with no source point that near by ``coverage_margin`` (a car receding, an earlier nearer view, a
        shape of more faces); else "source" (the frame shows faces the source lacks: a turn, a car passing)."""
        reg = self.config.registration
        if not len(frame) or not len(source):
            return "source"
        placed = unmove(x, frame, pivot)   # the frame in the source's placement: distances are the same
        frame_uncovered = float(np.mean(source.query(placed)[0] > reg.coverage_radius))
        source_uncovered = float(np.mean(NearestNeighbors(placed).query(source.target)[0] > reg.coverage_radius))
        return "frame" if source_uncovered - frame_uncovered > reg.coverage_margin else "source"


@dataclass
class Registration:
    """The outer loop with its strategies (chosen once by the tracker)."""

    config: TrackerConfig
    association: Association
    inliers: ShapeInliers
    metric: Metric
    reference: PriorReference | IterationReference
    consistency: Consistency
    data_free: DataFreeFrames

    def estimate(self, prev: Box, source: np.ndarray, shape: np.ndarray, target: FrameTarget, x0: np.ndarray,
                 scale: float, outer: int, icp_only: bool, mp_reference: np.ndarray | None, flags: list[str],
                 rng: np.random.Generator, det_target: np.ndarray | None = None,
                 travel: tuple[float, float] | None = None) -> tuple[np.ndarray, dict]:
        """Outer loop from motion ``x0``; returns the motion and diagnostics. ``source``: the ICP source (world),
        ``shape``: the shape model (object frame, placed at ``prev``); ``icp_only``: no shape or motion terms;
        ``travel``: (heading, weight) of the heading-from-travel term (tracker/strategies/travel.py) or None."""
        c = self.config
        reg, assoc = c.registration, self.association
        pivot = prev.center
        local = target.nn.target
        source = assoc.per_frame(source, rng)
        with_shape = not icp_only and c.shape.enabled and c.shape.weight > 0
        shape_src = assoc.per_frame(to_world_frame(shape, prev), rng) if with_shape else np.zeros((0, 3))
        x = np.asarray(x0, dtype=np.float64).copy()
        reference = None if mp_reference is None else mp_reference.copy()
        info = {"crop": 0, "icp_pairs": 0, "shape_inliers": 0, "iterations": 0}
        ransac_seed = int(rng.integers(2**62))
        paired = _FramePairing.of(c, source, shape_src, ransac_seed + 1)
        accel = Anderson(reg.anderson_depth)
        motion_terms_only = self.data_free.solves_without_data and not icp_only
        for it in range(outer):
            info["iterations"] = it + 1
            mask = points_in_box(local, box_moved(prev, x), scale)
            info["crop"] = int(mask.sum())
            enough = info["crop"] >= c.search.min_target_points  # too few points to register against: no data terms
            info["icp_pairs"] = info["shape_inliers"] = 0
            if not enough and not motion_terms_only:
                break
            fixed: list = []  # (name, source, target, normals, weight, normaliser floor)
            crop = assoc.crop(local, mask, rng) if enough else None
            inside = paired.inside(mask, rng) if enough else None
            if enough and reg.icp_weight > 0 and len(source) >= reg.min_points:
                src, idx, dist, _, tgt = paired.pairs("icp", assoc, x, source, pivot, target.nn, mask, crop, rng,
                                                      local, inside)
                if reg.max_pair_distance > 0:
                    keep = dist <= reg.max_pair_distance
                    src, idx, tgt = src[keep], idx[keep], tgt[keep]
                if len(src) >= reg.min_points:
                    fixed.append(("icp", src, tgt, self.metric.normals(target, idx), reg.icp_weight, reg.data_norm_min))
                    info["icp_pairs"] = len(src)
            if enough and len(shape_src) >= reg.min_points:
                src, idx, _, moved, tgt = paired.pairs("shape", assoc, x, shape_src, pivot, target.nn, mask, crop,
                                                       rng, local, inside)
                src, idx, tgt = self.inliers.select(src, idx, tgt, moved, ransac_seed, rng)
                if len(src) >= reg.min_points:
                    fixed.append(("shape", src, tgt, self.metric.normals(target, idx), c.shape.weight,
                                  reg.data_norm_min))
                    info["shape_inliers"] = len(src)
            if not fixed and not motion_terms_only:
                break
            blocks_at = self._loss(fixed, pivot, prev.heading, None if icp_only else reference, icp_only, det_target,
                                   travel)
            # the LM stops on a step below a tenth of the outer tolerance (at least 1e-8: never a fixed 50 steps)
            result = solve(blocks_at, x, max_iterations=reg.solver_iterations,
                           tolerance=max(0.1 * reg.convergence_tolerance, 1e-8))
            residual = result.x - x
            change = float(np.max(np.abs(residual)))
            x = accel.step(x, residual) if reg.anderson_depth > 0 and not icp_only else result.x
            reference = self.reference.next(reference, x)
            if change < reg.convergence_tolerance:
                break
        if with_shape and info["shape_inliers"] == 0:
            flags.append("no_shape_inliers")
        return x, info

    def _loss(self, fixed: list, pivot: np.ndarray, heading: float, reference: np.ndarray | None, icp_only: bool,
              det_target: np.ndarray | None, travel: tuple[float, float] | None = None):
        """The loss's residual blocks as a function of the motion (data terms fixed, motion terms unless icp_only)."""
        c = self.config
        # point-to-point pairs as sums, so each LM trial costs O(1) in the pairs (PairMoments)
        moments = [(name, PairMoments.of(s, t, pivot), w, norm) for name, s, t, n, w, norm in fixed if n is None]
        planes = [entry for entry in fixed if entry[3] is not None]
        plane_point_weight = c.registration.plane_point_weight

        def blocks_at(xx: np.ndarray) -> list[ResidualBlock]:
            blocks = [m.block(name, xx, w, norm) for name, m, w, norm in moments]
            blocks += [point_pair_block(name, xx, s, t, pivot, w, n, plane_point_weight, norm)
                       for name, s, t, n, w, norm in planes]
            if icp_only:
                return blocks
            blocks += self.consistency.blocks(xx, heading)
            if c.motion.prior_weight > 0 and reference is not None:
                blocks.append(motion_prior_block(xx, reference, c.motion.prior_weight))
            if det_target is not None:
                blocks.append(detection_block(xx, det_target, c.detection.weight))
            if travel is not None:
                blocks.append(travel_heading_block(xx, heading, travel[0], travel[1]))
            return blocks

        return blocks_at
