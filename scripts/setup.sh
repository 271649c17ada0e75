#!/usr/bin/env bash
# One-time setup on a fresh machine: everything the build, the tests and the demo need that
# cargo does not fetch by itself. Idempotent; safe to re-run.
set -euo pipefail
cd "$(dirname "$0")/.."

# Fetch all crates up front so a network hiccup fails here, not half-way through the tests.
cargo fetch --locked
