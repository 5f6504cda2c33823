"""Middlebury ``.flo`` files via OpenCV (``cv2.writeOpticalFlow`` / ``cv2.readOpticalFlow``).

Pixels without flow hold ``UNKNOWN_FLOW`` (1e10; Middlebury tools treat |value| > 1e9 as unknown).
"""

from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np

from ..errors import InputError
from ..io.atomic import atomic_path

__all__ = ["write_flo", "read_flo", "UNKNOWN_FLOW"]

UNKNOWN_FLOW = np.float32(1e10)


def write_flo(path: str | Path, flow: np.ndarray, valid: np.ndarray | None = None) -> None:
    data = np.ascontiguousarray(flow, dtype=np.float32).copy()
    if valid is not None:
        data[~np.asarray(valid, dtype=bool)] = UNKNOWN_FLOW
    with atomic_path(path) as tmp:
        if not cv2.writeOpticalFlow(str(tmp), data):
            raise RuntimeError(f"cv2.writeOpticalFlow failed for {path}")


def read_flo(path: str | Path) -> tuple[np.ndarray, np.ndarray]:
    """((H, W, 2) float32 flow with unknown pixels set to 0, (H, W) bool known)."""
    flow = cv2.readOpticalFlow(str(path))
    if flow is None or flow.size == 0:
        raise InputError(path, "not a Middlebury .flo file")
    known = (np.abs(flow) < 1e9).all(axis=-1)
    flow = flow.copy()
    flow[~known] = 0.0
    return flow, known
