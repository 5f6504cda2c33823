"""Protobuf wire format, just enough to locate fields without decoding them (zero-copy)."""

from __future__ import annotations

from typing import Iterator

__all__ = ["WireError", "varint", "fields", "select"]


class WireError(ValueError):
    """The bytes are not a well-formed protobuf message."""


def varint(buf: memoryview, pos: int, end: int) -> tuple[int, int]:
    value = shift = 0
    while True:
        if pos >= end or shift > 63:
            raise WireError(f"malformed varint at byte {pos}")
        byte = buf[pos]
        pos += 1
        value |= (byte & 0x7F) << shift
        if not byte & 0x80:
            return value, pos
        shift += 7


def fields(buf: memoryview, start: int = 0, end: int | None = None) -> Iterator[tuple[int, int, int, int, int]]:
    """Top-level fields of the message in ``buf[start:end]``: (number, wire type, tag start, value start, value end).

    For length-delimited fields (wire type 2) the value range excludes the length prefix.
    """
    end = len(buf) if end is None else end
    pos = start
    while pos < end:
        tag_start = pos
        key, pos = varint(buf, pos, end)
        number, wire_type = key >> 3, key & 7
        if wire_type == 0:
            _, value_end = varint(buf, pos, end)
            value_start = pos
        elif wire_type == 1:
            value_start, value_end = pos, pos + 8
        elif wire_type == 2:
            length, value_start = varint(buf, pos, end)
            value_end = value_start + length
        elif wire_type == 5:
            value_start, value_end = pos, pos + 4
        else:
            raise WireError(f"unsupported wire type {wire_type} at byte {tag_start}")
        if value_end > end or number == 0:
            raise WireError(f"field {number} at byte {tag_start} runs past the end of its message")
        yield number, wire_type, tag_start, value_start, value_end
        pos = value_end


def select(buf: memoryview, keep: set[int], start: int = 0, end: int | None = None) -> bytes:
    """The serialized message ``buf[start:end]`` restricted to the field numbers in ``keep``."""
    return b"".join(bytes(buf[tag_start:value_end]) for number, _, tag_start, _, value_end in fields(buf, start, end)
                    if number in keep)
