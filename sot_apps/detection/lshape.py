"""Search-based L-shape fitting of a 2D point set (Zhang et al., "Efficient L-shape fitting for vehicle
detection using laser scanners", IEEE IV 2017), closeness criterion, vectorised over the candidate headings."""

from __future__ import annotations

import numpy as np

__all__ = ["fit_rectangle"]


def fit_rectangle(xy: np.ndarray, heading_steps: int = 90) -> tuple[float, np.ndarray, np.ndarray]:
    """L-shape fit of (N, 2) points: (heading in [0, pi/2), min corner, max corner) of the best rectangle, the
    corners in the rotated frame (u along ``heading``, v across).

    For every heading of the search the points are projected on the two axes; each point's distance to the
    nearer of the two parallel edges of each axis (d_u, d_v) is taken, and the closeness score is
    sum(1 / max(min(d_u, d_v), 0.01)): points hugging two perpendicular edges score high. The rectangle's
    heading is defined modulo pi/2 (which side is the length is the caller's choice)."""
    xy = np.asarray(xy, dtype=np.float64).reshape(-1, 2)
    angles = np.arange(heading_steps) * (0.5 * np.pi / heading_steps)
    c, s = np.cos(angles), np.sin(angles)
    u = np.outer(c, xy[:, 0]) + np.outer(s, xy[:, 1])        # (H, N)
    v = np.outer(-s, xy[:, 0]) + np.outer(c, xy[:, 1])
    du = np.minimum(u.max(axis=1, keepdims=True) - u, u - u.min(axis=1, keepdims=True))
    dv = np.minimum(v.max(axis=1, keepdims=True) - v, v - v.min(axis=1, keepdims=True))
    d = np.maximum(np.minimum(du, dv), 0.01)
    score = (1.0 / d).sum(axis=1)
    best = int(np.argmax(score))
    lo = np.array([u[best].min(), v[best].min()])
    hi = np.array([u[best].max(), v[best].max()])
    return float(angles[best]), lo, hi
