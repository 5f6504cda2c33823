"""A small background (the synthetic world: road, walls, poles, parked and moving cars, rolling scan with
per-point times) and a bank of procedural vehicles, generated once per session; and one small benchmark."""

from __future__ import annotations

from pathlib import Path

import pytest

SMALL = dict(tracklets=8, frames=(0, 6), per_copy=8, range_m=(6.0, 30.0))


@pytest.fixture(scope="session")
def background(tmp_path_factory) -> Path:
    from sot_apps.synth import write_world

    return write_world(tmp_path_factory.mktemp("bg") / "world", frames=6, vehicles=2, seed=3)


@pytest.fixture(scope="session")
def bank(tmp_path_factory) -> Path:
    import numpy as np

    from sot_apps.io.ply import write_ply_mesh
    from sot_apps.objects.bank import Bank, entry_from_mesh_file, write_bank_index
    from sot_apps.synth.vehicles import make_vehicle

    root = tmp_path_factory.mktemp("bank")
    bank = Bank(root, [])
    for kind, size in (("sedan", (4.5, 1.8, 1.45)), ("suv", (4.7, 1.9, 1.75))):
        mesh = make_vehicle(kind, *size)
        path = root / f"{kind}.ply"
        write_ply_mesh(path, mesh.vertices, np.asarray(mesh.faces))
        bank.upsert(entry_from_mesh_file(root, path, kind, "Car"))
    write_bank_index(bank)
    return root


def _make_small(background: Path, bank: Path, out: Path, seed: int = 0) -> dict:
    from sot_apps.benchmark.make import MakeConfig, make_benchmark

    config = MakeConfig(str(background), str(bank), SMALL["tracklets"], SMALL["frames"], seed, str(out),
                        per_copy=SMALL["per_copy"], range_m=SMALL["range_m"])
    return make_benchmark(config, progress=False)


@pytest.fixture(scope="session")
def make_small():
    """``make_small(background, bank, out, seed=0)``: the small benchmark's ``make`` (8 tracklets, 6 frames)."""
    return _make_small


@pytest.fixture(scope="session")
def small_config() -> dict:
    return dict(SMALL)


@pytest.fixture(scope="session")
def small_benchmark(background, bank, tmp_path_factory) -> Path:
    out = tmp_path_factory.mktemp("bench") / "b"
    _make_small(background, bank, out)
    return out


HARD = dict(tracklets=8, frames=(0, 20), per_copy=8, profiles=("far_approach", "passing", "hidden", "oblique"))


@pytest.fixture(scope="session")
def hard_background(tmp_path_factory) -> Path:
    """An open synthetic road (no walls, no poles) of 20 frames without moving vehicles: room for the hard profiles."""
    from sot_apps.synth import write_world

    return write_world(tmp_path_factory.mktemp("road") / "road", frames=20, vehicles=0, seed=1, open_road=True)


AV2_TRACKS = ("bc1b7963", "f5e7cc26", "6ef9e307", "842a35d7")   # cars with 465-1166 points in the single sweep


@pytest.fixture(scope="session")
def real_bank(tmp_path_factory) -> Path:
    """A bank of 4 real, partial AV2 cars cut from one sweep (sot-apps bank build --from-annotations)."""
    from sot_apps.io import open_sequence
    from sot_apps.objects.bank import Bank, entries_from_annotations, write_bank_index
    from tests.readers.paths import AV2_LOG_B

    root = tmp_path_factory.mktemp("real_bank")
    seq = open_sequence(AV2_LOG_B)
    entries, skipped = entries_from_annotations(root, seq, [seq.resolve_track_id(t) for t in AV2_TRACKS],
                                                mirror=True, min_points=100)
    assert not skipped
    write_bank_index(Bank(root, entries))
    return root


@pytest.fixture(scope="session")
def hard_benchmark(hard_background, real_bank, tmp_path_factory) -> Path:
    """The four hard profiles on the synthetic road (2 tracklets each, 20 frames), real partial vehicles."""
    from sot_apps.benchmark.make import MakeConfig, make_benchmark

    out = tmp_path_factory.mktemp("hard") / "b"
    # seed 3: every profile listed (a far start often shows > 30 points and is not listed; same seed, same bytes)
    config = MakeConfig(str(hard_background), str(real_bank), HARD["tracklets"], HARD["frames"], 3, str(out),
                        per_copy=HARD["per_copy"], sensor="pandaset_pandar64", profiles=HARD["profiles"])
    make_benchmark(config, progress=False)
    return out
