"""Scores of optical flow: EPE (mean end-point error, px), Fl (share of pixels with EPE > 3 px and > 5 % of the
true flow magnitude) and coverage against a true flow (:func:`flow_errors`), and the photometric error of a flow
between two real images (:func:`warp_abs_difference`). The measurements that run the flow app, the tracker and
the baselines to get flows to score (``sot-apps bench flow-quality``) are in :mod:`sot_apps.bench.flow_quality`.
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
