"""Plain-text tables of the commands' reports (``sot-apps eval``, ``sot-apps bench ...``)."""

from __future__ import annotations

import math
from typing import Sequence

__all__ = ["format_table", "format_value"]


def format_value(value: float | None, spec: str) -> str:
    """``value`` formatted with ``spec``; ``—`` for a missing or non-finite value."""
    return "—" if value is None or not math.isfinite(value) else format(value, spec)


def format_table(header: Sequence[str], rows: Sequence[Sequence[str]]) -> str:
    """The header, a dashed rule and the rows, columns two spaces apart: the first left-aligned, the others
    right-aligned. Every row has the header's number of cells."""
    widths = [max(len(h), *(len(r[i]) for r in rows)) if rows else len(h) for i, h in enumerate(header)]

    def line(cells: Sequence[str]) -> str:
        return "  ".join(c.ljust(w) if i == 0 else c.rjust(w)
                         for i, (c, w) in enumerate(zip(cells, widths, strict=True)))

    return "\n".join([line(header), "  ".join("-" * w for w in widths), *(line(r) for r in rows)])
