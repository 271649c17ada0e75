#!/usr/bin/env bash
# Throughput of the HTTP API with wrk: GET /api/v1/robots and POST /api/v1/tasks against a
# real `planner-service serve` (temp data dir, the Nav2 depot map uploaded first).
# Usage: planner-service/benches/wrk/run.sh [path/to/planner-service] (default: target/release)
set -euo pipefail
here="$(cd "$(dirname "$0")" && pwd)"
root="$(cd "$here/../../.." && pwd)"
bin="${1:-${CARGO_TARGET_DIR:-$root/target}/release/planner-service}"
maps="${FLEET_SHARED_DIR:-$root/../shared}/maps/nav2"
port="${PORT:-18080}"
duration="${DURATION:-10s}"
threads="${THREADS:-2}"
conns="${CONNECTIONS:-32}"
# shellcheck source=serve.sh
. "$here/serve.sh"
echo "## GET /api/v1/robots"
wrk -t"$threads" -c"$conns" -d"$duration" --latency "http://127.0.0.1:$port/api/v1/robots"
echo "## POST /api/v1/tasks"
wrk -t"$threads" -c"$conns" -d"$duration" --latency -s "$here/post_task.lua" "http://127.0.0.1:$port/api/v1/tasks"
echo "tasks stored: $(curl -sf "http://127.0.0.1:$port/api/v1/tasks?limit=1000" | grep -o '"id":"t-' | wc -l) (list capped at 1000)"
