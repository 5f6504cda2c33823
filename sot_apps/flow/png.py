"""A PNG encoder for mostly-background images (flow and instance maps: objects cover a few % of a frame).

Only the rows that hold content are filtered and compressed; every background row is one deflate segment
compressed once and repeated (a segment ends with a full flush: it neither refers back nor is referred to, so
segments can be concatenated). The content rows are filtered with PNG's Sub filter all at once (numpy: a run of
background pixels filters to zero bytes) and each run of consecutive content rows goes through zlib (level 1) in
one call, which releases the GIL: the encoder runs beside the flow computation of the next pair. The zlib
checksum of the whole stream is combined from the pieces' checksums arithmetically.
The pieces can be kept and reused by a later image that shares them (flow_noc differs from flow_occ only in the
rows holding occluded pixels: :func:`~sot_apps.flow.kitti_io.kitti_flow_pngs`).
The decoded pixels are exactly the array given (lossless; tests read the files back with OpenCV).
"""

from __future__ import annotations

import struct
import zlib
from typing import Sequence

import numpy as np

__all__ = ["encode_png", "encode_rows_png"]

_SIGNATURE = b"\x89PNG\r\n\x1a\n"
_ADLER_MOD = 65521
_LEVEL = 1            # zlib level: the maps are smooth, level 1 is within ~15 % of level 6 in size
_MEM_LEVEL = 8        # zlib's default hash table (a smaller one gave 5 % larger files for the same time)
_SUB = 1              # PNG filter type "Sub": byte minus the same byte of the pixel to the left

Pieces = dict[tuple[int, int], tuple[bytes, int]]   # (first, stop) row index -> (deflate segment, Adler-32)


def _chunk(kind: bytes, data: bytes) -> bytes:
    return struct.pack(">I", len(data)) + kind + data + struct.pack(">I", zlib.crc32(data, zlib.crc32(kind)))


def _segment(compressor, data) -> bytes:
    """``data`` as a self-contained raw deflate segment (byte-aligned, no back references, not final)."""
    return compressor.compress(data) + compressor.flush(zlib.Z_FULL_FLUSH)


def _adler_combine(adler: int, block_adler: int, length: int) -> int:
    """Adler-32 of A + B from that of A, that of B alone (``block_adler``, started at 1) and B's ``length``
    (zlib's adler32_combine: per byte of B, S2 gains S1(A))."""
    a1, b1 = adler & 0xFFFF, adler >> 16
    a2, b2 = block_adler & 0xFFFF, block_adler >> 16
    a = (a1 + a2 - 1) % _ADLER_MOD
    b = (b1 + b2 + length * a1 - length) % _ADLER_MOD
    return (b << 16) | a


def _adler_repeat(adler: int, block_adler: int, length: int, count: int) -> int:
    """Adler-32 after ``count`` more copies of a block of ``length`` bytes whose own Adler-32 is ``block_adler``
    (by doubling: the copies of 1, 2, 4, ... blocks that make up ``count``)."""
    while count:
        if count & 1:
            adler = _adler_combine(adler, block_adler, length)
        block_adler, length, count = _adler_combine(block_adler, block_adler, length), 2 * length, count >> 1
    return adler


def _filtered(pixels: np.ndarray, bpp: int) -> np.ndarray:
    """(R, 1 + W * bpp) uint8: the rows of ``pixels`` (R, W[, 3]) in big-endian bytes, Sub-filtered, with the
    filter type byte in front (pixels already big-endian are not copied)."""
    raw = np.ascontiguousarray(pixels, dtype=pixels.dtype.newbyteorder(">")).view(np.uint8).reshape(len(pixels), -1)
    out = np.empty((len(raw), raw.shape[1] + 1), dtype=np.uint8)
    out[:, 0] = _SUB
    out[:, 1:1 + bpp] = raw[:, :bpp]
    np.subtract(raw[:, bpp:], raw[:, :-bpp], out=out[:, 1 + bpp:])
    return out


def encode_png(image: np.ndarray, background: tuple[int, ...] | int = 0, content: np.ndarray | None = None) -> bytes:
    """PNG bytes of an (H, W) grey or (H, W, 3) RGB image, uint8 or uint16 (channels in PNG order: R, G, B).

    ``background``: the pixel value of most pixels. ``content``: optional (H, W) bool, True wherever a pixel may
    differ from the background (a superset is fine; a row without any True is written as background, so when in
    doubt leave it None and the rows are found from the pixels).
    """
    image = np.asarray(image)
    _check(image)
    if content is None:
        bg = np.broadcast_to(np.asarray(background, dtype=image.dtype), (1 if image.ndim == 2 else 3,))
        differs = image != bg[0] if image.ndim == 2 else (image != bg).any(axis=2)
        rows = np.flatnonzero(differs.any(axis=1))
    else:
        content = np.asarray(content, dtype=bool)
        if content.shape != image.shape[:2]:
            raise ValueError(f"content mask {content.shape} does not match the image {image.shape[:2]}")
        rows = np.flatnonzero(content.any(axis=1))
    return encode_rows_png(image[rows], rows, len(image), background)


def _check(image: np.ndarray) -> None:
    if image.dtype.newbyteorder("=") not in (np.uint8, np.uint16) or image.ndim not in (2, 3) or (image.ndim == 3 and image.shape[2] != 3):
        raise ValueError(f"encode_png needs (H, W) or (H, W, 3) uint8/uint16, got {image.shape} {image.dtype}")


def encode_rows_png(pixels: np.ndarray, rows: np.ndarray, height: int, background: tuple[int, ...] | int = 0,
                    cuts: Sequence[int] = (), reuse: Pieces | None = None, keep: Pieces | None = None) -> bytes:
    """As :func:`encode_png` for an image of ``height`` rows of which only ``rows`` (increasing) hold anything but
    background: ``pixels[i]`` is row ``rows[i]``.

    The rows are compressed in pieces: each run of consecutive row numbers, also cut before every index of
    ``cuts``. ``keep``: filled with every piece, {(i, j): (deflate segment, Adler-32)} for ``pixels[i:j]``.
    ``reuse``: pieces of an earlier call whose pixel rows i..j-1 were the same as this call's (same width,
    background and dtype): they are copied instead of compressed again.
    """
    image = np.asarray(pixels)
    _check(image)
    rows = np.asarray(rows, dtype=np.int64)   # (pixels may be big-endian: PNG's byte order, written as they are)
    width = image.shape[1]
    if len(rows) != len(image) or (len(rows) and (rows.min() < 0 or rows.max() >= height or np.any(np.diff(rows) <= 0))):
        raise ValueError("rows must be increasing row numbers below height, one per row of pixels")
    channels = 1 if image.ndim == 2 else 3
    bg = np.broadcast_to(np.asarray(background, dtype=image.dtype), (channels,))
    bpp = channels * image.dtype.itemsize          # bytes per pixel
    row_bytes = 1 + width * bpp
    # a background row, filtered: the filter type, the first pixel as is, then zero differences
    empty_row = bytes([_SUB]) + bg.astype(image.dtype.newbyteorder(">")).tobytes() + bytes((width - 1) * bpp)
    compressor = zlib.compressobj(_LEVEL, zlib.DEFLATED, -15, _MEM_LEVEL)
    empty_segment, empty_adler = _segment(compressor, empty_row), zlib.adler32(empty_row)

    runs = (np.flatnonzero(np.diff(rows) != 1) + 1).tolist()
    bounds_list = sorted({0, len(rows), *runs, *(int(c) for c in cuts if 0 < c < len(rows))})
    parts: list[bytes] = []
    adler = 1
    done = 0                                          # image rows written so far
    for first, stop in zip(bounds_list[:-1], bounds_list[1:], strict=True):
        row = int(rows[first])
        parts.append(empty_segment * (row - done))
        adler = _adler_repeat(adler, empty_adler, row_bytes, row - done)
        piece = reuse.get((first, stop)) if reuse is not None else None
        if piece is None:
            data = memoryview(_filtered(image[first:stop], bpp)).cast("B")   # the piece's rows at once
            piece = (_segment(compressor, data), zlib.adler32(data))
        if keep is not None:
            keep[(first, stop)] = piece
        parts.append(piece[0])
        adler = _adler_combine(adler, piece[1], (stop - first) * row_bytes)
        done = int(rows[stop - 1]) + 1
    parts.append(empty_segment * (height - done))
    adler = _adler_repeat(adler, empty_adler, row_bytes, height - done)
    parts.append(compressor.flush(zlib.Z_FINISH))   # the final (empty) block
    stream = b"\x78\x01" + b"".join(parts) + struct.pack(">I", adler)
    colour_type = 0 if channels == 1 else 2
    header = struct.pack(">IIBBBBB", width, height, 8 * image.dtype.itemsize, colour_type, 0, 0, 0)
    return _SIGNATURE + _chunk(b"IHDR", header) + _chunk(b"IDAT", stream) + _chunk(b"IEND", b"")
