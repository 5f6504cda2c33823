"""Loss-term strategies of the per-frame solve.

The motion prior's reference (``motion.prior_reference``): :class:`PriorReference` keeps the motion model's
prediction (paper); :class:`IterationReference` (upstream) moves it to each outer iteration's result.
Motion consistency (``motion.consistency``): :class:`SymmetricConsistency` on both components;
:class:`XOnlyConsistency` upstream's x-only form. A frame without data terms (``registration.data_free_frames``):
:class:`KeepPrior` keeps the prediction (flag ``prior_only``); :class:`MotionTermsOnly` (upstream) still
minimises the motion prior + motion consistency.
"""

from __future__ import annotations

from typing import Protocol

import numpy as np

from ..terms import ResidualBlock, motion_consistency_block

__all__ = ["PriorReference", "IterationReference", "Consistency", "SymmetricConsistency", "XOnlyConsistency",
           "DataFreeFrames", "KeepPrior", "MotionTermsOnly"]


class PriorReference:
    def next(self, reference: np.ndarray | None, x: np.ndarray) -> np.ndarray | None:
        return reference


class IterationReference:
    def next(self, reference: np.ndarray | None, x: np.ndarray) -> np.ndarray | None:
        return None if reference is None else x.copy()


class Consistency(Protocol):
    def blocks(self, x: np.ndarray, heading: float) -> list[ResidualBlock]:
        """The MC term's residual blocks (none when its weight is 0)."""


class _Consistency:
    symmetric = True

    def __init__(self, weight: float) -> None:
        self.weight = weight

    def blocks(self, x: np.ndarray, heading: float) -> list[ResidualBlock]:
        if self.weight <= 0:
            return []
        return [motion_consistency_block(x, heading, self.weight, self.symmetric)]


class SymmetricConsistency(_Consistency):
    symmetric = True


class XOnlyConsistency(_Consistency):
    symmetric = False


class DataFreeFrames(Protocol):
    solves_without_data: bool  # the outer loop goes on with the motion terms alone

    def keeps_prior(self) -> bool:
        """Whether a frame whose solve had no data pairs takes the prior (flag prior_only)."""


class KeepPrior:
    solves_without_data = False

    def keeps_prior(self) -> bool:
        return True


class MotionTermsOnly:
    solves_without_data = True

    def keeps_prior(self) -> bool:
        return False
