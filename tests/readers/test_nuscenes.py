"""nuScenes reader: v1.0 tables written from the synthetic world read back exactly; the real demo keyframe
(LIDAR_TOP .pcd.bin, poses, calibrations, 69 boxes) read through the same reader reproduces num_lidar_pts."""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
from scipy.spatial.transform import Rotation

from sot_apps.cli.main import main
from sot_apps.io import detect_format, open_sequence
from sot_apps.io.tiny import TINY_NUM_FRAMES
from tracker.geometry import invert_transform, make_transform, points_in_box, rotation_z, transform_points

from .paths import NUSCENES_DEMO

# ------------------------------------------------------------------ an independent nuScenes table writer


def _quat_wxyz(rotation: np.ndarray) -> list[float]:
    x, y, z, w = Rotation.from_matrix(rotation).as_quat()
    return [float(w), float(x), float(y), float(z)]


class TableWriter:
    """Writes the ten v1.0 tables the way the nuScenes schema documents them."""

    def __init__(self, root: Path, version: str = "v1.0-mini") -> None:
        self.root, self.dir = root, root / version
        self.t: dict[str, list[dict]] = {n: [] for n in ("scene", "sample", "sample_data", "ego_pose", "calibrated_sensor",
                                                         "sensor", "sample_annotation", "instance", "category", "log")}
        self.t["log"].append({"token": "log0", "logfile": "synthetic", "vehicle": "v", "date_captured": "2026-01-01",
                              "location": "nowhere"})

    def sensor(self, channel: str, modality: str, target_from_sensor: np.ndarray, K: np.ndarray | None = None) -> str:
        token = f"cs-{channel}"
        self.t["sensor"].append({"token": f"sensor-{channel}", "channel": channel, "modality": modality})
        self.t["calibrated_sensor"].append({"token": token, "sensor_token": f"sensor-{channel}",
                                            "translation": target_from_sensor[:3, 3].tolist(),
                                            "rotation": _quat_wxyz(target_from_sensor[:3, :3]),
                                            "camera_intrinsic": [] if K is None else np.asarray(K).tolist()})
        return token

    def ego_pose(self, token: str, timestamp_us: int, world_from_ego: np.ndarray) -> str:
        self.t["ego_pose"].append({"token": token, "timestamp": timestamp_us, "translation": world_from_ego[:3, 3].tolist(),
                                   "rotation": _quat_wxyz(world_from_ego[:3, :3])})
        return token

    def sample_data(self, token: str, sample: str, cs: str, pose: str, timestamp_us: int, filename: str, key: bool,
                    width: int = 0, height: int = 0) -> None:
        self.t["sample_data"].append({"token": token, "sample_token": sample, "ego_pose_token": pose,
                                      "calibrated_sensor_token": cs, "timestamp": timestamp_us, "fileformat": filename[-3:],
                                      "is_key_frame": key, "height": height, "width": width, "filename": filename,
                                      "prev": "", "next": ""})

    def annotation(self, token: str, sample: str, instance: str, category: str, centre, size_lwh, yaw: float,
                   num_lidar_pts: int = 0) -> None:
        if not any(c["name"] == category for c in self.t["category"]):
            self.t["category"].append({"token": f"cat-{category}", "name": category, "description": ""})
        if not any(i["token"] == instance for i in self.t["instance"]):
            self.t["instance"].append({"token": instance, "category_token": f"cat-{category}", "nbr_annotations": 0,
                                       "first_annotation_token": token, "last_annotation_token": token})
        length, width, height = size_lwh
        self.t["sample_annotation"].append({
            "token": token, "sample_token": sample, "instance_token": instance, "visibility_token": "4",
            "attribute_tokens": [], "translation": [float(v) for v in centre], "size": [width, length, height],
            "rotation": _quat_wxyz(rotation_z(yaw)), "prev": "", "next": "", "num_lidar_pts": num_lidar_pts,
            "num_radar_pts": 0})

    def write(self) -> Path:
        self.dir.mkdir(parents=True, exist_ok=True)
        for name, rows in self.t.items():
            (self.dir / f"{name}.json").write_text(json.dumps(rows))
        return self.root


def _link(root: Path, filename: str, source: Path) -> None:
    (root / filename).parent.mkdir(parents=True, exist_ok=True)
    (root / filename).symlink_to(source.resolve())


# nuScenes' LIDAR_TOP: x right, y forward, z up, 0.94 m ahead of the rear axle and 1.84 m up
_EGO_FROM_LIDAR = make_transform(rotation_z(-math.pi / 2), np.array([0.94, 0.0, 1.84]))


def _write_tiny_dataroot(tiny, root: Path) -> Path:
    w = TableWriter(root)
    cs_lidar = w.sensor("LIDAR_TOP", "lidar", _EGO_FROM_LIDAR)
    cam = tiny.cameras["front_camera"]
    cs_cam = w.sensor("CAM_FRONT", "camera", cam.ego_from_camera, cam.K)
    keys = list(range(0, TINY_NUM_FRAMES, 2))
    for k in keys:
        w.t["sample"].append({"token": f"s{k}", "timestamp": tiny.frames[k].timestamp_ns // 1000, "scene_token": "scene0",
                              "prev": f"s{k - 2}" if k else "", "next": f"s{k + 2}" if k + 2 < TINY_NUM_FRAMES else ""})
    w.t["scene"] += [{"token": "scene0", "log_token": "log0", "nbr_samples": len(keys), "first_sample_token": "s0",
                      "last_sample_token": f"s{keys[-1]}", "name": "scene-0001", "description": "tiny"},
                     {"token": "scene1", "log_token": "log0", "nbr_samples": 0, "first_sample_token": "",
                      "last_sample_token": "", "name": "scene-0002", "description": "empty"}]
    lidar_from_ego = invert_transform(_EGO_FROM_LIDAR)
    for k in range(TINY_NUM_FRAMES):
        key = k % 2 == 0
        sample = f"s{k if key else min(k + 1, keys[-1])}"
        stamp = tiny.frames[k].timestamp_ns // 1000
        folder = "samples" if key else "sweeps"
        name = f"{folder}/LIDAR_TOP/tiny__LIDAR_TOP__{stamp}.pcd.bin"
        sweep = tiny.sweep(k)
        xyz = transform_points(lidar_from_ego, sweep.xyz.astype(np.float64))
        data = np.column_stack([xyz, sweep.intensity, np.zeros(len(xyz))]).astype("<f4")
        (root / name).parent.mkdir(parents=True, exist_ok=True)
        if k != 9:  # frame 9's sweep file was lost
            data.tofile(root / name)
        w.sample_data(f"sd-lidar-{k}", sample, cs_lidar, w.ego_pose(f"ep-{k}", stamp, tiny.frames[k].world_from_ego),
                      stamp, name, key)
        cf = cam.frames[k]
        cam_stamp = cf.timestamp_ns // 1000
        cam_name = f"{folder}/CAM_FRONT/tiny__CAM_FRONT__{cam_stamp}.png"
        _link(root, cam_name, Path(cf.image_path))
        w.sample_data(f"sd-cam-{k}", sample, cs_cam, w.ego_pose(f"ep-cam-{k}", cam_stamp, cf.world_from_camera @
                                                                invert_transform(cam.ego_from_camera)),
                      cam_stamp, cam_name, key, cam.width, cam.height)
        if key:
            for ann in tiny.annotations[k]:
                b = ann.box
                w.annotation(f"a-{ann.track_id}-{k}", sample, f"inst-{ann.track_id}", "vehicle.car", b.center,
                             (b.length, b.width, b.height), b.heading)
    return w.write()


def test_tables_from_the_synthetic_world_read_back(tmp_path, capsys):
    from sot_apps.io.tiny import make_tiny_sequence

    tiny = open_sequence(make_tiny_sequence(tmp_path / "tiny"))
    root = _write_tiny_dataroot(tiny, tmp_path / "nuscenes")
    assert detect_format(root) == "nuscenes"
    assert main(["info", str(root), "--no-point-stats"]) == 2  # two scenes: the error names them
    assert "scene-0001, scene-0002" in capsys.readouterr().err
    seq = open_sequence(f"{root}#scene-0001")
    assert seq.id == "scene-0001" and len(seq) == TINY_NUM_FRAMES and seq.missing_sweeps() == [9]
    np.testing.assert_allclose(seq.ego_from_lidar, _EGO_FROM_LIDAR, atol=1e-12)
    for k in range(TINY_NUM_FRAMES):
        assert seq.frames[k].timestamp_ns == tiny.frames[k].timestamp_ns
        np.testing.assert_allclose(seq.frames[k].world_from_ego, tiny.frames[k].world_from_ego, atol=1e-9)
        if k != 9:
            np.testing.assert_allclose(seq.sweep(k).xyz, tiny.sweep(k).xyz, atol=2e-5)
            np.testing.assert_array_equal(seq.sweep(k).intensity, tiny.sweep(k).intensity)
        if k % 2:  # sweeps between keyframes carry no boxes
            assert seq.annotations[k] == []
        else:
            got = {a.track_id: a for a in seq.annotations[k]}
            assert set(got) == {f"inst-{a.track_id}" for a in tiny.annotations[k]}
            for ann in tiny.annotations[k]:
                g = got[f"inst-{ann.track_id}"]
                assert g.label == "vehicle.car"
                np.testing.assert_allclose(g.box.to_array(), ann.box.to_array(), atol=1e-9)
    cam = seq.cameras["CAM_FRONT"]
    tiny_cam = tiny.cameras["front_camera"]
    np.testing.assert_allclose(cam.K, tiny_cam.K)
    assert (cam.width, cam.height) == (tiny_cam.width, tiny_cam.height) and len(cam.frames) == TINY_NUM_FRAMES
    for got, want in zip(cam.frames, tiny_cam.frames, strict=True):
        assert got.timestamp_ns == want.timestamp_ns  # per-image time (50 ms before the lidar)
        np.testing.assert_allclose(got.world_from_camera, want.world_from_camera, atol=1e-9)
    tracks = seq.tracks()
    assert sorted(tracks) == ["inst-car-move", "inst-car-park"] and list(tracks["inst-car-move"].frames) == list(range(0, 20, 2))


# ------------------------------------------------------------------ the real demo keyframe


def _demo_dataroot(tmp_path: Path) -> tuple[Path, dict]:
    """The demo keyframe as a one-sample dataroot: its real point file, images, poses and calibrations,
    and its 69 boxes written back as nuScenes annotations (global frame, size w l h, yaw about z)."""
    info = json.loads((NUSCENES_DEMO / "DERIVED_info_from_pkl.json").read_text())["data_list"][0]
    root = tmp_path / "nuscenes_demo"
    w = TableWriter(root)
    global_from_ego = np.array(info["ego2global"])
    ego_from_lidar = np.array(info["lidar_points"]["lidar2ego"])
    stamp = int(round(info["timestamp"] * 1e6))
    cs = w.sensor("LIDAR_TOP", "lidar", ego_from_lidar)
    w.ego_pose("ep", stamp, global_from_ego)
    name = f"samples/LIDAR_TOP/{info['lidar_points']['lidar_path']}"
    _link(root, name, NUSCENES_DEMO / info["lidar_points"]["lidar_path"])
    w.sample_data("sd-lidar", "s0", cs, "ep", stamp, name, True)
    for channel, image in info["images"].items():
        ego_from_camera = np.array(image["cam2ego"])
        cs_cam = w.sensor(channel, "camera", ego_from_camera, np.array(image["cam2img"]))
        cam_name = f"samples/{channel}/{image['img_path']}"
        _link(root, cam_name, NUSCENES_DEMO / image["img_path"])
        # each image has its own ego pose: lidar2cam includes the ego motion between the two capture times
        world_from_camera = global_from_ego @ ego_from_lidar @ invert_transform(np.array(image["lidar2cam"]))
        pose = w.ego_pose(f"ep-{channel}", int(round(image["timestamp"] * 1e6)), world_from_camera @ invert_transform(ego_from_camera))
        w.sample_data(f"sd-{channel}", "s0", cs_cam, pose, int(round(image["timestamp"] * 1e6)), cam_name, True, 1600, 900)
    w.t["sample"].append({"token": "s0", "timestamp": stamp, "scene_token": "sc", "prev": "", "next": ""})
    w.t["scene"].append({"token": "sc", "log_token": "log0", "nbr_samples": 1, "first_sample_token": "s0",
                         "last_sample_token": "s0", "name": "scene-0061", "description": ""})
    global_from_lidar = global_from_ego @ ego_from_lidar
    for i, inst in enumerate(info["instances"]):
        x, y, z, length, width, height, yaw = inst["bbox_3d"]
        centre = transform_points(global_from_lidar, np.array([[x, y, z]]))[0]
        direction = global_from_lidar[:3, :3] @ np.array([math.cos(yaw), math.sin(yaw), 0.0])
        w.annotation(f"a{i}", "s0", f"i{i}", str(inst["bbox_label_3d"]), centre, (length, width, height),
                     math.atan2(direction[1], direction[0]), inst["num_lidar_pts"])
    return w.write(), info


def test_real_demo_points_in_boxes_equal_num_lidar_pts(readers_root, tmp_path):
    root, info = _demo_dataroot(tmp_path)
    seq = open_sequence(root)
    assert len(seq) == 1 and len(seq.sweep(0)) == 34688
    world = seq.points_world(0)
    truth = {f"i{i}": inst["num_lidar_pts"] for i, inst in enumerate(info["instances"])}
    counts = {a.track_id: int(points_in_box(world, a.box).sum()) for a in seq.annotations[0]}
    exact = sum(counts[t] == truth[t] for t in truth)
    close = sum(abs(counts[t] - truth[t]) <= 2 for t in truth)
    assert len(counts) == 69 and exact >= 60 and close >= 66, (exact, close)


def test_real_demo_box_centres_project_onto_the_camera_boxes(readers_root, tmp_path):
    root, info = _demo_dataroot(tmp_path)
    seq = open_sequence(root)
    centres = np.array([a.box.center for a in seq.annotations[0]])
    checked = 0
    for channel, instances in info["cam_instances"].items():
        cam = seq.cameras[channel]
        assert (cam.width, cam.height) == (1600, 900) and len(cam.frames) == 1
        cam_pts = transform_points(invert_transform(cam.frames[0].world_from_camera), centres)
        front = cam_pts[:, 2] > 0.1
        uv = cam_pts[front, :2] / cam_pts[front, 2:] * np.diag(cam.K)[:2] + cam.K[:2, 2]
        for inst in instances:
            assert np.min(np.linalg.norm(uv - inst["center_2d"], axis=1)) < 0.5
            checked += 1
    assert checked == 84


def test_bad_tables_and_point_files_are_named(tmp_path, capsys):
    from sot_apps.io.tiny import make_tiny_sequence

    tiny = open_sequence(make_tiny_sequence(tmp_path / "tiny"))
    root = _write_tiny_dataroot(tiny, tmp_path / "nuscenes")
    pcd = next((root / "samples" / "LIDAR_TOP").glob("*.pcd.bin"))
    pcd.write_bytes(pcd.read_bytes()[:-7])
    assert main(["info", f"{root}#scene-0001"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and str(pcd) in err[0] and "truncated" in err[0], err
    table = root / "v1.0-mini" / "sample_data.json"
    rows = json.loads(table.read_text())
    rows[3]["ego_pose_token"] = "no-such-pose"
    table.write_text(json.dumps(rows))
    assert main(["info", f"{root}#scene-0001", "--no-point-stats"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and str(table) in err[0] and "unknown calibrated_sensor_token or ego_pose_token" in err[0], err
