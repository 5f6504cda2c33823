#!/usr/bin/env bash
# Build the tracker's selection material from ../shared into OUT (docs/benchmark.md, "The selection set"):
# the two banks, the synthetic roads and worlds, the choosing sets and the confirming sets, each under the name
# the rule's commands use (docs/evaluation.md, "The rule for changing `full`"). Every step is one documented
# command; a rerun skips what exists (`benchmark make` resumes its copies).
#
#   bash scripts/make-selection-sets.sh OUT [choose|confirm|all]     # default all
#
# `choose` builds the banks, roads, worlds and choosing sets only (17 minutes on the 2-core VM), `confirm` the
# confirming sets (and the banks and roads they need).
set -euo pipefail

OUT=${1:?usage: make-selection-sets.sh OUT [choose|confirm|all]}
PART=${2:-all}
HERE=$(cd "$(dirname "$0")/.." && pwd)
SHARED=${SOT_APPS_SHARED:-$HERE/../shared}
PANDASET=$SHARED/data/pandaset_002
READERS=$SHARED/data/readers
WORKERS=${WORKERS:-2}
mkdir -p "$OUT"
cd "$OUT"

step() { echo "== $*" >&2; }

# ---------------------------------------------------------------- banks
if [ ! -f bank/.done ]; then
  step "bank: the 44 vehicles"
  rm -rf bank nuscenes_demo
  sot-apps bank build --from-annotations "$PANDASET" --track-id 20d13d1d --track-id 8ac00bad \
    --track-id 0d238564 --track-id f0b32b02 --track-id 91aa5b5c --track-id 71a404f3 --track-id 8febbea0 \
    --track-id 1a46fa13 --track-id b09e1c68 --mirror --out bank
  for log in "$READERS"/av2_sensor_test/sensor/val/*; do
    sot-apps bank build --from-annotations "$log" --all --min-points 100 --mirror --out bank
  done
  sot-apps bank build --from-annotations "$READERS/kitti_object_vod" --all --min-points 100 --mirror --out bank
  # the nuScenes demo keyframe comes in mmdetection3d's info layout: written as a one-sample dataroot first
  python "$HERE/scripts/nuscenes_demo_dataroot.py" "$READERS/nuscenes_demo" nuscenes_demo
  sot-apps bank build --from-annotations nuscenes_demo --all --min-points 40 --mirror --out bank
  touch bank/.done
fi
if [ ! -f bank_long/.done ]; then
  step "bank_long: the choosing part's long vehicles"
  rm -rf bank_long
  sot-apps bank build --from-annotations "$PANDASET" --track-id 49914840 --track-id bdc0f646 \
    --track-id 9c698ef3 --track-id 7ed5e06e --min-points 100 --mirror --out bank_long
  sot-apps bank build --from-annotations \
    "$READERS/av2_sensor_test/sensor/val/adcf7d18-0510-35b0-a2fa-b4cea13a6d76" \
    --track-id c48dca5e --min-points 20 --mirror --out bank_long
  touch bank_long/.done
fi

# ---------------------------------------------------------------- synthetic roads and worlds
[ -d synth_road ] || sot-apps synth --out synth_road --frames 40 --vehicles 0 --seed 0 --sensor pandaset_pandar64 --open-road
for s in 1 2 3; do
  [ -d W$s ] || sot-apps synth --out W$s --frames 60 --vehicles 8 --seed $s
done

bench_set() {  # NAME ARGS...: one set, resumable
  local name=$1; shift
  step "$name"
  sot-apps benchmark make --workers "$WORKERS" --quiet --out "$name" "$@"
}
ALL11="constant_speed hard_brake strong_accel stop_and_go lane_change turn u_turn occluded far_approach hidden oblique"
TEN="constant_speed hard_brake strong_accel stop_and_go lane_change turn u_turn occluded hidden oblique"
HARD="far_approach passing hidden oblique"

# ---------------------------------------------------------------- choosing sets
if [ "$PART" != confirm ]; then
  bench_set classic_choose_s0 --background synth_road --bank bank --tracklets 8 --frames 0:40 --seed 0 --split choose
  for s in 0 1 2; do
    bench_set synth_choose_s$s --background synth_road --bank bank --tracklets 8 --frames 0:40 --seed $s --profiles $HARD --split choose
  done
  bench_set pandaset_choose_s1 --background "$PANDASET" --bank bank --tracklets 11 --frames 0:40 --seed 1 --split choose --profiles $ALL11
  bench_set sparse_choose_s21 --background "$PANDASET" --bank bank --tracklets 12 --frames 0:40 --seed 21 --split choose \
    --profiles turn strong_accel hard_brake --range 28:60 --bands 40
  for s in 30 31 32; do
    bench_set hidden_choose_s$s --background synth_road --bank bank --tracklets 10 --frames 0:40 --seed $s --split choose --profiles hidden
  done
  for s in 33 34 35; do
    bench_set street_hidden_choose_s$s --background "$PANDASET" --bank bank --tracklets 12 --frames 0:40 --seed $s --split choose --profiles hidden
  done
  bench_set accel_choose_s31 --background "$PANDASET" --bank bank --tracklets 16 --frames 0:40 --seed 31 --split choose \
    --profiles strong_accel u_turn --range 5:60 --bands 17 28 40
  bench_set long_choose_s41 --background "$PANDASET" --bank bank_long --tracklets 12 --frames 0:40 --seed 41 --split choose \
    --profiles strong_accel u_turn constant_speed
  bench_set long_choose_s42 --background "$PANDASET" --bank bank_long --tracklets 12 --frames 0:40 --seed 42 --split choose \
    --profiles strong_accel u_turn constant_speed --range 5:60 --bands 17 28 40
  for s in 2 3; do
    bench_set street_choose_s$s --background "$PANDASET" --bank bank --tracklets 30 --frames 0:40 --seed $s --split choose --profiles $TEN
  done
fi

# ---------------------------------------------------------------- confirming sets (report only: never choose on them)
if [ "$PART" != choose ]; then
  for s in 0 1 2; do
    bench_set confirm_s$s --background "$PANDASET" --bank bank --tracklets 30 --frames 0:40 --seed $s --split confirm --profiles $TEN
  done
  bench_set pandaset_confirm_s0 --background "$PANDASET" --bank bank --tracklets 11 --frames 0:40 --seed 0 --split confirm --profiles $ALL11
  for s in 0 1 2; do
    bench_set synth_confirm_s$s --background synth_road --bank bank --tracklets 8 --frames 0:40 --seed $s --profiles $HARD --split confirm
  done
  [ -d road60 ] || sot-apps synth --out road60 --frames 60 --vehicles 0 --seed 0 --sensor pandaset_pandar64 --open-road
  bench_set far60_confirm_s1 --background road60 --bank bank --tracklets 12 --frames 0:60 --seed 1 --split confirm --profiles far_approach
fi
step "done: $OUT"
