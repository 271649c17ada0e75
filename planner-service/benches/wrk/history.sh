#!/usr/bin/env bash
# Issue 17 item 2 under load: what a listing costs once the store holds a long history.
# Fills a real `planner-service serve` (temp data dir, the Nav2 depot map) with STORED tasks
# (default 36 800, the issue's figure) through POST /api/v1/tasks, then runs wrk with 32
# connections on GET /api/v1/tasks?limit=1 and, at the same time, 4 connections on /healthz.
# Usage: planner-service/benches/wrk/history.sh [path/to/planner-service] (default target/release)
set -euo pipefail
here="$(cd "$(dirname "$0")" && pwd)"
root="$(cd "$here/../../.." && pwd)"
bin="${1:-${CARGO_TARGET_DIR:-$root/target}/release/planner-service}"
maps="${FLEET_SHARED_DIR:-$root/../shared}/maps/nav2"
port="${PORT:-18081}"
stored="${STORED:-36800}"
duration="${DURATION:-10s}"
# shellcheck source=serve.sh
. "$here/serve.sh"
auth=(-H "Authorization: Bearer $FLEET_TOKEN")
echo "## filling the store: $stored tasks through POST /api/v1/tasks"
count() { curl -sf "http://127.0.0.1:$port/metrics" | awk '/^fleet_tasks\{state="queued"\}/{print $2}'; }
start_s=$(date +%s)
# Each 5 s round prints the create rate beside the queued count it started from, so the rate on
# an empty store and on a full one come from the same run.
while [ "$(count)" -lt "$stored" ]; do
  before=$(count)
  rate=$(wrk -t2 -c32 -d5s -s "$here/post_task.lua" "http://127.0.0.1:$port/api/v1/tasks" | awk '/Requests\/sec/{print $2}')
  echo "queued $before: $rate creates/s"
done
echo "stored $(count) tasks in $(( $(date +%s) - start_s )) s"
echo "db size: $(du -h "$data"/*.redb 2>/dev/null | cut -f1 | tr '\n' ' ')"
echo "## GET /api/v1/tasks?limit=1 (32 connections) with GET /healthz (4 connections) at the same time"
wrk -t1 -c4 -d"$duration" --latency "http://127.0.0.1:$port/healthz" >"$data/healthz.txt" &
hz=$!
wrk -t2 -c32 -d"$duration" --latency "${auth[@]}" "http://127.0.0.1:$port/api/v1/tasks?limit=1"
wait $hz
echo "## GET /healthz meanwhile"
cat "$data/healthz.txt"
echo "## one page of 100 after a cursor, and the live-stream snapshot (sequential, 20 each)"
cursor=$(curl -sfD - -o /dev/null "${auth[@]}" "http://127.0.0.1:$port/api/v1/tasks?limit=100" | tr -d '\r' | awk -F': ' 'tolower($1)=="next-cursor"{print $2}')
for what in "api/v1/tasks?limit=100&cursor=$cursor" "api/v1/events"; do
  times=$(for _ in $(seq 20); do
    curl -s -o /dev/null -m 2 -w '%{time_starttransfer}\n' "${auth[@]}" "http://127.0.0.1:$port/$what" || true
  done | sort -n)
  echo "$what: time to first byte p50 $(echo "$times" | sed -n 10p) s, max $(echo "$times" | tail -1) s"
done
