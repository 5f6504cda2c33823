"""Fit the model-free detector's score on sequences with exact ground truth (synthetic worlds, the generated
benchmark): ``python -m sot_apps.detection.calibrate SEQUENCE... [--step 4] [--held-out SEQUENCE...]``.

Every candidate cluster of every ``step``-th frame is a sample: its features (:data:`.detector.FEATURES`)
and whether its box overlaps a ground-truth vehicle at BEV IoU >= 0.5. A logistic regression (L2-penalised,
Newton's method) gives the weights to paste into ``DetectorConfig.score_weights``; the score is then the
probability that a box is a true positive, so the detections scored >= 0.5 have a precision above 0.5 by
construction and, in practice (most of them score well above), far above it. The precision and recall at
score >= 0.5 are printed for the training and the held-out sequences.
"""

from __future__ import annotations

import argparse

import numpy as np

from tracker import iou_bev_batch

from .detector import FEATURES, DetectorConfig, boxes_to_world, frame_candidates, sweep_window

__all__ = ["candidate_samples", "fit_logistic"]


def candidate_samples(sequence, config: DetectorConfig | None = None, frames=None, iou: float = 0.5
                      ) -> tuple[np.ndarray, np.ndarray]:
    """(features (N, F), is_true_positive (N,)) of every candidate of ``frames`` (default: all)."""
    from ..objects.selection import DEFAULT_SELECTION

    config = config or DetectorConfig()
    labels = {lbl.lower() for lbl in DEFAULT_SELECTION.vehicle_labels(sequence)}
    sensor_xy = np.asarray(sequence.ego_from_lidar)[:2, 3]
    xs, ys = [], []
    for k in (range(len(sequence)) if frames is None else frames):
        window = sweep_window(sequence, k, config)
        candidates = frame_candidates(window, config, sensor_xy)
        if not candidates:
            continue
        boxes = boxes_to_world(np.array([c.box for c in candidates]), window[0][1])
        truth = np.array([a.box.to_array() for a in sequence.annotations[k] if a.label.lower() in labels]).reshape(-1, 7)
        best = np.zeros(len(boxes))
        if len(truth):
            pairs = iou_bev_batch(np.repeat(boxes, len(truth), axis=0), np.tile(truth, (len(boxes), 1)))
            best = pairs.reshape(len(boxes), len(truth)).max(axis=1)
        xs.append(np.array([c.features for c in candidates]))
        ys.append(best >= iou)
    if not xs:
        return np.zeros((0, len(FEATURES))), np.zeros(0, dtype=bool)
    return np.vstack(xs), np.concatenate(ys)


def fit_logistic(x: np.ndarray, y: np.ndarray, l2: float = 1e-2, iterations: int = 50) -> np.ndarray:
    """Weights (1 + F,) (bias first) of P(y | x) = sigmoid(w0 + x w), L2-penalised (not the bias), Newton."""
    a = np.column_stack([np.ones(len(x)), x])
    w = np.zeros(a.shape[1])
    penalty = np.full(a.shape[1], l2 * len(x))
    penalty[0] = 0.0
    for _ in range(iterations):
        p = 1.0 / (1.0 + np.exp(-(a @ w)))
        gradient = a.T @ (p - y) + penalty * w
        hessian = (a * (p * (1 - p))[:, None]).T @ a + np.diag(penalty) + 1e-9 * np.eye(a.shape[1])
        step = np.linalg.solve(hessian, gradient)
        w -= step
        if np.abs(step).max() < 1e-8:
            break
    return w


def _report(name: str, x: np.ndarray, y: np.ndarray, w: np.ndarray) -> str:
    score = 1.0 / (1.0 + np.exp(-(w[0] + x @ w[1:])))
    confident = score >= 0.5
    precision = y[confident].mean() if confident.any() else float("nan")
    return (f"{name}: {len(y)} candidates, {int(y.sum())} true; at score >= 0.5: {int(confident.sum())} kept, "
            f"precision {precision:.3f}, true positives kept {int((confident & y).sum())}/{int(y.sum())}")


def main(argv: list[str] | None = None) -> int:
    from ..io import open_sequence

    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("sequences", nargs="+")
    parser.add_argument("--held-out", nargs="*", default=[])
    parser.add_argument("--step", type=int, default=4)
    parser.add_argument("--l2", type=float, default=1e-3)
    args = parser.parse_args(argv)
    samples = {}
    for path in args.sequences + args.held_out:
        sequence = open_sequence(path)
        samples[path] = candidate_samples(sequence, frames=range(0, len(sequence), args.step))
    x = np.vstack([samples[p][0] for p in args.sequences])
    y = np.concatenate([samples[p][1] for p in args.sequences])
    w = fit_logistic(x, y.astype(np.float64), args.l2)
    print("score_weights = (" + ", ".join(f"{v:.3f}" for v in w) + ")")
    print("  features: bias, " + ", ".join(FEATURES))
    print(_report("training", x, y, w))
    for path in args.sequences + args.held_out:
        print(_report(("held out " if path in args.held_out else "") + path, *samples[path], w))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
