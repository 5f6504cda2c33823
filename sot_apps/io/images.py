"""Camera images read whole or not at all.

OpenCV decodes a truncated JPEG without an error (libjpeg prints "Premature end of JPEG file" and fills the rest
with grey), so a damaged image would be drawn into pictures as if it were real. :func:`read_color_image` checks
that a JPEG ends with its end-of-image marker and that the decoder returned an image; anything else is an
InputError naming the file.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ..errors import InputError

__all__ = ["read_color_image"]

_JPEG_START, _JPEG_END = b"\xff\xd8", b"\xff\xd9"


def _jpeg_is_complete(data: bytes) -> bool:
    # 0xFF in the entropy-coded data is always followed by 0x00, so FFD9 near the end can only be the EOI marker;
    # a few bytes of padding after it are allowed
    return _JPEG_END in data[-64:]


def read_color_image(path: str | Path) -> np.ndarray:
    """The image at ``path`` as (H, W, 3) uint8 BGR; a missing, undecodable or truncated file -> InputError."""
    import cv2

    path = Path(path)
    try:
        data = path.read_bytes()
    except OSError as exc:
        raise InputError(path, f"cannot read the camera image ({exc.strerror or exc})") from None
    if data.startswith(_JPEG_START) and not _jpeg_is_complete(data):
        raise InputError(path, f"truncated JPEG ({len(data)} bytes, no end-of-image marker): the camera image is "
                               "damaged")
    image = cv2.imdecode(np.frombuffer(data, np.uint8), cv2.IMREAD_COLOR) if data else None
    if image is None:
        raise InputError(path, f"cannot decode the camera image ({len(data)} bytes; damaged or not an image)")
    return image
