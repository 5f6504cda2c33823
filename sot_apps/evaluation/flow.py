"""Scores of optical flow: end-point error and outliers against a true flow (:func:`flow_errors`), and the
photometric error of a flow between two real images (:func:`warp_abs_difference`). The measurements that run the
flow app, the tracker and the baselines (``sot-apps bench flow``) are in :mod:`sot_apps.bench.flow_quality`:

(a) ``synthetic_quality``: a synthetic world with rendered camera images (``sot_apps.lidar_sim``).
    The exact flow comes from the ground-truth meshes and 1 ms trajectories, with the static world
    (walls, poles, ground) as occluders. Compared on vehicle pixels visible in both images: our
    annotation from ground-truth boxes (10 Hz, shapes from the simulated LiDAR points), from tracker
    states (SOTracker run from the first GT box), and OpenCV's DIS and Farneback flow on the rendered
    image pairs. Metrics: EPE (mean end-point error, px) and Fl (share of pixels with EPE > 3 px AND
    > 5 % of the true flow magnitude), plus coverage (share of the true object pixels that get a value).
(b) ``photometric_quality``: real image pairs. Image k+1 is warped into k with a flow over the
    annotated object pixels (cv2.remap); the mean absolute grey-level difference to image k is
    reported for our flow, zero flow and DIS flow on the same pixels.
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

__all__ = ["flow_errors", "warp_abs_difference", "FlowScore"]


@dataclass
class FlowScore:
    """Errors of one method over pixels: ``epe`` mean end-point error (px), ``fl`` outlier share,
    ``coverage`` share of the evaluated true pixels that have an estimate, ``pixels`` evaluated."""

    method: str
    epe: float
    fl: float
    coverage: float
    pixels: int


def flow_errors(estimate: np.ndarray, estimate_valid: np.ndarray, truth: np.ndarray, truth_valid: np.ndarray,
                method: str = "") -> FlowScore:
    both = truth_valid & estimate_valid
    n_truth = int(truth_valid.sum())
    if not both.any():
        return FlowScore(method, 0.0, 0.0, 0.0, 0)
    err = np.linalg.norm(estimate[both].astype(np.float64) - truth[both], axis=1)
    mag = np.linalg.norm(truth[both].astype(np.float64), axis=1)
    outlier = (err > 3.0) & (err > 0.05 * mag)
    return FlowScore(method, float(err.mean()), float(outlier.mean()), float(both.sum() / max(n_truth, 1)),
                     int(both.sum()))


def warp_abs_difference(image_k: np.ndarray, image_k1: np.ndarray, flow: np.ndarray) -> np.ndarray:
    """|I_k - warp(I_k+1)| per pixel (grey levels, float32): image k+1 sampled at each pixel moved by ``flow``
    (k -> k+1, (H, W, 2)), bilinear, borders replicated."""
    g0, g1 = image_k.astype(np.float32), image_k1.astype(np.float32)
    h, w = g0.shape
    grid_x, grid_y = np.meshgrid(np.arange(w, dtype=np.float32), np.arange(h, dtype=np.float32))
    warped = cv2.remap(g1, grid_x + flow[..., 0], grid_y + flow[..., 1], cv2.INTER_LINEAR,
                       borderMode=cv2.BORDER_REPLICATE)
    return np.abs(warped - g0)
