"""Levenberg–Marquardt (damped Gauss–Newton) on the 4 motion parameters [dx, dy, dz, dtheta]."""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Callable

import numpy as np

from .terms import ResidualBlock

__all__ = ["SolverResult", "total_loss", "solve"]

BlockFunction = Callable[[np.ndarray], list[ResidualBlock]]


@dataclass(frozen=True)
class SolverResult:
    x: np.ndarray
    loss: float
    iterations: int


def total_loss(blocks: list[ResidualBlock]) -> float:
    return float(sum(b.loss for b in blocks))


def _normal_equations(blocks: list[ResidualBlock]) -> tuple[np.ndarray, np.ndarray]:
    hessian = np.zeros((4, 4))
    gradient = np.zeros(4)
    for b in blocks:
        if b.normal_equations is not None:
            hessian += b.weight * b.normal_equations[0]
            gradient += b.weight * b.normal_equations[1]
        else:
            hessian += b.weight * (b.jacobian.T @ b.jacobian)
            gradient += b.weight * (b.jacobian.T @ b.residuals)
    return hessian, gradient


def _usable(hessian: np.ndarray) -> bool:
    """Finite and not all zero. A finite sum means every entry is finite (an inf or NaN entry makes the sum inf or
    NaN), so the entry-wise check runs only when the sum is not finite (also when finite entries overflow it)."""
    return (math.isfinite(hessian.sum()) or bool(np.isfinite(hessian).all())) and bool(hessian.any())


def solve(blocks_at: BlockFunction, x0: np.ndarray, max_iterations: int = 10, tolerance: float = 1e-6,
          damping: float = 1e-6) -> SolverResult:
    """Minimise sum_b weight_b * ||r_b(x)||^2 from ``x0``.

    ``blocks_at(x)`` returns the residual blocks (with Jacobians) at x. Steps are Gauss–Newton steps
    damped by ``lambda * (diag(H) + eps)``; lambda grows when a step does not decrease the loss.
    """
    x = np.asarray(x0, dtype=np.float64).copy()
    blocks = blocks_at(x)
    loss = total_loss(blocks)
    lam = damping
    iterations = 0
    while iterations < max_iterations:
        iterations += 1
        hessian, gradient = _normal_equations(blocks)
        if not _usable(hessian):
            break
        diag = hessian.diagonal() + 1e-9
        accepted = False
        step = np.zeros(4)
        for _ in range(8):
            try:
                step = -np.linalg.solve(hessian + lam * np.diag(diag), gradient)
            except np.linalg.LinAlgError:
                lam *= 10.0
                continue
            candidate = x + step
            new_blocks = blocks_at(candidate)
            new_loss = total_loss(new_blocks)
            if new_loss <= loss:
                x, blocks, loss = candidate, new_blocks, new_loss
                lam = max(lam * 0.1, 1e-9)
                accepted = True
                break
            lam *= 10.0
        if not accepted or np.abs(step).max() < tolerance:
            break
    return SolverResult(x, loss, iterations)
