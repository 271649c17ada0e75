#!/usr/bin/env bash
# The README's run command: the fleet demo. Builds the release binaries, then runs
# `planner-service demo`: the planner service (HTTP API + dashboard, embedded store with the
# shipped floor plans preloaded), the simulator with N robots (default 3) and one robot agent
# per robot, as separate processes over Zenoh on loopback; the robots drive with LPE-Net
# (models/lpe.onnx on ONNX Runtime, which scripts/setup.sh installs). It prints the dashboard URL
# and the token and runs until Ctrl-C. Arguments go to `planner-service demo` (e.g. --robots 5,
# --listen 0.0.0.0:8080, --controllers dynamic-window,path-tracker). It runs from the repository
# root, where the demo finds sim/scenarios, ../shared and models/ by itself (elsewhere:
# FLEET_SCENARIOS_DIR, FLEET_SHARED_DIR, FLEET_MODELS_DIR; README, "Command-line tools").
set -euo pipefail
cd "$(dirname "$0")/.."
cargo build --release --locked -p planner-service -p sim -p robot-agent
exec target/release/planner-service demo "$@"
