"""The terms of the SOTracker loss (ICP, Shape, MC, MP and the Det+SOT Detection term) as residual blocks with analytic Jacobians.

Parameters x = [dx, dy, dz, dtheta]: rotate by dtheta about the vertical axis through ``pivot`` (the
previous box centre), then translate by (dx, dy, dz) — the paper's Eq. (3). Every term is a sum of
squares ``weight * sum(r**2)``; point terms are means over their pairs (weight / |A|).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Callable

import numpy as np

__all__ = ["ResidualBlock", "apply_motion", "point_pair_block", "motion_consistency_block", "motion_prior_block",
           "detection_block"]


@dataclass(frozen=True)
class ResidualBlock:
    """residuals (m,), jacobian (m, 4), weight: the block contributes weight * sum(residuals**2).

    ``normal_equations`` optionally carries (J^T J, J^T r) computed in closed form (point terms), so the
    solver never forms the (m, 4) Jacobian; ``jacobian`` is then built on first access.
    """

    name: str
    residuals: np.ndarray
    jacobian_data: np.ndarray | None
    weight: float
    normal_equations: tuple[np.ndarray, np.ndarray] | None = None
    jacobian_fn: Callable[[], np.ndarray] | None = None

    @property
    def jacobian(self) -> np.ndarray:
        if self.jacobian_data is not None:
            return self.jacobian_data
        assert self.jacobian_fn is not None
        return self.jacobian_fn()

    @property
    def loss(self) -> float:
        return float(self.weight * (self.residuals @ self.residuals))


def apply_motion(x: np.ndarray, points: np.ndarray, pivot: np.ndarray) -> np.ndarray:
    """Points moved by x = [dx, dy, dz, dtheta] (rotation about z through ``pivot``, then translation)."""
    c, s = np.cos(x[3]), np.sin(x[3])
    a = points - pivot
    out = np.empty_like(a)
    out[:, 0] = c * a[:, 0] - s * a[:, 1] + pivot[0] + x[0]
    out[:, 1] = s * a[:, 0] + c * a[:, 1] + pivot[1] + x[1]
    out[:, 2] = points[:, 2] + x[2]
    return out


def point_pair_block(name: str, x: np.ndarray, source: np.ndarray, target: np.ndarray, pivot: np.ndarray,
                     weight: float, normals: np.ndarray | None = None, point_weight: float = 0.1,
                     min_norm: int = 0) -> ResidualBlock:
    """Mean squared distance between moved ``source`` points and their paired ``target`` points.

    The mean divides by max(|pairs|, ``min_norm``): with ``min_norm`` > 0 a term resting on few pairs
    weighs less against the motion terms.

    With ``normals`` (unit target normals; zero rows = undefined), each pair contributes its
    point-to-plane distance squared plus ``point_weight`` times its point-to-point distance squared
    (pairs without a normal: the point-to-point distance alone).
    """
    n = len(source)
    c, s = np.cos(x[3]), np.sin(x[3])
    a = source - pivot
    moved = apply_motion(x, source, pivot)
    e = moved - target
    w = weight / max(n, min_norm, 1)
    if normals is None:
        # closed-form normal equations: J_i = [I_3 | t_i], t_i = d(moved_i)/d(theta)
        tx = -s * a[:, 0] - c * a[:, 1]
        ty = c * a[:, 0] - s * a[:, 1]
        hessian = np.zeros((4, 4))
        hessian[0, 0] = hessian[1, 1] = hessian[2, 2] = n
        hessian[0, 3] = hessian[3, 0] = tx.sum()
        hessian[1, 3] = hessian[3, 1] = ty.sum()
        hessian[3, 3] = tx @ tx + ty @ ty
        esum = e.sum(axis=0)
        gradient = np.array([esum[0], esum[1], esum[2], tx @ e[:, 0] + ty @ e[:, 1]])

        def full_jacobian() -> np.ndarray:
            jac = np.zeros((n, 3, 4))
            jac[:, 0, 0] = jac[:, 1, 1] = jac[:, 2, 2] = 1.0
            jac[:, 0, 3], jac[:, 1, 3] = tx, ty
            return jac.reshape(-1, 4)

        return ResidualBlock(name, e.reshape(-1), None, w, (hessian, gradient), full_jacobian)
    jac = np.zeros((n, 3, 4))
    jac[:, 0, 0] = 1.0
    jac[:, 1, 1] = 1.0
    jac[:, 2, 2] = 1.0
    jac[:, 0, 3] = -s * a[:, 0] - c * a[:, 1]
    jac[:, 1, 3] = c * a[:, 0] - s * a[:, 1]
    has = np.any(normals != 0.0, axis=1)
    scale = np.where(has, np.sqrt(point_weight), 1.0)
    r_plane = (normals * e).sum(axis=1)
    j_plane = np.einsum("ni,nij->nj", normals, jac)
    r = np.concatenate([r_plane, (e * scale[:, None]).reshape(-1)])
    j = np.concatenate([j_plane, (jac * scale[:, None, None]).reshape(-1, 4)])
    return ResidualBlock(name, r, j, w)


def motion_consistency_block(x: np.ndarray, previous_heading: float, weight: float,
                             symmetric: bool = True) -> ResidualBlock:
    """The motion direction agrees with the heading: r = |v| cos(mean heading) - dx (and the sin/dy part).

    The mean heading is (theta_{k-1} + theta_k) / 2 = previous_heading + dtheta / 2.
    """
    dx, dy = float(x[0]), float(x[1])
    speed = float(np.hypot(dx, dy))
    mean_heading = previous_heading + 0.5 * float(x[3])
    c, s = np.cos(mean_heading), np.sin(mean_heading)
    ux, uy = (dx / speed, dy / speed) if speed > 1e-9 else (0.0, 0.0)
    rows = [speed * c - dx]
    jac = [[ux * c - 1.0, uy * c, 0.0, -0.5 * speed * s]]
    if symmetric:
        rows.append(speed * s - dy)
        jac.append([ux * s, uy * s - 1.0, 0.0, 0.5 * speed * c])
    return ResidualBlock("mc", np.array(rows), np.array(jac), weight)


def motion_prior_block(x: np.ndarray, reference: np.ndarray, weight: float) -> ResidualBlock:
    """||x - reference||^2: stay close to the predicted motion."""
    return ResidualBlock("mp", np.asarray(x, dtype=np.float64) - reference, np.eye(4), weight)


def detection_block(x: np.ndarray, target: np.ndarray, weight: float) -> ResidualBlock:
    """The paper's Detection term ||dS_k - (S_D - S_{k-1})||^2: ``target`` is the associated detection's
    motion from the previous box (:func:`tracker.detection.detection_motion`)."""
    r = np.asarray(x, dtype=np.float64) - target
    r[3] = (r[3] + np.pi) % (2.0 * np.pi) - np.pi
    return ResidualBlock("det", r, np.eye(4), weight)
