#!/usr/bin/env bash
# A walk-through of the pieces one by one, leaving pictures to look at: floor plans into the
# versioned store and back out, a hybrid A* plan with its LPE intention, and the simulator's
# world and camera. Output goes to ./out/walkthrough (or $1). The fleet itself: scripts/demo.sh.
set -euo pipefail
cd "$(dirname "$0")/.."
out=${1:-out/walkthrough}
maps=${FLEET_SHARED_DIR:-../shared}/maps/nav2
mkdir -p "$out"

cargo build --release --locked -p map-store -p planner-service -p sim
bin=target/release

echo "== 1. import the Nav2 floor plans into a fresh store ($out/store)"
rm -rf "$out/store"
for yaml in "$maps"/*.yaml; do
  "$bin/map-store" --data-dir "$out/store" import "$yaml"
done
"$bin/map-store" --data-dir "$out/store" list
"$bin/map-store" --data-dir "$out/store" export depot "$out/depot_export.yaml"

echo "== 2. plan across the depot with hybrid A* (path picture + LPE intention image)"
"$bin/planner-service" plan --map "$maps/depot.yaml" --start 2,2,0 --goal 25,12,1.57 \
  --picture "$out/depot_path.png" --lpe "$out/depot_lpe.png" | head -6

echo "== 3. the simulator: task E (a maze) from above, and what the camera sees in task B"
"$bin/sim" view --scenario sim/scenarios/task_e.yaml --out "$out/task_e_world.png"
"$bin/sim" render --scenario sim/scenarios/task_b.yaml --pose 2.5,10,0 \
  --out "$out/task_b_camera.png" --scan-out "$out/task_b_scan.json"

echo
echo "pictures in $out: depot_path.png depot_lpe.png task_e_world.png task_b_camera.png"
