"""The terms of the SOTracker loss (ICP, Shape, MC, MP and the Det+SOT Detection term) as residual blocks with analytic Jacobians.

Parameters x = [dx, dy, dz, dtheta]: rotate by dtheta about the vertical axis through ``pivot`` (the
previous box centre), then translate by (dx, dy, dz) — the paper's Eq. (3). Every term is a sum of
squares ``weight * sum(r**2)``; point terms are means over their pairs (weight / |A|).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Callable

import numpy as np

__all__ = ["ResidualBlock", "PairMoments", "apply_motion", "point_pair_block", "motion_consistency_block",
           "motion_prior_block", "detection_block", "travel_heading_block"]


@dataclass(frozen=True)
class ResidualBlock:
    """residuals (m,), jacobian (m, 4), weight: the block contributes weight * sum(residuals**2).

    ``normal_equations`` optionally carries (J^T J, J^T r) computed in closed form (point terms), so the
    solver never forms the (m, 4) Jacobian; ``jacobian`` is then built on first access. ``sum_squares``
    optionally carries sum(residuals**2) in closed form (:class:`PairMoments`); the residuals are then built
    on first access too (``residuals_fn``).
    """

    name: str
    residual_data: np.ndarray | None
    jacobian_data: np.ndarray | None
    weight: float
    normal_equations: tuple[np.ndarray, np.ndarray] | None = None
    jacobian_fn: Callable[[], np.ndarray] | None = None
    sum_squares: float | None = None
    residuals_fn: Callable[[], np.ndarray] | None = None

    @property
    def residuals(self) -> np.ndarray:
        if self.residual_data is not None:
            return self.residual_data
        assert self.residuals_fn is not None
        return self.residuals_fn()

    @property
    def jacobian(self) -> np.ndarray:
        if self.jacobian_data is not None:
            return self.jacobian_data
        assert self.jacobian_fn is not None
        return self.jacobian_fn()

    @property
    def loss(self) -> float:
        if self.sum_squares is not None:
            return float(self.weight * self.sum_squares)
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


@dataclass(frozen=True)
class PairMoments:
    """Sums over fixed point pairs (source a_i, target b_i, both relative to the pivot) from which the
    point-to-point term's sum of squares, gradient and Gauss-Newton Hessian follow at any x in O(1).

    With R the rotation by dtheta about z and t = (dx, dy, dz), e_i = R a_i + t - b_i, and (xy part)
    sum |e_i|^2 = aa + n |t|^2 + bb + 2 t.(R sum_a) - 2 t.sum_b - 2 (cos dtheta dot + sin dtheta cross),
    plus sum (dz_i + t_z)^2 with dz_i = a_z - b_z; the rotation's derivative R' gives the theta column.
    """

    count: int
    sum_a: np.ndarray   # (2,) sum of a_xy
    sum_b: np.ndarray   # (2,) sum of b_xy
    aa: float           # sum |a_xy|^2
    bb: float           # sum |b_xy|^2
    dot: float          # sum a_xy . b_xy
    cross: float        # sum a_x b_y - a_y b_x
    dz: float           # sum (a_z - b_z)
    dzdz: float         # sum (a_z - b_z)^2
    source: np.ndarray = field(repr=False)
    target: np.ndarray = field(repr=False)
    pivot: np.ndarray = field(repr=False)

    @classmethod
    def of(cls, source: np.ndarray, target: np.ndarray, pivot: np.ndarray) -> "PairMoments":
        a = source - pivot
        b = target - pivot
        ax, ay, bx, by = a[:, 0], a[:, 1], b[:, 0], b[:, 1]
        dz = a[:, 2] - b[:, 2]
        return cls(len(source), np.array([ax.sum(), ay.sum()]), np.array([bx.sum(), by.sum()]),
                   float(ax @ ax + ay @ ay), float(bx @ bx + by @ by), float(ax @ bx + ay @ by),
                   float(ax @ by - ay @ bx), float(dz.sum()), float(dz @ dz), source, target, pivot)

    def block(self, name: str, x: np.ndarray, weight: float, min_norm: int = 0) -> ResidualBlock:
        """The mean squared pair distance at x as a block (see :func:`point_pair_block`)."""
        n = self.count
        c, s = np.cos(x[3]), np.sin(x[3])
        sa, sb = self.sum_a, self.sum_b
        rot_a = np.array([c * sa[0] - s * sa[1], s * sa[0] + c * sa[1]])        # R sum_a
        drot_a = np.array([-s * sa[0] - c * sa[1], c * sa[0] - s * sa[1]])      # R' sum_a = sum t_i
        t = np.asarray(x[:2], dtype=np.float64)
        tz = float(x[2])
        sum_squares = (self.aa + n * float(t @ t) + self.bb + 2.0 * float(t @ rot_a) - 2.0 * float(t @ sb)
                       - 2.0 * (c * self.dot + s * self.cross) + self.dzdz + 2.0 * tz * self.dz + n * tz * tz)
        hessian = np.zeros((4, 4))
        hessian[0, 0] = hessian[1, 1] = hessian[2, 2] = n
        hessian[0, 3] = hessian[3, 0] = drot_a[0]
        hessian[1, 3] = hessian[3, 1] = drot_a[1]
        hessian[3, 3] = self.aa
        gxy = rot_a + n * t - sb
        # sum t_i . e_i: t_i is orthogonal to R a_i, and sum t_i . b_i = -sin dot + cos cross
        gradient = np.array([gxy[0], gxy[1], self.dz + n * tz, float(t @ drot_a) + s * self.dot - c * self.cross])
        w = weight / max(n, min_norm, 1)
        x = np.array(x, dtype=np.float64)

        def residuals() -> np.ndarray:
            return (apply_motion(x, self.source, self.pivot) - self.target).reshape(-1)

        def full_jacobian() -> np.ndarray:
            a = self.source - self.pivot
            jac = np.zeros((n, 3, 4))
            jac[:, 0, 0] = jac[:, 1, 1] = jac[:, 2, 2] = 1.0
            jac[:, 0, 3], jac[:, 1, 3] = -s * a[:, 0] - c * a[:, 1], c * a[:, 0] - s * a[:, 1]
            return jac.reshape(-1, 4)

        return ResidualBlock(name, None, None, w, (hessian, gradient), full_jacobian, max(sum_squares, 0.0),
                             residuals)


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
    if normals is None:
        return PairMoments.of(source, target, pivot).block(name, x, weight, min_norm)
    c, s = np.cos(x[3]), np.sin(x[3])
    a = source - pivot
    moved = apply_motion(x, source, pivot)
    e = moved - target
    w = weight / max(n, min_norm, 1)
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


def travel_heading_block(x: np.ndarray, previous_heading: float, target: float, weight: float) -> ResidualBlock:
    """Heading from travel: (previous_heading + dtheta - target)^2, the new heading toward the direction of
    travel (tracker/strategies/travel.py)."""
    r = (previous_heading + float(x[3]) - target + np.pi) % (2.0 * np.pi) - np.pi
    return ResidualBlock("travel", np.array([r]), np.array([[0.0, 0.0, 0.0, 1.0]]), weight)
