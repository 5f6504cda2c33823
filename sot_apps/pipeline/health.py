"""Track health of a pipeline run: which finished tracks look lost (sot_apps.evaluation.track_health).

A tracking unit that finished ("done" or "cached") still may have lost its object; the run summary,
``manifest.json`` (``track_health``) and the report list these instead of counting them as simply done.
"""

from __future__ import annotations

from pathlib import Path

from ..evaluation.track_health import track_health
from ..io.tracks import read_track
from .stages import track_dir

__all__ = ["run_track_health", "health_lines"]


def run_track_health(out: Path, records) -> list[dict]:
    """``[{sequence, object, status, measured, frames, ...}]`` for every finished tracking unit of ``records``: the
    verdict the tracking task recorded with the track (its summary, or its completion marker for a cached unit),
    else read from its ``track.json``."""
    rows = []
    for r in records:
        if r.stage != "track" or r.status not in ("done", "cached"):
            continue
        recorded = (r.result or {}).get("health")
        if recorded is not None:
            rows.append({"sequence": r.sequence, **recorded})
            continue
        directory = track_dir(out, r.sequence, r.object)
        if (directory / "track.json").is_file():
            rows.append({"sequence": r.sequence, **track_health(read_track(directory)[1]).to_json()})
    return rows


def health_lines(health: list[dict]) -> list[str]:
    """One count line, then one ``LOST`` line per track that looks lost (empty without tracks)."""
    if not health:
        return []
    count = {s: sum(h["status"] == s for h in health) for s in ("ok", "weak", "lost")}
    lines = [f"track health (tracker's own evidence, docs/pipeline.md): {count['ok']} ok, {count['weak']} weak "
             f"(measured in < 80 % of frames), {count['lost']} look lost (< 20 %)"]
    for h in health:
        if h["status"] == "lost":
            where = f", on the motion prior from frame {h['lost_from']}" if h["lost_from"] is not None else ""
            lines.append(f"LOST {h['sequence']}/{h['object']}: measured {h['measured']}/{h['frames']} frames, "
                         f"mean quality {h['mean_quality']:.2f}{where}")
    return lines
