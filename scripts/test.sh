#!/usr/bin/env bash
# The test command of the README: the whole workspace, unit and integration tests.
set -euo pipefail
cd "$(dirname "$0")/.."
cargo test --workspace --locked "$@"
