"""The ``bank`` app: surfel-mesh bank entries from the tracked shapes (``OUT/bank/``; docs/lidar_sim.md)."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

from . import AppBase, RunContext, SequenceTracks, Unit, UnitOutput, track_dir


@dataclass(frozen=True)
class BankConfig:
    mirror: bool = False
    min_quality: float = 0.0
    min_points: int = 30           # shapes with fewer points are not put into the bank


class BankApp(AppBase):
    name = "bank"
    config_type = BankConfig
    description = "surfel meshes of the tracked shapes, the vehicle bank of simulate-lidar"
    outputs = ("bank/<sequence>__<object>.ply", "bank/<sequence>__<object>.points.ply", "bank/index.json")

    def plan(self, config: BankConfig, run: RunContext) -> list:
        def units(s: SequenceTracks) -> list[Unit]:
            return [Unit(f"bank/{s.name}", {"tracks": s.checksums}, {"sequence": s.name, "object_ids": list(s.objects)},
                         s.name)]
        return self.per_sequence(run, units)

    def run(self, config: BankConfig, out: Path, sequence: str, object_ids: list[str]) -> UnitOutput:
        """Bank entries from one sequence's tracked shapes; the index over all sequences is written by finish."""

        from ..io.tracks import read_track
        from ..objects.bank import entry_from_points

        bank_root = Path(out) / "bank"
        entries, skipped, files = [], [], []
        for object_id in object_ids:
            header, track = read_track(track_dir(out, sequence, object_id))
            shape = track.shape_points
            assert shape is not None   # read_track always reads the shape
            quality = track.mean_score if len(track) else 0.0
            if len(shape) < config.min_points or quality < config.min_quality:
                skipped.append({"object": object_id, "shape_points": int(len(shape)), "quality": round(quality, 4)})
                continue
            source = {"kind": "track", "sequence": header.sequence, "object_id": object_id,
                      "track": str(Path(sequence) / "tracks" / object_id)}
            entry = entry_from_points(bank_root, f"{sequence}__{object_id}", shape, source, quality,
                                      label=track.label or None, mirror=config.mirror, size=track.size)
            entry.build_seconds = None   # keep index.json reproducible
            entries.append(entry.to_json())
            files += [bank_root / entry.mesh] + ([bank_root / entry.points] if entry.points else [])
        return UnitOutput(files, {"sequence": sequence, "entries": entries, "skipped": skipped})

    def finish(self, config: BankConfig, out: Path, results: list[dict]) -> None:
        """``OUT/bank/index.json`` from every sequence's entries."""
        from ..objects.bank import Bank, BankEntry, write_bank_index

        entries = [BankEntry.from_json(e) for r in results for e in r.get("entries", [])]
        if entries:
            write_bank_index(Bank(Path(out) / "bank", entries))
