#!/usr/bin/env bash
# The test command of the README: the whole workspace (unit, integration and the multi-process
# end-to-end tests in tests/, which start the real binaries), then the dashboard's tests in
# headless Chromium against the real fleet demo.
set -euo pipefail
cd "$(dirname "$0")/.."
# The end-to-end tests run the binaries as separate processes: build them first.
cargo build --workspace --bins --locked
cargo test --workspace --locked "$@"
# Browser tests reuse the debug binaries just built (no second, release build).
FLEET_PROFILE=dev bash scripts/browser-test.sh
