#!/usr/bin/env bash
# Property-based API testing with schemathesis against the OpenAPI document the service itself
# serves (issue 17 item 5: the document must match what the server accepts). Starts a real
# `planner-service serve` on a free loopback port with a fresh data dir and a known token, uploads
# the Nav2 `depot` map (so generated tasks and map reads can meet a real map), runs schemathesis
# with every check (schemathesis 4 runs them all by default; scripts/schemathesis.toml lists the
# few exceptions, which a `--checks` flag would override), and exits with its status: any
# failure fails the run.
#
# Usage: scripts/api-fuzz.sh [MAX_EXAMPLES] (default 40 generated cases per operation)
# Environment: FLEET_BIN_DIR (default target/debug), FLEET_SHARED_DIR, SCHEMATHESIS
# (default .venv/bin/schemathesis; scripts/setup.sh installs it), API_FUZZ_SEED (default 17),
# API_FUZZ_MAX_TIME_S (default 240: the whole run's time budget).
# Reports: out/api-fuzz/ (junit.xml, and a reproducing pytest file for each failure).
set -euo pipefail
cd "$(dirname "$0")/.."
root=$PWD
max_examples=${1:-40}
seed=${API_FUZZ_SEED:-17}
max_time_s=${API_FUZZ_MAX_TIME_S:-240}
bin=${FLEET_BIN_DIR:-${CARGO_TARGET_DIR:-$root/target}/debug}
schemathesis=${SCHEMATHESIS:-$root/.venv/bin/schemathesis}
maps=${FLEET_SHARED_DIR:-$root/../shared}/maps/nav2

if [ ! -x "$bin/planner-service" ]; then
  echo "error: no planner-service binary in $bin (cargo build -p planner-service, or set FLEET_BIN_DIR)" >&2
  exit 1
fi
if [ ! -x "$schemathesis" ]; then
  echo "error: no schemathesis at $schemathesis (bash scripts/setup.sh installs it into .venv)" >&2
  exit 1
fi

port=$(python3 -c 'import socket; s = socket.socket(); s.bind(("127.0.0.1", 0)); print(s.getsockname()[1])')
data_dir=$(mktemp -d "${TMPDIR:-/tmp}/fleet-api-fuzz.XXXXXX")
export FLEET_TOKEN=api-fuzz-token-0123456789abcdef
report=$root/out/api-fuzz
rm -rf "$report"
mkdir -p "$report"

"$bin/planner-service" serve --listen "127.0.0.1:$port" --data-dir "$data_dir" \
  --zenoh-listen tcp/127.0.0.1:0 >"$report/serve.log" 2>&1 &
pid=$!
cleanup() {
  kill -TERM "$pid" 2>/dev/null || true
  wait "$pid" 2>/dev/null || true
  rm -rf "$data_dir"
}
trap cleanup EXIT

base=http://127.0.0.1:$port
for _ in $(seq 200); do
  curl -sf "$base/healthz" >/dev/null && break
  sleep 0.1
done
curl -sf "$base/healthz" >/dev/null || { echo "error: the service did not come up; see $report/serve.log" >&2; exit 1; }
curl -sf -H "Authorization: Bearer $FLEET_TOKEN" -F name=depot \
  -F "yaml=@$maps/depot.yaml" -F "image=@$maps/depot.pgm" "$base/api/v1/maps" >/dev/null

# The live event stream never ends by design (server-sent events), so a generated request to it
# would only time out; the dashboard's browser tests and the SSE tests cover it.
set +e
"$schemathesis" --config-file "$root/scripts/schemathesis.toml" run "$base/api/v1/openapi.json" \
  --exclude-path /api/v1/events \
  --header "Authorization: Bearer $FLEET_TOKEN" \
  --max-examples "$max_examples" \
  --seed "$seed" \
  --max-time "$max_time_s" \
  --request-timeout 10 \
  --generation-database none \
  --workers 2 \
  --no-color \
  --report junit,pytest --report-dir "$report"
status=$?
set -e
if [ "$status" -ne 0 ]; then
  echo "schemathesis found failures (exit $status); reports in $report, service log in $report/serve.log" >&2
fi
exit "$status"
