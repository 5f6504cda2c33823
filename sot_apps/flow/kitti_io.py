"""KITTI flow PNGs: 16-bit, 3 channels (R, G, B) = (u, v, valid), value = flow * 64 + 2**15.

OpenCV reads and writes BGR, so the array handed to cv2 is ``[valid, v, u]``. Flow is rounded to
1/64 px and clipped to the representable range (-512, +512) px. Invalid pixels store u = v = 0
(i.e. 2**15) and valid = 0.
"""

from __future__ import annotations

from pathlib import Path
from typing import Sequence

import cv2
import numpy as np

from ..errors import InputError
from ..io.atomic import write_bytes
from .png import Pieces, encode_rows_png

__all__ = ["encode_kitti_flow", "decode_kitti_flow", "kitti_flow_png", "kitti_flow_pngs", "write_kitti_flow",
           "write_kitti_flows", "read_kitti_flow"]

_INVALID_RGB = (2 ** 15, 2 ** 15, 0)   # an invalid pixel in PNG channel order (u, v, valid)
_BE16 = np.dtype(">u2")                # the block is built in PNG's byte order: the encoder filters it as it is


def _kitti_values(flow: np.ndarray) -> np.ndarray:
    """(..., 2) flow -> (..., 2) uint16 u, v as stored (1/64 px, offset 2**15, clipped)."""
    if flow.dtype == np.float32:
        # flow * 64 is exact in float32 (a power of two), so is its rounding; adding the even offset 2**15 after
        # the rounding gives what rounding flow * 64 + 2**15 (float64, exact) gives, half-to-even ties included
        scaled = flow * np.float32(64.0)
        np.rint(scaled, out=scaled)
        np.clip(scaled, -(2.0 ** 15), 2.0 ** 15 - 1, out=scaled)
        scaled += np.float32(2.0 ** 15)
        return scaled.astype(np.uint16)
    scaled = flow.astype(np.float64)      # float64: flow * 64 + 2**15 is exact before the rounding
    scaled *= 64.0
    scaled += 2.0 ** 15
    np.rint(scaled, out=scaled)
    np.clip(scaled, 0, 65535, out=scaled)
    return scaled.astype(np.uint16)


def encode_kitti_flow(flow: np.ndarray, valid: np.ndarray) -> np.ndarray:
    """(H, W, 3) uint16 array in cv2 (BGR) order: [valid, v, u]."""
    flow = np.asarray(flow)
    valid = np.asarray(valid, dtype=bool)
    out = np.zeros(flow.shape[:2] + (3,), dtype=np.uint16)
    out[..., 1:] = 2 ** 15
    valid = valid & np.isfinite(flow).all(axis=-1)
    vs, us = np.nonzero(valid)
    scaled = _kitti_values(flow[vs, us])
    out[vs, us, 0] = 1
    out[vs, us, 1] = scaled[:, 1]
    out[vs, us, 2] = scaled[:, 0]
    return out


def decode_kitti_flow(bgr: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Inverse of :func:`encode_kitti_flow`: ((H, W, 2) float32 flow (u, v), (H, W) bool valid)."""
    bgr = np.asarray(bgr)
    flow = (np.stack([bgr[..., 2], bgr[..., 1]], axis=-1).astype(np.float32) - 2.0 ** 15) / 64.0
    valid = bgr[..., 0] > 0
    flow[~valid] = 0.0
    return flow, valid


def _pixels_of(flow: np.ndarray, flat: np.ndarray) -> np.ndarray:
    """(N, 2) flow of the pixels with flat indices ``flat``. A float32 map is gathered as one 8-byte item per pixel
    (~10x faster than a row gather; the bits are copied as they are); other types row by row."""
    if flow.dtype == np.float32 and flow.flags.c_contiguous:
        return flow.reshape(-1, 2).view(np.uint64).reshape(-1)[flat].view(np.float32).reshape(-1, 2)
    return flow.reshape(-1, 2)[flat]


def _both_finite(values: np.ndarray) -> np.ndarray:
    """(N,) bool: both components of the (N, 2) float32 ``values`` are finite (two bools read as one uint16)."""
    return np.isfinite(values).view(np.uint16).reshape(-1) == 0x0101


class _FlowBlock:
    """The rows of a KITTI flow PNG that hold valid pixels, filled: ``pixels`` (len(rows), W, 3) big-endian
    uint16 in PNG order, ``candidates`` the valid pixels' flat indices into the block."""

    def __init__(self, flow: np.ndarray, valid: np.ndarray) -> None:
        height, width = valid.shape
        rows = np.flatnonzero(valid.any(axis=1))
        candidates = np.flatnonzero(valid[rows])           # flat indices into the (len(rows), W) block
        image_index = np.flatnonzero(valid)                 # the same pixels, in the same order, in the image
        values = _pixels_of(flow, image_index)
        finite = _both_finite(values)
        if not finite.all():
            candidates, values = candidates[finite], values[finite]
        row = np.empty((width, 3), dtype=_BE16)
        row[:] = _INVALID_RGB                               # invalid pixels: u = v = 0 px, valid = 0
        pixels = np.empty((len(rows), width, 3), dtype=_BE16)
        pixels[:] = row                                     # row by row: a plain copy, not a 3-value broadcast
        stored = np.empty((len(candidates), 3), dtype=_BE16)
        stored[:, :2] = _kitti_values(values)
        stored[:, 2] = 1
        # one scatter of whole 6-byte pixels (as opaque items: ~2x faster than a (N, 3) row scatter)
        pixels.reshape(-1, 3).view("V6").reshape(-1)[candidates] = stored.view("V6").reshape(-1)
        self.height, self.rows, self.pixels, self.candidates = height, rows, pixels, candidates

    def png(self, cuts: Sequence[int] = (), reuse: Pieces | None = None, keep: Pieces | None = None) -> bytes:
        """The PNG (``cuts``/``reuse``/``keep``: pieces of rows, :func:`~sot_apps.flow.png.encode_rows_png`)."""
        return encode_rows_png(self.pixels, self.rows, self.height, _INVALID_RGB, cuts, reuse, keep)

    def changed_rows(self, keep: np.ndarray) -> np.ndarray:
        """(len(rows),) bool: the block rows in which some valid pixel is not in ``keep`` (an (H, W) mask)."""
        drop = self.candidates[~keep[self.rows].reshape(-1)[self.candidates]]
        changed = np.zeros(len(self.rows), dtype=bool)
        changed[drop // self.pixels.shape[1]] = True
        return changed

    def restricted(self, keep: np.ndarray) -> "_FlowBlock":
        """The block with only the pixels of ``keep`` (an (H, W) mask) still valid (a copy; this one unchanged)."""
        out = object.__new__(_FlowBlock)
        kept = keep[self.rows].reshape(-1)[self.candidates]
        out.height, out.rows, out.candidates = self.height, self.rows, self.candidates[kept]
        out.pixels = self.pixels.copy()
        out.pixels.reshape(-1, 3)[self.candidates[~kept]] = _INVALID_RGB
        return out


def kitti_flow_png(flow: np.ndarray, valid: np.ndarray) -> bytes:
    """The KITTI flow PNG's bytes (decoded: exactly :func:`encode_kitti_flow`). Only the rows that hold valid
    pixels are encoded (:mod:`.png`), so the cost follows the object pixels, not the image size."""
    return _FlowBlock(np.asarray(flow), np.asarray(valid, dtype=bool)).png()


def kitti_flow_pngs(flow: np.ndarray, valid: np.ndarray, valid_subset: np.ndarray) -> tuple[bytes, bytes]:
    """The PNGs of :func:`kitti_flow_png` for ``valid`` and for ``valid_subset`` (e.g. flow_occ and flow_noc: the
    non-occluded pixels are some of all the valid ones), the flow values scaled once for both. A subset mask
    that is not one is taken as it is (each PNG on its own).

    The first PNG is compressed in pieces cut around the rows that the subset changes; the second copies every
    other piece and compresses only those rows again."""
    flow = np.asarray(flow)
    valid = np.asarray(valid, dtype=bool)
    subset = np.asarray(valid_subset, dtype=bool)
    block = _FlowBlock(flow, valid)
    if (subset & ~valid).any():
        return block.png(), kitti_flow_png(flow, subset)
    changed = block.changed_rows(subset)
    if not changed.any():
        data = block.png()
        return data, data
    edges = np.flatnonzero(np.diff(changed.astype(np.int8))) + 1     # where runs of changed rows start and end
    pieces: Pieces = {}
    data = block.png(cuts=edges.tolist(), keep=pieces)
    reusable = {span: piece for span, piece in pieces.items() if not changed[span[0]:span[1]].any()}
    return data, block.restricted(subset).png(cuts=edges.tolist(), reuse=reusable)


def write_kitti_flow(path: str | Path, flow: np.ndarray, valid: np.ndarray, sync: bool = True) -> None:
    """The KITTI flow PNG of ``flow`` where ``valid``, atomically (``sync``: :func:`sot_apps.io.atomic.write_bytes`)."""
    write_bytes(path, kitti_flow_png(flow, valid), sync)


def write_kitti_flows(path: str | Path, subset_path: str | Path, flow: np.ndarray, valid: np.ndarray,
                      valid_subset: np.ndarray, sync: bool = True) -> None:
    """:func:`write_kitti_flow` of ``valid`` to ``path`` and of ``valid_subset`` to ``subset_path``
    (:func:`kitti_flow_pngs`: the values scaled once)."""
    data, subset_data = kitti_flow_pngs(flow, valid, valid_subset)
    write_bytes(path, data, sync)
    write_bytes(subset_path, subset_data, sync)


def read_kitti_flow(path: str | Path) -> tuple[np.ndarray, np.ndarray]:
    with open(path, "rb") as handle:   # not cv2.imread: any path the OS takes (non-UTF-8 names too)
        image = cv2.imdecode(np.frombuffer(handle.read(), np.uint8), cv2.IMREAD_UNCHANGED)
    if image is None or image.dtype != np.uint16 or image.ndim != 3 or image.shape[2] != 3:
        raise InputError(path, "not a 16-bit 3-channel KITTI flow PNG")
    return decode_kitti_flow(image)
