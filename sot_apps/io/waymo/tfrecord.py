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


def _compose(outer: tuple[int, ...], inner: tuple[int, ...]) -> tuple[int, ...]:
    """Columns of the GF(2)-linear map outer . inner (maps given by their images of 1 << i)."""
    return tuple(_apply(outer, c) for c in inner)


def _apply(columns: tuple[int, ...], reg: int) -> int:
    out = 0
    i = 0
    while reg:
        if reg & 1:
            out ^= columns[i]
        reg >>= 1
        i += 1
    return out


@lru_cache(maxsize=128)
def _shift_columns(nbytes: int) -> tuple[int, ...]:
    """The linear map 'feed ``nbytes`` zero bytes into the register', as its 32 columns."""
    if nbytes == 0:
        return tuple(1 << i for i in range(32))
    if nbytes == 1:
        table = _byte_table()
        return tuple((1 << i >> 8) ^ int(table[(1 << i) & 0xFF]) for i in range(32))
    half = _shift_columns(nbytes // 2)
    columns = _compose(half, half)
    return _compose(_shift_columns(1), columns) if nbytes % 2 else columns


@lru_cache(maxsize=128)
def _shift_tables(nbytes: int) -> np.ndarray:
    """(4, 256) lookup tables applying the ``nbytes`` zero-byte shift to a register byte by byte."""
    columns = np.array(_shift_columns(nbytes), dtype=np.uint32)
    bits = (np.arange(256)[:, None] >> np.arange(8)) & 1
    tables = np.zeros((4, 256), dtype=np.uint32)
    for j in range(4):
        tables[j] = np.bitwise_xor.reduce(np.where(bits == 1, columns[8 * j:8 * j + 8][None, :], 0).astype(np.uint32),
                                          axis=1)
    return tables


@lru_cache(maxsize=1)
def _word_tables() -> tuple[np.ndarray, np.ndarray]:
    """Tables applying the 4-zero-byte shift to the low and the high 16 bits of a register."""
    columns = np.array(_shift_columns(4), dtype=np.uint32)
    bits = ((np.arange(65536, dtype=np.uint32)[:, None] >> np.arange(16, dtype=np.uint32)) & 1).astype(bool)
    low = np.bitwise_xor.reduce(np.where(bits, columns[None, :16], np.uint32(0)), axis=1).astype(np.uint32)
    high = np.bitwise_xor.reduce(np.where(bits, columns[None, 16:], np.uint32(0)), axis=1).astype(np.uint32)
    return low, high


_CHUNK = 256  # bytes per parallel lane


def _raw_register(data: np.ndarray) -> int:
    """Register after feeding ``data`` into a zero register (no init, no final xor), vectorised.

    Leading zero bytes leave a zero register unchanged, so the data are left-padded to whole chunks
    (and a zero chunk is put in front whenever a level has an odd count). The chunks run in parallel, four bytes per step (register ^= word, then
    the 4-zero-byte shift by two 16-bit table lookups); then neighbours are combined pairwise
    (reg(AB) = shift_len(B)(reg(A)) ^ reg(B)) until one register is left.
    """
    low, high = _word_tables()
    rows = -(-data.size // _CHUNK)
    padded = np.zeros(rows * _CHUNK, dtype=np.uint8)
    padded[padded.size - data.size:] = data
    words = padded.view("<u4").reshape(rows, _CHUNK // 4).T.copy()  # (words per chunk, rows)
    regs = np.zeros(rows, dtype=np.uint32)
    for j in range(_CHUNK // 4):
        regs ^= words[j]
        regs = low[regs & np.uint32(0xFFFF)] ^ high[regs >> np.uint32(16)]
    length = _CHUNK
    while regs.size > 1:
        if regs.size % 2:
            regs = np.concatenate([np.zeros(1, np.uint32), regs])
        tables = _shift_tables(length)
        left, right = regs[0::2], regs[1::2]
        regs = (tables[0][left & 0xFF] ^ tables[1][(left >> 8) & 0xFF] ^ tables[2][(left >> 16) & 0xFF]
                ^ tables[3][left >> 24] ^ right)
        length *= 2
    return int(regs[0])


def crc32c(data: bytes | memoryview | np.ndarray) -> int:
    """CRC-32C (Castagnoli) of ``data``."""
    array = np.frombuffer(data, dtype=np.uint8) if not isinstance(data, np.ndarray) else data.view(np.uint8).ravel()
    if array.size == 0:
        return 0
    return (_raw_register(array) ^ _apply(_shift_columns(array.size), 0xFFFFFFFF)) ^ 0xFFFFFFFF


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
