#!/usr/bin/env bash
# Headless-Chromium tests of the web dashboard against the real fleet demo: builds the binaries,
# starts `planner-service demo` (service + simulator + robot agents as separate processes) on a
# free port with a fresh data dir and a known token, waits for /healthz, runs web/tests with
# node:test and playwright-core on the system Chromium (no browser download), and always stops
# the demo's whole process group. Screenshots: out/browser/*.png. Exit status: the tests'.
#
# Environment: CHROMIUM (default /usr/bin/chromium), FLEET_BIN_DIR (use these binaries instead of
# building), FLEET_PROFILE (cargo profile to build, default release: the robots must drive in
# real time), FLEET_ROBOTS (default 2), FLEET_TASK_TIMEOUT_MS (default 300000).
set -euo pipefail
cd "$(dirname "$0")/.."
root=$PWD

chromium=${CHROMIUM:-/usr/bin/chromium}
if [ ! -x "$chromium" ]; then
  echo "error: no Chromium at $chromium (apt-get install -y chromium chromium-driver, or set CHROMIUM)" >&2
  exit 1
fi
export CHROMIUM=$chromium

echo "== npm ci (web/)"
(cd web && npm ci --no-audit --no-fund --prefer-offline)

profile=${FLEET_PROFILE:-release}
if [ -n "${FLEET_BIN_DIR:-}" ]; then
  bin=$FLEET_BIN_DIR
else
  echo "== cargo build --profile $profile (planner-service, sim, robot-agent)"
  cargo build --locked --profile "$profile" -p planner-service -p sim -p robot-agent
  target=${CARGO_TARGET_DIR:-$root/target}
  case $profile in
    dev) bin=$target/debug ;;
    *) bin=$target/$profile ;;
  esac
fi
if [ ! -x "$bin/planner-service" ]; then
  echo "error: no planner-service binary in $bin" >&2
  exit 1
fi

port=$(python3 -c 'import socket; s = socket.socket(); s.bind(("127.0.0.1", 0)); print(s.getsockname()[1])')
data_dir=$(mktemp -d "${TMPDIR:-/tmp}/fleet-browser-test.XXXXXX")
token=$(od -An -N16 -tx1 /dev/urandom | tr -d ' \n')
log=$root/out/browser/demo.log
mkdir -p "$root/out/browser"
rm -f "$root"/out/browser/*.png

demo_pid=
cleanup() {
  local rc=$?
  if [ -n "$demo_pid" ]; then
    # The demo leads its own process group (setsid): stop it and every child it started.
    kill -TERM -- "-$demo_pid" 2>/dev/null || true
    for _ in $(seq 1 50); do
      kill -0 -- "-$demo_pid" 2>/dev/null || break
      sleep 0.1
    done
    kill -KILL -- "-$demo_pid" 2>/dev/null || true
  fi
  rm -rf "$data_dir"
  exit "$rc"
}
trap cleanup EXIT
trap 'exit 130' INT TERM

echo "== starting the demo on 127.0.0.1:$port (log: $log)"
PATH="$bin:$PATH" setsid "$bin/planner-service" demo --robots "${FLEET_ROBOTS:-2}" \
  --listen "127.0.0.1:$port" --data-dir "$data_dir" --token "$token" >"$log" 2>&1 &
demo_pid=$!

url="http://127.0.0.1:$port"
for i in $(seq 1 240); do
  if curl -fsS "$url/healthz" >/dev/null 2>&1; then
    break
  fi
  if ! kill -0 "$demo_pid" 2>/dev/null; then
    echo "error: the demo exited before /healthz answered; its log:" >&2
    tail -n 40 "$log" >&2
    exit 1
  fi
  if [ "$i" -eq 240 ]; then
    echo "error: /healthz did not answer within 120 s; the demo's log:" >&2
    tail -n 40 "$log" >&2
    exit 1
  fi
  sleep 0.5
done
echo "== $(curl -fsS "$url/healthz")"

echo "== browser tests"
status=0
(cd web && FLEET_URL="$url" FLEET_TOKEN="$token" node --test --test-concurrency=1 tests/dashboard.test.js) || status=$?
if [ "$status" -ne 0 ]; then
  echo "browser tests failed (exit $status); the demo's last log lines:" >&2
  tail -n 40 "$log" >&2
fi
echo "screenshots: $(ls "$root"/out/browser/*.png 2>/dev/null | tr '\n' ' ')"
exit "$status"
