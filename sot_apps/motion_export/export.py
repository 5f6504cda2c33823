"""The motion export as one call: tracks -> kinematics -> MCAP and tables."""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

from .. import __version__
from ..io.object_track import ObjectTrack
from ..io.sequence import Sequence
from ..objects.smoother import (
    ANNOTATION_SMOOTHER,
    TRACKER_SMOOTHER,
    SmootherConfig,
    smooth_track,
)
from .mcap_writer import McapSummary, write_motion_mcap
from .tables import make_scenario, write_csv, write_npz_table, write_parquet

__all__ = ["ExportResult", "export_motion"]


@dataclass
class ExportResult:
    kinematics: list[ObjectTrack]
    mcap: McapSummary | None = None
    outputs: dict[str, str] = field(default_factory=dict)


def export_motion(sequence: Sequence, tracks: list[ObjectTrack], out_mcap: str | Path | None,
                  parquet: str | Path | None = None, npz: str | Path | None = None, csv: str | Path | None = None,
                  with_points: bool = False, smoother: SmootherConfig | None = None, source: str = "tracks",
                  focal_track_id: str | None = None, observed_steps: int | None = None,
                  progress: bool = True, extra_metadata: dict | None = None) -> ExportResult:
    """Smooth every track and write the requested outputs (each atomically)."""
    if smoother is None:
        smoother = ANNOTATION_SMOOTHER if source == "annotations" else TRACKER_SMOOTHER
    kinematics = [smooth_track(t, smoother) for t in tracks]
    result = ExportResult(kinematics=kinematics)
    if out_mcap is not None:
        metadata = {"source": source, "sequence": sequence.id, "sequence_path": str(sequence.root),
                    "sot_apps_version": __version__, "smoother": {"model": "CTRV EKF + RTS", **smoother.to_dict()},
                    "inputs": [t.source for t in tracks], "with_points": with_points,
                    "tracker_configs": {t.object_id: t.config for t in tracks}, **(extra_metadata or {})}
        result.mcap = write_motion_mcap(out_mcap, sequence, kinematics, metadata, with_points=with_points,
                                        progress=progress)
        result.outputs["mcap"] = str(out_mcap)
    if parquet is not None or npz is not None:
        scenario = make_scenario(sequence.id, sequence.timestamps_ns, kinematics, focal_track_id, observed_steps)
        if parquet is not None:
            write_parquet(parquet, scenario)
            result.outputs["parquet"] = str(parquet)
        if npz is not None:
            write_npz_table(npz, scenario)
            result.outputs["npz"] = str(npz)
    if csv is not None:
        write_csv(csv, kinematics)
        result.outputs["csv"] = str(csv)
    return result
