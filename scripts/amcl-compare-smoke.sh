#!/usr/bin/env bash
# Smoke run of the Nav2 comparison (docs/logs.md): records 20 simulated seconds of task A with
# the debug build, replays the log through our AMCL and Nav2's filter, and checks that both
# rows are there and that both filters localized (mean error under 0.3 m). The full comparison
# (tasks A–E, release build) is a documented command, not a CI step.
# FLEET_BIN_DIR: use the eval and robot-agent binaries there instead of building them (CI passes
# the ones the tests built: a per-package build resolves other dependency features and compiles
# much of the tree again).
set -euo pipefail
cd "$(dirname "$0")/.."
if [ -n "${FLEET_BIN_DIR:-}" ]; then
  bin=$FLEET_BIN_DIR
else
  cargo build --locked -p eval -p robot-agent
  bin="${CARGO_TARGET_DIR:-target}/debug"
fi
tmp="$(mktemp -d)"
trap 'rm -rf "$tmp"' EXIT
"$bin/eval" amcl-accuracy --tasks a --seed 1 --max-sim-s 20 --record-dir "$tmp/logs" >/dev/null
.venv/bin/python scripts/amcl_compare.py --agent "$bin/robot-agent" --out "$tmp/cmp" "$tmp"/logs/*.mcap
.venv/bin/python - "$tmp/cmp/compare.json" <<'PY'
import json, sys
rows = json.load(open(sys.argv[1]))
assert len(rows) == 1, rows
for name in ("ours", "nav2"):
    f = rows[0][name]
    assert f["cycles"] == 200 and f["updates"] > 100, (name, f)
    assert f["mean_position_error_m"] < 0.3, (name, f)
print("amcl compare smoke: ok")
PY
