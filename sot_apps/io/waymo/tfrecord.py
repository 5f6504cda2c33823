"""TFRecord framing without TensorFlow: record index, masked CRC32C checks, payload access.

A TFRecord file is a run of records ``<u64 LE length><u32 masked crc32c(length bytes)><payload>
<u32 masked crc32c(payload)>``, mask(crc) = ((crc >> 15) | (crc << 17)) + 0xa282ead8 (mod 2^32).
:class:`TFRecordFile` memory-maps the file, indexes the records once (checking every header CRC and
that no record runs past the end) and hands out payloads as memoryviews, checking a payload's CRC the
first time it is asked for with ``verify=True``.
"""

from __future__ import annotations

import mmap
import struct
from functools import lru_cache
from pathlib import Path

import numpy as np

from ...errors import InputError

__all__ = ["crc32c", "masked_crc32c", "TFRecordFile"]

_POLY = 0x82F63B78  # CRC-32C (Castagnoli), reflected
_MASK_DELTA = 0xA282EAD8


@lru_cache(maxsize=1)
def _byte_table() -> np.ndarray:
    """table[b] = register after feeding byte b into a zero register (reflected CRC-32C)."""
    reg = np.arange(256, dtype=np.uint32)
    for _ in range(8):
        reg = np.where(reg & 1, (reg >> 1) ^ np.uint32(_POLY), reg >> 1).astype(np.uint32)
    return reg


def _zero_shift(reg: int, table: np.ndarray) -> int:
    """Register after feeding one zero byte."""
    return (reg >> 8) ^ int(table[reg & 0xFF])


@lru_cache(maxsize=64)
def _shift_columns(nbytes: int) -> tuple[int, ...]:
    """The GF(2)-linear map 'feed ``nbytes`` zero bytes' as its 32 columns (images of 1 << i)."""
    table = _byte_table()

    def apply(columns: tuple[int, ...], reg: int) -> int:
        out = 0
        i = 0
        while reg:
            if reg & 1:
                out ^= columns[i]
            reg >>= 1
            i += 1
        return out

    result = tuple(1 << i for i in range(32))  # identity
    power = tuple(_zero_shift(1 << i, table) for i in range(32))  # one byte
    n = nbytes
    while n:
        if n & 1:
            result = tuple(apply(power, c) for c in result)
        power = tuple(apply(power, c) for c in power)
        n >>= 1
    return result


def _apply_shift(nbytes: int, reg: int) -> int:
    columns = _shift_columns(nbytes)
    out = 0
    for i in range(32):
        if reg >> i & 1:
            out ^= columns[i]
    return out


def _raw_register(data: np.ndarray, chunk: int) -> int:
    """Register after feeding ``data`` into a zero register (no init, no final xor), vectorised.

    The data are left-padded with zeros (which leave a zero register unchanged) to whole chunks; all
    chunks are run in parallel, then combined: reg = shift_chunk(reg) ^ chunk_register.
    """
    table = _byte_table()
    n = data.size
    rows = -(-n // chunk)
    padded = np.zeros(rows * chunk, dtype=np.uint8)
    padded[rows * chunk - n:] = data
    block = padded.reshape(rows, chunk).T.copy()  # (chunk, rows): contiguous per step
    regs = np.zeros(rows, dtype=np.uint32)
    for j in range(chunk):
        regs = (regs >> np.uint32(8)) ^ table[(regs ^ block[j]) & np.uint32(0xFF)]
    columns = _shift_columns(chunk)
    reg = 0
    for value in regs.tolist():
        shifted = 0
        i = 0
        while reg:
            if reg & 1:
                shifted ^= columns[i]
            reg >>= 1
            i += 1
        reg = shifted ^ value
    return reg


def crc32c(data: bytes | memoryview | np.ndarray) -> int:
    """CRC-32C (Castagnoli) of ``data``."""
    array = np.frombuffer(data, dtype=np.uint8) if not isinstance(data, np.ndarray) else data.view(np.uint8).ravel()
    n = array.size
    if n == 0:
        return 0
    chunk = max(64, int(np.sqrt(n)) // 4)
    raw = _raw_register(array, chunk)
    return (raw ^ _apply_shift(n, 0xFFFFFFFF)) ^ 0xFFFFFFFF


def masked_crc32c(data: bytes | memoryview | np.ndarray) -> int:
    crc = crc32c(data)
    return ((((crc >> 15) | (crc << 17)) & 0xFFFFFFFF) + _MASK_DELTA) & 0xFFFFFFFF


class TFRecordFile:
    """Records of one TFRecord file, indexed at open (header CRCs checked), payloads on demand."""

    def __init__(self, path: str | Path) -> None:
        self.path = Path(path)
        if not self.path.is_file():
            raise InputError(self.path, "no such file")
        self._file = open(self.path, "rb")
        size = self.path.stat().st_size
        self._map = mmap.mmap(self._file.fileno(), 0, access=mmap.ACCESS_READ) if size else None
        self.offsets: list[tuple[int, int]] = []  # (payload start, payload length)
        self._verified: set[int] = set()
        offset = 0
        while offset < size:
            k = len(self.offsets)
            if offset + 12 > size:
                raise InputError(self.path, f"truncated TFRecord: record {k} at byte {offset} has an incomplete header")
            header = self._map[offset:offset + 12]
            (length,) = struct.unpack("<Q", header[:8])
            (length_crc,) = struct.unpack("<I", header[8:])
            if masked_crc32c(header[:8]) != length_crc:
                raise InputError(self.path, f"not a TFRecord or corrupt: record {k} at byte {offset} fails its length CRC")
            end = offset + 12 + length + 4
            if end > size:
                raise InputError(self.path, f"truncated TFRecord: record {k} at byte {offset} needs {end - offset} bytes, "
                                            f"only {size - offset} left")
            self.offsets.append((offset + 12, length))
            offset = end

    def __len__(self) -> int:
        return len(self.offsets)

    def payload(self, index: int, verify: bool = True) -> memoryview:
        """Record ``index``'s payload (zero-copy); ``verify`` checks its CRC once."""
        start, length = self.offsets[index]
        view = memoryview(self._map)[start:start + length] if self._map is not None else memoryview(b"")
        if verify and index not in self._verified:
            (stored,) = struct.unpack("<I", self._map[start + length:start + length + 4])
            if masked_crc32c(view) != stored:
                raise InputError(self.path, f"corrupt TFRecord: record {index} (byte {start - 12}) fails its data CRC")
            self._verified.add(index)
        return view
