"""``sot-apps benchmark make``: hundreds of tracklets with exact ground truth in real background sweeps.

Layout of ``OUT``::

    OUT/benchmark.json                 every listed tracklet (LiDAR-SOT list format + difficulty, profile, ...)
    OUT/easy.json, medium.json, hard.json   the same entries split by difficulty (as LiDAR-SOT ships them)
    OUT/make.json                      the configuration, counts and timing
    OUT/<background>_cNN/              one canonical sequence per copy of the background (frames A:B renumbered
                                       from 0) with the real annotations and every inserted vehicle's boxes,
                                       plus inserted.json (vehicles, motions, trajectories) and
                                       labels/NNNNNN.npz (per point: -1 real, else the vehicle's index)

Many tracklets share one copy (``--per-copy``, default 14): one simulation per frame serves all of them.
The whole plan (every vehicle of every copy) is drawn first from ``--seed``; copies are then simulated
independently (``--workers``) and each is marked done with its plan's digest, so an interrupted run resumes
where it stopped and the same seed gives the same bytes.
"""

from __future__ import annotations

import dataclasses
import hashlib
import itertools
import json
import time
from concurrent.futures import ProcessPoolExecutor
from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np
from tqdm import tqdm

from tracker import DIFFICULTY_THRESHOLDS, difficulty, points_in_box, transform_points

from ..errors import InputError
from ..io import open_sequence
from ..io.atomic import write_json, write_npz
from ..io.canonical import write_sequence
from ..io.sequence import BoxAnnotation, FrameInfo, Sequence, Sweep
from ..objects.bank import split_entries
from ..objects.motion_profiles import ALL_PROFILES, PROFILES, MotionSpec
from ..objects.selection import annotated_span
from ..schemas import validate
from .background import boxes_array, build_ground_map, ego_from_sensor, fitted_sensor
from .deps import Bank, Realism, load_sensor, read_bank
from .hard_profiles import PROFILE_BANDS, hidden_frames, points_ok, tracklet_geometry
from .insert import InsertedFrame, simulate_frame, vehicle_scenes
from .placement import InsertedVehicle, PlacementContext, place_occluder, place_vehicle

__all__ = ["MakeConfig", "plan_copies", "make_benchmark", "CopyPlan"]

TYPE_VEHICLE = 1  # Waymo Label.Type as LiDAR-SOT's lists carry it


@dataclass(frozen=True)
class MakeConfig:
    background: str
    bank: str
    tracklets: int
    frames: tuple[int, int]        # [A, B): python slice of the background's frames
    seed: int
    out: str
    per_copy: int = 14
    sensor: str = "pandar64"
    range_m: tuple[float, float] = (5.0, 80.0)
    drop_random: float = 0.0
    workers: int = 1
    origin: tuple[float, float, float] = (0.0, 0.0, 0.0)   # the optical centre in the LiDAR frame
    replicas: tuple[str, ...] = ()   # instead of profiles: copies of these real tracks (bank entries of theirs)
    band_edges_m: tuple[float, ...] = (17.0, 40.0)   # range bands filled in turn (pandar64: ~easy / medium / hard)
    profiles: tuple[str, ...] = PROFILES   # tracklet i gets profiles[i mod len]
    split: str = "all"                      # the part of the bank drawn from: choose, confirm or all


@dataclass(frozen=True)
class CopyPlan:
    index: int
    name: str
    vehicles: list[InsertedVehicle]

    def digest(self, config: MakeConfig) -> str:
        h = hashlib.sha256(json.dumps({k: v for k, v in asdict(config).items() if k not in ("workers", "out")},
                                      sort_keys=True).encode())
        for v in self.vehicles:
            h.update(f"{v.id}|{v.bank_id}|{v.listed}|{v.hidden}".encode())
            h.update(np.ascontiguousarray(v.states).tobytes())
        return h.hexdigest()[:16]


def _frames(seq: Sequence, frames: tuple[int, int]) -> list[int]:
    a, b = frames
    if not (0 <= a < b <= len(seq)):
        raise InputError(seq.root, f"--frames {a}:{b} is outside the sequence's 0:{len(seq)}")
    if b - a < 2:
        raise InputError(seq.root, "--frames needs at least 2 frames")
    return list(range(a, b))


def _context(seq: Sequence, frames: list[int], config: MakeConfig) -> PlacementContext:
    ground = build_ground_map(seq, frames)
    times = np.array([seq.frames[k].timestamp_ns for k in frames], dtype=np.int64)
    sensor_xyh = []
    for k in frames:
        m = seq.frames[k].world_from_ego @ seq.ego_from_lidar
        sensor_xyh.append((m[0, 3], m[1, 3], np.arctan2(m[1, 0], m[0, 0])))
    real = [boxes_array([a.box for a in (seq.annotations[k] if seq.annotations else [])]) for k in frames]
    seam = fitted_sensor(seq, frames, load_sensor(config.sensor)).scan_start_deg
    return PlacementContext(ground, times, np.array(sensor_xyh), real, config.range_m, seam_deg=seam)


def box_size(bank: Bank, entry, sigma: float) -> tuple[float, float, float]:
    """The ground-truth box size of a bank entry: its (annotated) size, grown where needed to cover the mesh
    plus three range-noise sigmas on each side (a mesh file's size is its exact bounds, which noisy returns
    leave half the time)."""
    vertices, _ = bank.mesh(entry.id)
    extent = 2.0 * np.abs(vertices).max(axis=0) + 6.0 * sigma
    return tuple(round(float(max(a, b)), 3) for a, b in zip(entry.box_size(), extent, strict=True))  # type: ignore[return-value]


def _place_tracklet(ctx: PlacementContext, rng: np.random.Generator, vid: str, entry, profile: str,
                    band: tuple[float, float], entries, sizes: dict) -> list[InsertedVehicle] | None:
    """The tracklet's vehicle (and, for ``occluded``, its occluder: up to 3 target places are tried; for
    ``hidden``, the frames whose points are removed)."""
    for _ in range(3 if profile == "occluded" else 1):
        vehicle = place_vehicle(ctx, rng, vid, entry.id, entry.label or "Car", sizes[entry.id], profile, band)
        if vehicle is not None and profile == "hidden":
            vehicle = dataclasses.replace(vehicle, hidden=hidden_frames(rng, len(ctx.frame_times_ns)))
        if vehicle is None or profile != "occluded":
            return None if vehicle is None else [vehicle]
        occ = entries[int(rng.integers(len(entries)))]
        occluder = place_occluder(ctx, rng, vehicle, vid.replace("ins_", "occ_"), occ.id, occ.label or "Car",
                                  sizes[occ.id])
        if occluder is not None:
            return [vehicle, occluder]
        ctx.remove_last()
    return None


def range_bands(range_m: tuple[float, float], edges: tuple[float, ...]) -> list[tuple[float, float]]:
    """``range_m`` cut at ``edges`` (bands narrower than 1 m are dropped)."""
    cuts = [range_m[0]] + [e for e in edges if range_m[0] < e < range_m[1]] + [range_m[1]]
    return [(a, b) for a, b in itertools.pairwise(cuts) if b - a >= 1.0] or [tuple(range_m)]


def _plan_replicas(seq: Sequence, bank: Bank, config: MakeConfig, frames: list[int]) -> list[CopyPlan]:
    """One copy in which each real track of ``config.replicas`` is replaced by its bank vehicle on the real path
    (the real car's points are cut, the copy is simulated): same ranges, headings and occluders (realism check)."""
    sigma = load_sensor(config.sensor).range_noise_sigma
    tracks = seq.tracks()
    vehicles = []
    for prefix in config.replicas:
        tid = seq.resolve_track_id(prefix)
        entry = next((e for e in bank.entries if e.source.get("track") == tid), None)
        if entry is None:
            raise InputError(Path(config.bank) / "index.json", f"no bank entry built from track {tid}")
        trk = tracks[tid]
        ks = [k for k in frames if trk.box_at(k) is not None]
        first, last = annotated_span(ks) if ks else (0, -1)
        run = list(range(first, last + 1))
        if len(run) < 2:
            raise InputError(seq.root, f"track {tid} has fewer than 2 frames in --frames")
        boxes = [trk.box_at(k) for k in run]
        states = np.array([[b.x, b.y, b.z, b.heading] for b in boxes])
        states[:, 3] = np.unwrap(states[:, 3])
        times = np.array([seq.frames[k].timestamp_ns for k in run], dtype=np.int64)
        vehicles.append(InsertedVehicle(f"rep_{tid[:8]}", entry.id, entry.label or "Car", box_size(bank, entry, sigma),
                                        MotionSpec("replica", 0.0), times, states, True, None,
                                        (run[0] - frames[0], run[-1] - frames[0]), tid))
    return [CopyPlan(0, f"{seq.id}_replicas", vehicles)]


def plan_copies(seq: Sequence, bank: Bank, config: MakeConfig, progress: bool = False) -> list[CopyPlan]:
    """Every copy's inserted vehicles (deterministic in ``config.seed``).

    Tracklet i gets profile i mod P (``config.profiles``) and range band (i div P) mod bands, shuffled by the
    seed, so every profile meets every band; a profile of :data:`PROFILE_BANDS` starts in its own band instead.
    Vehicles are drawn from the bank's ``config.split`` part. A copy takes tracklets in turn until ``per_copy``
    are placed; a (profile, band) that finds no place in a copy is not tried again in that copy (its tracklets
    wait for the next copy). One that finds no place even in an empty copy is widened to the whole range; a
    profile that fails so in 3 empty copies makes the background unusable."""
    frames = _frames(seq, config.frames)
    if config.replicas:
        return _plan_replicas(seq, bank, config, frames)
    rng = np.random.default_rng(config.seed)
    bands = range_bands(config.range_m, config.band_edges_m)
    profiles = config.profiles
    unknown = [p for p in profiles if p not in ALL_PROFILES]
    if unknown or not profiles:
        raise InputError(None, f"unknown motion profile {unknown[0] if unknown else '(none)'}; known: "
                               f"{', '.join(ALL_PROFILES)}")
    cells = [(profiles[i % len(profiles)], PROFILE_BANDS.get(profiles[i % len(profiles)],
                                                              bands[(i // len(profiles)) % len(bands)]))
             for i in range(config.tracklets)]
    queue = [cells[i] for i in rng.permutation(len(cells))]
    plans: list[CopyPlan] = []
    entries = sorted(split_entries(bank.entries, config.split), key=lambda e: e.id)
    if not entries:
        raise InputError(Path(config.bank) / "index.json", f"the bank has no entry in its {config.split!r} part")
    sigma = load_sensor(config.sensor).range_noise_sigma
    sizes = {e.id: box_size(bank, e, sigma) for e in entries}
    bar = tqdm(total=len(queue), desc="placing", unit="tracklet", disable=not progress, leave=False)
    base = _context(seq, frames, config)
    impossible: set[tuple] = set()   # (profile, band) that found no place even in an empty copy
    hopeless: dict[str, int] = {}    # profile -> empty copies in which it found no place in the whole range
    for attempt in itertools.count():
        if not queue:
            break
        c = len(plans)
        ctx = base.fresh()
        crng = np.random.default_rng([config.seed, attempt])
        vehicles: list[InsertedVehicle] = []
        left = []
        failed: set[tuple] = set()
        for cell in queue:
            profile, band = cell = (cell[0], tuple(config.range_m)) if cell in impossible else cell
            if sum(v.listed for v in vehicles) >= config.per_copy or cell in failed:
                left.append(cell)
                continue
            entry = entries[int(crng.integers(len(entries)))]
            vid = f"ins_c{c:02d}_{len(vehicles):02d}"
            placed = _place_tracklet(ctx, crng, vid, entry, profile, band, entries, sizes)
            if placed is None:
                failed.add(cell)
                if not vehicles:  # nowhere even in an empty copy: widen the band to the whole range, then give up
                    if band == tuple(config.range_m):
                        hopeless[profile] = hopeless.get(profile, 0) + 1
                        if hopeless[profile] >= 3:
                            raise InputError(seq.root, f"could not place a {profile} tracklet on free ground of the "
                                                       "background even in 3 empty copies (try other --frames, or "
                                                       "the synthetic open road: docs/benchmark.md)")
                    impossible.add(cell)
                left.append(cell)
                continue
            vehicles += placed
            bar.update(1)
        queue = left
        if vehicles:
            plans.append(CopyPlan(c, f"{seq.id}_c{c:02d}", vehicles))
    bar.close()
    return plans


def _hide(frame: InsertedFrame, hidden: list[int]) -> InsertedFrame:
    """The frame without the points of the inserted vehicles ``hidden`` (their boxes stay: ground truth)."""
    if not hidden:
        return frame
    keep = ~np.isin(frame.instance, hidden)
    return dataclasses.replace(frame, xyz=frame.xyz[keep], intensity=frame.intensity[keep],
                               time_offset_ns=frame.time_offset_ns[keep], instance=frame.instance[keep])


def _xyh(world_from_sensor: np.ndarray) -> tuple[float, float, float]:
    return (float(world_from_sensor[0, 3]), float(world_from_sensor[1, 3]),
            float(np.arctan2(world_from_sensor[1, 0], world_from_sensor[0, 0])))


def _geometry(v: InsertedVehicle, j: int, a: int, b: int, sensor_xyh: np.ndarray, box_xyh: np.ndarray) -> dict:
    """The profile's per-tracklet figures (hard_profiles.tracklet_geometry) over frames a..b, relative to a."""
    hidden = (v.hidden[0] - a, v.hidden[1] - a) if v.hidden else None
    boxes = box_xyh[a:b + 1, j]
    return tracklet_geometry(v.motion.profile, boxes[:, 0:2], boxes[:, 2], sensor_xyh[a:b + 1], hidden)


_BACKGROUNDS: dict[str, Sequence] = {}


def _background(path: str) -> Sequence:
    """The background, opened once per process with every sweep kept once read (copies reread them all)."""
    if path not in _BACKGROUNDS:
        seq = open_sequence(path)
        seq.cache_size = len(seq)
        _BACKGROUNDS[path] = seq
    return _BACKGROUNDS[path]


def _copy_done(directory: Path, digest: str) -> bool:
    path = directory / "done.json"
    if not path.is_file():
        return False
    try:
        return json.loads(path.read_text()).get("digest") == digest
    except (json.JSONDecodeError, OSError):
        return False


def _simulate_copy(config: MakeConfig, plan: CopyPlan, progress: bool = False) -> dict:
    """Simulate and write one copy; returns its tracklet summaries (also stored in done.json)."""
    out = Path(config.out) / plan.name
    digest = plan.digest(config)
    if _copy_done(out, digest):
        return json.loads((out / "done.json").read_text())
    seq = _background(config.background)
    bank = read_bank(config.bank)
    frames = _frames(seq, config.frames)
    sensor = fitted_sensor(seq, frames, load_sensor(config.sensor))
    meshes = {v.bank_id: bank.mesh(v.bank_id) for v in plan.vehicles}
    scenes = vehicle_scenes(plan.vehicles, meshes)
    sweeps: list[Sweep] = []
    infos: list[FrameInfo] = []
    annotations: list[list[BoxAnnotation]] = []
    counts = np.zeros((len(frames), len(plan.vehicles)), dtype=np.int64)
    sensor_xyh: list[tuple[float, float, float]] = []
    box_xyh: list[list[tuple[float, float, float]]] = []
    removed = [0, 0]
    for i, k in enumerate(tqdm(frames, desc=plan.name, unit="frame", disable=not progress, leave=False)):
        realism = Realism(drop_random=config.drop_random, seed=config.seed * 1_000_003 + plan.index * 1_009 + k)
        replaced = {v.replaces for v in plan.vehicles if v.replaces}
        real = [a for a in (seq.annotations[k] if seq.annotations else []) if a.track_id not in replaced]
        cut = [a.box for a in (seq.annotations[k] if seq.annotations else []) if a.track_id in replaced]
        frame = _hide(simulate_frame(seq, k, sensor, plan.vehicles, meshes, realism, scenes, config.origin, cut),
                      [j for j, v in enumerate(plan.vehicles) if v.hidden and v.hidden[0] <= i <= v.hidden[1]])
        sweeps.append(Sweep(frame.xyz, frame.intensity, frame.time_offset_ns))
        write_npz(out / "labels" / f"{i:06d}.npz", instance=frame.instance)
        info = seq.frames[k]
        infos.append(FrameInfo(i, info.timestamp_ns, info.world_from_ego, Path(f"points/{i:06d}.npz")))
        annotations.append(real + [BoxAnnotation(v.id, v.label, b, stationary=False)
                                   for v, b in zip(plan.vehicles, frame.boxes, strict=True)])
        world = transform_points(info.world_from_ego, frame.xyz)
        counts[i] = [int(points_in_box(world, b).sum()) for b in frame.boxes]
        sensor_xyh.append(_xyh(info.world_from_ego @ ego_from_sensor(seq, config.origin)))
        box_xyh.append([(b.x, b.y, b.heading) for b in frame.boxes])
        removed[0] += frame.removed_real
        removed[1] += frame.removed_inserted
    copy = Sequence(id=plan.name, root=Path(config.background), format="benchmark", frames=infos,
                    load_sweep=lambda j: sweeps[j], ego_from_lidar=seq.ego_from_lidar, annotations=annotations,
                    cache_size=0)
    write_json(out / "inserted.json", {
        "version": 1, "background": str(config.background), "frames": list(config.frames),
        "sensor": sensor.to_dict(), "vehicles": [
            {"id": v.id, "bank_id": v.bank_id, "label": v.label, "listed": v.listed, "occluder_of": v.occluder_of,
             "size": {"length": v.size[0], "width": v.size[1], "height": v.size[2]}, "motion": v.motion.to_dict(),
             "hidden_frames": list(v.hidden) if v.hidden else None,
             "times_ns": v.times_ns, "states": np.round(v.states, 5)} for v in plan.vehicles]})
    write_sequence(copy, out, progress=False)
    n = min(10, len(frames))
    tracklets = []
    unlisted: dict[str, int] = {}
    for j, v in enumerate(plan.vehicles):
        if not v.listed:
            continue
        a, b = v.span if v.span is not None else (0, len(frames) - 1)
        hidden = (v.hidden[0] - a, v.hidden[1] - a) if v.hidden else None
        if not points_ok(v.motion.profile, counts[a:b + 1, j], hidden):
            unlisted[v.motion.profile] = unlisted.get(v.motion.profile, 0) + 1
            continue
        mean10 = float(counts[a:a + n, j].mean())
        sensor_xy = (seq.frames[frames[a]].world_from_ego @ ego_from_sensor(seq, config.origin))[:2, 3]
        r0 = float(np.hypot(*(annotations[a][len(annotations[a]) - len(plan.vehicles) + j].box.center[:2] - sensor_xy)))
        tracklets.append({"id": v.id, "type": TYPE_VEHICLE, "segment_name": plan.name,
                          "frame_range": [a, b], "difficulty": difficulty(mean10, DIFFICULTY_THRESHOLDS),
                          "profile": v.motion.profile, "mean_points_first10": round(mean10, 2),
                          "initial_range_m": round(r0, 2), "bank_id": v.bank_id, "motion": v.motion.to_dict(),
                          "min_points": int(counts[a:b + 1, j].min()),
                          "mean_points": round(float(counts[a:b + 1, j].mean()), 2),
                          "start_points": int(counts[a, j]), "split": config.split}
                         | _geometry(v, j, a, b, np.array(sensor_xyh), np.array(box_xyh)))
    summary = {"digest": digest, "tracklets": tracklets, "unlisted": unlisted, "removed_real_points": removed[0],
               "removed_inserted_points": removed[1]}
    write_json(out / "done.json", summary)
    return summary


def make_benchmark(config: MakeConfig, progress: bool = True) -> dict:
    """Plan, simulate (resuming finished copies) and write the lists; returns make.json's content."""
    start = time.perf_counter()
    seq = _background(config.background)
    bank = read_bank(config.bank)
    if not bank.entries:
        raise InputError(Path(config.bank) / "index.json", "the bank has no entries")
    if (config.tracklets < 1 and not config.replicas) or config.per_copy < 1:
        raise InputError(None, "--tracklets and --per-copy must be >= 1")
    plans = plan_copies(seq, bank, config, progress)
    planned = time.perf_counter() - start
    out = Path(config.out)
    out.mkdir(parents=True, exist_ok=True)
    summaries: list[dict] = []
    if config.workers > 1:
        from ..interrupts import ignore_sigint, sigint_ignored_in_children

        with sigint_ignored_in_children():   # Ctrl-C is the parent's: the workers neither print nor go on
            pool = ProcessPoolExecutor(config.workers, initializer=ignore_sigint)
            futures = [pool.submit(_simulate_copy, config, p) for p in plans]
        try:
            for f in tqdm(futures, desc="copies", unit="copy", disable=not progress):
                summaries.append(f.result())
        except BaseException:   # Ctrl-C: exit promptly (the caller holds OUT's lock: the leftovers are ours)
            from ..interrupts import stop_process_pool
            from ..io.atomic import remove_stale_temporaries

            stop_process_pool(pool)
            remove_stale_temporaries(out)
            raise
        pool.shutdown()
    else:
        bar = tqdm(plans, desc="copies", unit="copy", disable=not progress)
        for p in bar:
            summaries.append(_simulate_copy(config, p, progress))
    entries = [t for s in summaries for t in s["tracklets"]]
    validate("benchmark", entries, out / "benchmark.json")
    write_json(out / "benchmark.json", entries)
    for level in ("easy", "medium", "hard"):
        write_json(out / f"{level}.json", [e for e in entries if e["difficulty"] == level])
    counts = {"difficulty": {d: sum(e["difficulty"] == d for e in entries) for d in ("easy", "medium", "hard")},
              "profile": {p: sum(e["profile"] == p for e in entries)
                          for p in list(config.profiles)
                          + sorted({e["profile"] for e in entries} - set(config.profiles))}}
    unlisted: dict[str, int] = {}
    for s in summaries:
        for p, n in s.get("unlisted", {}).items():
            unlisted[p] = unlisted.get(p, 0) + n
    report = {"config": asdict(config), "copies": len(plans), "tracklets": len(entries), "counts": counts,
              "unlisted": unlisted,
              "removed_real_points": sum(s["removed_real_points"] for s in summaries),
              "removed_inserted_points": sum(s["removed_inserted_points"] for s in summaries),
              "seconds": {"planning": round(planned, 1), "total": round(time.perf_counter() - start, 1)}}
    write_json(out / "make.json", {k: v for k, v in report.items() if k != "seconds"} | {"seconds": report["seconds"]})
    return report
