"""Simulated detections: ground-truth boxes with a learned detector's errors (noise, misses, false positives).

A :class:`DetectionNoise` profile is data; ``simulate_detections`` is deterministic for a seed. The
``learned`` profile mimics the error structure reported for LiDAR vehicle detectors (PointPillars /
CenterPoint-class on KITTI, nuScenes, Waymo):

- recall falls with point support: P(detect) = recall_max * (1 - exp(-n / support_points)) for a box
  holding n sweep points (an empty box is never detected);
- centre error grows with range and sparsity: sigma = (base + per_metre * range) * (1 + sparse_points /
  (n + sparse_points)), larger along the length than across (extent ambiguity of a partial view);
- heading error (Gaussian) plus occasional flips by pi; size error multiplicative (log-normal);
- errors are correlated over time for the same object (AR(1) with ``correlation`` per frame): a learned
  detector sees nearly the same partial view in consecutive sweeps and repeats its bias, so averaging
  detections over a few frames does not remove it;
- scores: true positives high and rising with support, false positives mostly below 0.5;
- false positives: Poisson per frame, half next to real objects (duplicates / split clutter), half anywhere
  in range.
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from typing import Iterable

import numpy as np

from tracker import FrameDetections, wrap_angle

from ..objects.box_points import count_points_in_boxes

__all__ = ["DetectionNoise", "NOISE_PROFILES", "simulate_frame", "simulate_detections"]


@dataclass(frozen=True)
class DetectionNoise:
    """Error model of simulated detections (lengths in metres, angles in radians)."""

    recall_max: float = 0.95
    support_points: float = 8.0          # P(detect) reaches 63 % of recall_max at this many points
    sigma_along: float = 0.15            # centre noise along the length at range 0 with many points
    sigma_across: float = 0.08
    sigma_z: float = 0.05
    sigma_per_metre: float = 0.004       # added to every centre sigma per metre of range
    sparse_points: float = 10.0          # sigmas double for an empty box, x1.5 at this many points
    sigma_heading: float = 0.05
    flip_probability: float = 0.03       # heading off by pi
    sigma_log_size: float = 0.08
    correlation: float = 0.7             # AR(1) coefficient of an object's errors from frame to frame
    tp_score_base: float = 0.55
    tp_score_gain: float = 0.40          # score = base + gain * (1 - exp(-n / 30)) + N(0, score_noise)
    score_noise: float = 0.08
    false_positives_per_frame: float = 2.0
    fp_score_alpha: float = 2.0          # FP scores ~ Beta(alpha, beta): mean 0.29, P(> 0.5) ~ 11 %
    fp_score_beta: float = 5.0
    max_range: float = 70.0


NOISE_PROFILES: dict[str, DetectionNoise] = {
    "learned": DetectionNoise(),
    "clean": DetectionNoise(recall_max=1.0, support_points=1e-9, sigma_along=0.0, sigma_across=0.0, sigma_z=0.0,
                            sigma_per_metre=0.0, sparse_points=0.0, sigma_heading=0.0, flip_probability=0.0,
                            sigma_log_size=0.0, tp_score_base=1.0, tp_score_gain=0.0, score_noise=0.0,
                            false_positives_per_frame=0.0),
}
NOISE_PROFILES["noisy"] = replace(NOISE_PROFILES["learned"], recall_max=0.85, sigma_along=0.25, sigma_across=0.15,
                                  sigma_heading=0.08, flip_probability=0.06, false_positives_per_frame=5.0)


def simulate_frame(gt_boxes: np.ndarray, gt_points: np.ndarray, ego_xyz: np.ndarray, noise: DetectionNoise,
                   rng: np.random.Generator, labels: tuple[str, ...] = (),
                   unit_errors: np.ndarray | None = None) -> FrameDetections:
    """One frame's simulated detections from its ground-truth boxes (M, 7) and their point counts (M,).

    ``unit_errors``: (M, 7) standard-normal errors (along, across, z, heading, log l, log w, log h) of the
    boxes (default: drawn independently), scaled here by the profile's sigmas."""
    gt = np.asarray(gt_boxes, dtype=np.float64).reshape(-1, 7)
    if unit_errors is None:
        unit_errors = rng.standard_normal((len(gt), 7))
    n = np.asarray(gt_points, dtype=np.float64).reshape(-1)
    rng_draws = rng.random(len(gt))
    support = noise.recall_max * (1.0 - np.exp(-n / noise.support_points)) if noise.support_points > 0 else \
        np.full(len(gt), noise.recall_max)
    dist = np.hypot(gt[:, 0] - ego_xyz[0], gt[:, 1] - ego_xyz[1])
    keep = (rng_draws < support) & (n > 0) & (dist <= noise.max_range)
    g, npts, r, e = gt[keep], n[keep], dist[keep], unit_errors[keep]
    sparse = 1.0 + noise.sparse_points / (npts + noise.sparse_points) if noise.sparse_points > 0 else np.ones(len(g))
    along = (noise.sigma_along + noise.sigma_per_metre * r) * sparse * e[:, 0]
    across = (noise.sigma_across + noise.sigma_per_metre * r) * sparse * e[:, 1]
    c, s = np.cos(g[:, 3]), np.sin(g[:, 3])
    boxes = g.copy()
    boxes[:, 0] += c * along - s * across
    boxes[:, 1] += s * along + c * across
    boxes[:, 2] += (noise.sigma_z + noise.sigma_per_metre * r) * sparse * e[:, 2]
    flips = rng.random(len(g)) < noise.flip_probability
    boxes[:, 3] = wrap_angle(g[:, 3] + noise.sigma_heading * sparse * e[:, 3] + np.pi * flips)
    boxes[:, 4:7] = g[:, 4:7] * np.exp(noise.sigma_log_size * e[:, 4:7])
    scores = (noise.tp_score_base + noise.tp_score_gain * (1.0 - np.exp(-npts / 30.0))
              + noise.score_noise * rng.standard_normal(len(g)))
    kept_labels = tuple(lbl for lbl, k in zip(labels, keep, strict=True) if k) if labels else ()
    # false positives: half near real objects, half anywhere within range
    n_fp = int(rng.poisson(noise.false_positives_per_frame))
    fp = np.zeros((n_fp, 7))
    near = rng.random(n_fp) < 0.5
    anchors = gt[rng.integers(len(gt), size=n_fp)] if len(gt) else np.tile(np.r_[ego_xyz, 0, 4.5, 1.9, 1.6], (n_fp, 1))
    offset_angle = rng.uniform(-np.pi, np.pi, n_fp)
    offset = np.where(near, rng.uniform(2.0, 5.0, n_fp), 0.0)
    radius = rng.uniform(5.0, noise.max_range, n_fp)
    place = rng.uniform(-np.pi, np.pi, n_fp)
    fp[:, 0] = np.where(near, anchors[:, 0] + offset * np.cos(offset_angle), ego_xyz[0] + radius * np.cos(place))
    fp[:, 1] = np.where(near, anchors[:, 1] + offset * np.sin(offset_angle), ego_xyz[1] + radius * np.sin(place))
    fp[:, 2] = anchors[:, 2]
    fp[:, 3] = rng.uniform(-np.pi, np.pi, n_fp)
    fp[:, 4:7] = np.array([4.5, 1.9, 1.6]) * np.exp(0.15 * rng.standard_normal((n_fp, 3)))
    fp_scores = rng.beta(noise.fp_score_alpha, noise.fp_score_beta, n_fp)
    all_labels = kept_labels + ("car",) * n_fp if labels else ()
    return FrameDetections(np.vstack([boxes, fp]), np.clip(np.concatenate([scores, fp_scores]), 0.0, 1.0), all_labels)


def simulate_detections(sequence, noise: DetectionNoise | str = "learned", seed: int = 0,
                        labels: Iterable[str] | None = None, progress=None) -> dict[int, FrameDetections]:
    """Simulated detections of every annotated frame of ``sequence`` (a :class:`~sot_apps.io.Sequence`).

    ``labels``: ground-truth classes that the simulated detector finds (case-insensitive; None = all).
    """
    profile = NOISE_PROFILES[noise] if isinstance(noise, str) else noise
    rng = np.random.default_rng(seed)
    wanted = None if labels is None else {lbl.lower() for lbl in labels}
    out: dict[int, FrameDetections] = {}
    state: dict[str, np.ndarray] = {}   # per object: its current (AR(1)) standard-normal errors
    rho = profile.correlation
    frames = range(len(sequence))
    for k in (progress(frames) if progress else frames):
        anns = [a for a in (sequence.annotations[k] if sequence.annotations else [])
                if wanted is None or a.label.lower() in wanted]
        gt = np.array([a.box.to_array() for a in anns]).reshape(-1, 7)
        counts = count_points_in_boxes(sequence.points_world(k), gt)
        ego = np.asarray(sequence.frames[k].world_from_ego)[:3, 3]
        fresh = rng.standard_normal((len(anns), 7))
        errors = np.array([rho * state[a.track_id] + np.sqrt(1.0 - rho * rho) * f if a.track_id in state else f
                           for a, f in zip(anns, fresh, strict=True)]).reshape(-1, 7)
        state = {a.track_id: err for a, err in zip(anns, errors, strict=True)}
        out[k] = simulate_frame(gt, counts, ego, profile, rng, tuple(a.label for a in anns), errors)
    return out
