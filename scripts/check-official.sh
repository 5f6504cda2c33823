#!/usr/bin/env bash
# Round trips of the label writers through the official tools (not part of the test suite).
#
#   bash scripts/check-official.sh            # from the repository root
#
# 1. KITTI tracking 0000 (../shared/data/readers) -> `sot-apps convert --labels kitti` -> TrackEval's
#    Kitti2DBox (car) against the original label file: HOTA >= 90.
# 2. AV2 log 7fab2350 -> `sot-apps convert --labels av2` (score 1 added; the rows with num_interior_pts > 0, as av2
#    counts a detection of a cuboid without points as a false positive) -> av2's detection evaluation against
#    the log's own annotations.feather: AP(REGULAR_VEHICLE) >= 0.95.
# 3. Both AV2 logs -> `sot-apps convert` (canonical, world frame) -> av2's own Cuboid.compute_interior_points on
#    the world points in every converted world box == the log's num_interior_pts.
#
# The official tools go into a separate venv ($OFFICIAL_VENV, default /tmp/official-venv) with the fewest
# dependencies: av2==0.3.6 and trackeval==1.3.0 (TrackEval, Jonathon Luiten's, as published on PyPI) without
# their declared dependencies (av2 declares torch, kornia, ... that its evaluation does not import), plus what
# the imports used here need. The project itself runs with $PYTHON (default: python on PATH, e.g. the project
# venv). Exit 0 only if every check passes.
set -euo pipefail

REPO="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
READERS="${SOT_APPS_READERS:-$REPO/../shared/data/readers}"
OFFICIAL_VENV="${OFFICIAL_VENV:-/tmp/official-venv}"
PYTHON="${PYTHON:-python}"
WORK="${WORK:-$(mktemp -d /tmp/check-official.XXXXXX)}"
AV2_A="$READERS/av2_sensor_test/sensor/val/7fab2350-7eaf-3b7e-a39d-6937a4c1bede"
AV2_B="$READERS/av2_sensor_test/sensor/val/adcf7d18-0510-35b0-a2fa-b4cea13a6d76"
KITTI="$READERS/kitti_tracking_labels/training"

if [ ! -x "$OFFICIAL_VENV/bin/python" ]; then
  echo "== creating $OFFICIAL_VENV"
  python3 -m venv "$OFFICIAL_VENV"
fi
OPY="$OFFICIAL_VENV/bin/python"
if ! "$OPY" -c "import av2.evaluation.detection.eval, av2.structures.cuboid, trackeval" 2>/dev/null; then
  echo "== installing the official tools into $OFFICIAL_VENV"
  "$OPY" -m pip install -q --no-deps av2==0.3.6 trackeval==1.3.0
  # what av2's detection evaluation and cuboid code and TrackEval's KITTI evaluation import
  "$OPY" -m pip install -q numpy scipy pandas pyarrow polars joblib tqdm universal-pathlib opencv-python-headless \
    pillow matplotlib numba
fi
"$OPY" -m pip list 2>/dev/null | grep -iE "^(av2|trackeval|numpy|pandas|polars|pyarrow) " | tr -s ' ' | sed 's/^/   /'

sot() { (cd "$REPO" && PYTHONPATH="$REPO" "$PYTHON" -m sot_apps.cli.main "$@"); }

echo "== converting (work dir $WORK)"
sot convert "$KITTI/label_02/0000.txt" --labels kitti --out "$WORK/kitti_out"
sot convert "$AV2_A" --labels av2 --out "$WORK/av2_labels"
sot convert "$AV2_A" --out "$WORK/av2_a" >/dev/null
sot convert "$AV2_B" --out "$WORK/av2_b" >/dev/null

cat > "$WORK/trackeval_kitti.py" <<'EOF'
import shutil, sys
from pathlib import Path

import numpy as np
import trackeval

original, converted, work = (Path(p) for p in sys.argv[1:4])
gt = work / "trackeval" / "gt"
(gt / "label_02").mkdir(parents=True, exist_ok=True)
shutil.copy(original, gt / "label_02" / "0000.txt")
frames = 1 + max(int(line.split()[0]) for line in original.read_text().splitlines() if line.strip())
(gt / "evaluate_tracking.seqmap.training").write_text(f"0000 empty 000000 {frames:06d}\n")
tracker = work / "trackeval" / "trackers" / "convert" / "data"
tracker.mkdir(parents=True, exist_ok=True)
shutil.copy(converted, tracker / "0000.txt")
dataset = trackeval.datasets.Kitti2DBox({"GT_FOLDER": str(gt), "TRACKERS_FOLDER": str(tracker.parents[1]),
                                         "TRACKERS_TO_EVAL": ["convert"], "CLASSES_TO_EVAL": ["car"],
                                         "SPLIT_TO_EVAL": "training", "PRINT_CONFIG": False,
                                         "OUTPUT_FOLDER": str(work / "trackeval" / "out")})
evaluator = trackeval.Evaluator({"USE_PARALLEL": False, "PRINT_RESULTS": False, "PRINT_CONFIG": False,
                                 "OUTPUT_SUMMARY": False, "OUTPUT_DETAILED": False, "PLOT_CURVES": False,
                                 "TIME_PROGRESS": False, "OUTPUT_EMPTY_CLASSES": False})
results, _ = evaluator.evaluate([dataset], [trackeval.metrics.HOTA()])
hota = results["Kitti2DBox"]["convert"]["COMBINED_SEQ"]["car"]["HOTA"]
score = 100 * float(np.mean(hota["HOTA"]))
print(f"KITTI 0000 -> convert --labels kitti -> TrackEval Kitti2DBox car: HOTA {score:.2f} "
      f"(DetA {100 * np.mean(hota['DetA']):.2f}, AssA {100 * np.mean(hota['AssA']):.2f}, "
      f"LocA {100 * np.mean(hota['LocA']):.2f}); required >= 90")
sys.exit(0 if score >= 90 else 1)
EOF

cat > "$WORK/av2_detection.py" <<'EOF'
import sys
from pathlib import Path

import pyarrow.feather as feather
from av2.evaluation.detection.eval import evaluate
from av2.evaluation.detection.utils import DetectionCfg

def ap(dts, gts):
    _, _, metrics = evaluate(dts, gts, DetectionCfg(eval_only_roi_instances=False), n_jobs=1)
    return metrics.loc["REGULAR_VEHICLE"]


if __name__ == "__main__":
    log, converted = Path(sys.argv[1]), Path(sys.argv[2])
    gts = feather.read_feather(log / "annotations.feather")
    dts = feather.read_feather(converted)
    gts["log_id"] = dts["log_id"] = log.name
    dts["score"] = 1.0
    # av2 drops ground-truth cuboids without interior points, and a detection of such a cuboid is then a
    # false positive: the detections are the converted boxes that hold points (num_interior_pts > 0)
    with_points = ap(dts[dts["num_interior_pts"] > 0], gts)
    every_row = ap(dts, gts)
    print(f"AV2 {log.name[:8]} -> convert --labels av2 -> av2 detection evaluation (detections = converted rows with "
          f"num_interior_pts > 0): AP(REGULAR_VEHICLE) {with_points['AP']:.4f} (ATE {with_points['ATE']:.4f} m, "
          f"ASE {with_points['ASE']:.4f}, AOE {with_points['AOE']:.4f}); required >= 0.95. "
          f"[every converted row as a detection: AP {every_row['AP']:.4f}]")
    sys.exit(0 if with_points["AP"] >= 0.95 else 1)
EOF

cat > "$WORK/av2_interior.py" <<'EOF'
import json, sys
from pathlib import Path

import numpy as np
import pyarrow.feather as feather
from av2.geometry.se3 import SE3
from av2.structures.cuboid import Cuboid

ok = True
for log, canonical in zip(sys.argv[1::2], sys.argv[2::2]):
    log, canonical = Path(log), Path(canonical)
    truth = feather.read_feather(log / "annotations.feather")
    truth = {(int(t), u): int(n) for t, u, n in zip(truth["timestamp_ns"], truth["track_uuid"], truth["num_interior_pts"])}
    doc = json.loads((canonical / "sequence.json").read_text())
    equal = total = 0
    for frame in doc["frames"]:
        if "points" not in frame:
            continue
        world_from_ego = np.array(frame["world_from_ego"])
        xyz = np.load(canonical / frame["points"])["xyz"].astype(np.float64)
        world = xyz @ world_from_ego[:3, :3].T + world_from_ego[:3, 3]
        for b in frame["boxes"]:
            h, p, r = b["heading"], b.get("pitch", 0.0), b.get("roll", 0.0)
            cz, sz, cy, sy, cx, sx = np.cos(h), np.sin(h), np.cos(p), np.sin(p), np.cos(r), np.sin(r)
            rotation = (np.array([[cz, -sz, 0], [sz, cz, 0], [0, 0, 1]]) @ np.array([[cy, 0, sy], [0, 1, 0], [-sy, 0, cy]])
                        @ np.array([[1, 0, 0], [0, cx, -sx], [0, sx, cx]]))
            cuboid = Cuboid(SE3(rotation, np.array([b["x"], b["y"], b["z"]])), b["length"], b["width"], b["height"])
            _, inside = cuboid.compute_interior_points(world)
            equal += int(inside.sum()) == truth[(int(frame["timestamp_ns"]), b["track_id"])]
            total += 1
    print(f"AV2 {log.name[:8]}: av2 Cuboid.compute_interior_points of the world points in the converted world boxes "
          f"== num_interior_pts for {equal} / {total} boxes")
    ok &= equal == total
sys.exit(0 if ok else 1)
EOF

status=0
echo "== TrackEval (KITTI 2D box, HOTA)"
"$OPY" "$WORK/trackeval_kitti.py" "$KITTI/label_02/0000.txt" "$WORK/kitti_out/label_02/0000.txt" "$WORK" || status=1
echo "== av2 detection evaluation"
"$OPY" "$WORK/av2_detection.py" "$AV2_A" "$WORK/av2_labels/annotations.feather" || status=1
echo "== av2 interior points in the world-frame boxes"
"$OPY" "$WORK/av2_interior.py" "$AV2_A" "$WORK/av2_a" "$AV2_B" "$WORK/av2_b" || status=1
echo "== $([ $status = 0 ] && echo 'all official round trips pass' || echo 'FAILED')"
exit $status
