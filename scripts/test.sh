#!/usr/bin/env bash
# The test command of the README: the whole workspace (unit, integration and the multi-process
# end-to-end tests in tests/, which start the real binaries), then the dashboard's tests in
# headless Chromium against the real fleet demo.
set -euo pipefail
cd "$(dirname "$0")/.."
# The end-to-end tests run the binaries as separate processes: build them first. Building the
# tests builds every binary too (each has integration tests), with the features the tests
# resolve; a `cargo build` here resolved the test-only dependencies' features differently
# (criterion, jsonschema) and the tests then compiled zenoh and most of the tree a second time.
cargo test --workspace --locked --no-run
cargo test --workspace --locked "$@"
# Browser tests reuse the debug binaries just built: a per-package build would resolve other
# features again (no second build, no release build).
FLEET_BIN_DIR="${CARGO_TARGET_DIR:-$PWD/target}/debug" bash scripts/browser-test.sh
