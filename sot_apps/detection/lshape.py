"""Search-based L-shape fitting of a 2D point set (Zhang et al., "Efficient L-shape fitting for vehicle
detection using laser scanners", IEEE IV 2017), vectorised over the candidate headings; the closeness or the
variance criterion."""

from __future__ import annotations

import numpy as np

__all__ = ["CRITERIA", "fit_rectangle"]

CRITERIA = ("closeness", "variance")


def _masked_variance(d: np.ndarray, mask: np.ndarray) -> np.ndarray:
    """Per row, the variance of ``d`` where ``mask`` (0 where the mask is empty)."""
    n = mask.sum(axis=1)
    s = np.where(mask, d, 0.0).sum(axis=1)
    s2 = np.where(mask, d * d, 0.0).sum(axis=1)
    mean = s / np.maximum(n, 1)
    return np.where(n > 0, s2 / np.maximum(n, 1) - mean * mean, 0.0)


def fit_rectangle(xy: np.ndarray, heading_steps: int = 90, criterion: str = "closeness"
                  ) -> tuple[float, np.ndarray, np.ndarray]:
    """L-shape fit of (N, 2) points: (heading in [0, pi/2), min corner, max corner) of the best rectangle, the
    corners in the rotated frame (u along ``heading``, v across).

    For every heading of the search the points are projected on the two axes; each point's distance to the
    nearer of the two parallel edges of each axis (d_u, d_v) is taken. ``closeness``: the score is
    sum(1 / max(min(d_u, d_v), 0.01)): points hugging two perpendicular edges score high. ``variance``: each
    point is assigned to the edge it is nearer (u or v) and the score is -(var of the u-edge distances + var
    of the v-edge distances): the two sides are straight lines, whatever their length (Zhang et al. found it
    the most accurate criterion on partial views). The rectangle's heading is defined modulo pi/2 (which side
    is the length is the caller's choice)."""
    if criterion not in CRITERIA:
        raise ValueError(f"unknown L-shape criterion {criterion!r}: one of {CRITERIA}")
    xy = np.asarray(xy, dtype=np.float64).reshape(-1, 2)
    angles = np.arange(heading_steps) * (0.5 * np.pi / heading_steps)
    c, s = np.cos(angles), np.sin(angles)
    u = np.outer(c, xy[:, 0]) + np.outer(s, xy[:, 1])        # (H, N)
    v = np.outer(-s, xy[:, 0]) + np.outer(c, xy[:, 1])
    du = np.minimum(u.max(axis=1, keepdims=True) - u, u - u.min(axis=1, keepdims=True))
    dv = np.minimum(v.max(axis=1, keepdims=True) - v, v - v.min(axis=1, keepdims=True))
    if criterion == "closeness":
        score = (1.0 / np.maximum(np.minimum(du, dv), 0.01)).sum(axis=1)
    else:
        on_u = du < dv
        score = -(_masked_variance(du, on_u) + _masked_variance(dv, ~on_u))
    best = int(np.argmax(score))
    lo = np.array([u[best].min(), v[best].min()])
    hi = np.array([u[best].max(), v[best].max()])
    return float(angles[best]), lo, hi
