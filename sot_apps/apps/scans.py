"""The ``scans`` app: bank vehicles placed around a simulated sensor and ray cast (``OUT/scans/``; docs/lidar_sim.md)."""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path

from . import AppBase, RunContext, Skip, Unit, UnitOutput


@dataclass(frozen=True)
class ScanConfig:
    sensor: str = "pandar64"
    ranges_m: tuple[float, ...] = (20.0, 40.0)
    headings_deg: tuple[float, ...] = (0.0, 45.0, 90.0, 135.0)
    max_entries: int = 3


def scene_name(entry_id: str, range_m: float) -> str:
    return f"{entry_id}__r{range_m:g}m"


class ScansApp(AppBase):
    name = "scans"
    config_type = ScanConfig
    description = "simulated LiDAR scans of the best bank vehicles at several ranges and headings"
    outputs = ("scans/<entry>__r<range>m/{scan.npz, boxes.json, labels_kitti.txt, preview.png, scene.json}",)
    needs = ("bank",)

    def plan(self, config: ScanConfig, run: RunContext) -> list[Unit | Skip]:
        from ..io.checksums import sha256_file
        from ..objects.bank import read_bank

        bank = read_bank(run.out / "bank", must_exist=False)
        entries = sorted(bank.entries, key=lambda e: (-e.quality, e.id))[: config.max_entries]
        if not entries:
            return [Skip("scans", "the bank has no entries")]
        units: list[Unit | Skip] = []
        for e in entries:
            mesh = run.out / "bank" / e.mesh
            mesh_sum = sha256_file(mesh) if mesh.is_file() else None
            for r in config.ranges_m:
                units.append(Unit(f"scans/{scene_name(e.id, float(r))}", {"mesh": mesh_sum, "range": r},
                                  {"entry_id": e.id, "range_m": float(r)}, None, e.id))
        return units

    def run(self, config: ScanConfig, out: Path, entry_id: str, range_m: float) -> UnitOutput:
        """One bank vehicle placed ``len(headings)`` times at ``range_m`` (evenly spread azimuths, one heading
        each) and ray cast."""
        from ..lidar_sim.scene import SceneObject, SceneSpec
        from ..lidar_sim.simulate import run_simulation
        from ..objects.bank import read_bank
        from ..sensor.model import load_sensor
        from ..sensor.noise import Realism

        bank = read_bank(Path(out) / "bank")
        entry = bank.get(entry_id)
        n = len(config.headings_deg)
        objects = []
        for i, heading in enumerate(config.headings_deg):
            azimuth = 2.0 * math.pi * i / n + math.radians(20.0)
            objects.append(SceneObject(entry.id, round(range_m * math.cos(azimuth), 4),
                                       round(range_m * math.sin(azimuth), 4), None, math.radians(float(heading)),
                                       entry.label))
        spec = SceneSpec(load_sensor(config.sensor), -1.8, objects, Realism(motion_distortion=False, seed=0))
        scene = scene_name(entry_id, range_m)
        outputs = run_simulation(spec, bank, Path(out) / "scans" / scene, preview_extent=max(25.0, range_m * 1.25))
        counts = [int((outputs.result.scan.instance == i).sum()) for i in range(len(objects))]
        return UnitOutput(list(outputs.files), {"scene": scene, "entry": entry_id, "range_m": range_m,
                                                "headings_deg": list(config.headings_deg), "points": counts})
