"""``read_npz``: the arrays of an ``.npz`` file, or one InputError that names the file and says what is wrong."""

from __future__ import annotations

import zipfile
from pathlib import Path

import numpy as np

from ..errors import InputError

__all__ = ["read_npz"]


def read_npz(path: str | Path) -> dict[str, np.ndarray]:
    """All arrays of ``path`` (never unpickles: object arrays are refused as bad input)."""
    path = Path(path)
    try:
        with open(path, "rb") as handle:
            head = handle.read(4)
        if head[:2] != b"PK":
            raise InputError(path, "not an npz archive (no zip header): the file is corrupt or of another type")
        with np.load(path, allow_pickle=False) as data:
            return {k: data[k] for k in data.files}
    except InputError:
        raise
    except ValueError as exc:
        if "pickle" in str(exc):
            raise InputError(path, "holds object arrays (pickled Python objects), which are never loaded; "
                                   "point files hold plain numeric arrays") from exc
        raise InputError(path, f"cannot read npz: file is truncated or corrupt ({exc})") from exc
    except (zipfile.BadZipFile, OSError, EOFError, KeyError) as exc:
        raise InputError(path, f"cannot read npz: file is truncated or corrupt ({type(exc).__name__}: {exc})") from exc
