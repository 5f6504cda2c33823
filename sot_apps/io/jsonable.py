"""numpy values as plain JSON values: the one converter (reports, benchmark JSON, a track file's config)."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

__all__ = ["json_safe"]


def json_safe(value: Any) -> Any:
    """Dicts (keys as strings), lists, tuples, numpy arrays and scalars and paths as JSON values. A non-finite
    float (NaN, ±inf) becomes None: JSON has no such number, and a missing figure (e.g. the Shape of a row that has
    no shape) is written as null rather than refused."""
    if isinstance(value, dict):
        return {str(k): json_safe(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [json_safe(v) for v in value]
    if isinstance(value, np.ndarray):
        return json_safe(value.tolist())
    if isinstance(value, (float, np.floating)):
        return float(value) if np.isfinite(value) else None
    if isinstance(value, np.integer):
        return int(value)
    if isinstance(value, np.bool_):
        return bool(value)
    if isinstance(value, Path):
        return str(value)
    return value
