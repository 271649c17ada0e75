#!/usr/bin/env bash
# The README's run command. Until the fleet demo (planner service + simulator + agents) lands,
# it walks through the pieces that exist: floor plans into the versioned store, listed and
# exported back to ROS format. Output goes to ./out/demo (or $1).
set -euo pipefail
cd "$(dirname "$0")/.."
out=${1:-out/demo}
maps=${FLEET_SHARED_DIR:-../shared}/maps/nav2
mkdir -p "$out"

cargo build --release --locked -p map-store
bin=target/release

echo "== import the Nav2 floor plans into a fresh store ($out/store)"
rm -rf "$out/store"
for yaml in "$maps"/*.yaml; do
  "$bin/map-store" --data-dir "$out/store" import "$yaml"
done

echo "== the store"
"$bin/map-store" --data-dir "$out/store" list

echo "== export depot back to ROS map_server format"
"$bin/map-store" --data-dir "$out/store" export depot "$out/depot_export.yaml"
echo "wrote $out/depot_export.yaml and its PGM"
