#!/usr/bin/env bash
# One-time setup on a fresh machine: everything the build, the tests and the demo need that
# cargo does not fetch by itself. Idempotent; safe to re-run.
set -euo pipefail
cd "$(dirname "$0")/.."

# Fetch all crates up front so a network hiccup fails here, not half-way through the tests.
cargo fetch --locked

# ONNX Runtime for the robot agent's intention-net controllers. `ort` is built with
# `load-dynamic`, so the shared library is opened at run time; it comes from the PyPI wheel
# (the same version Python uses to compute the fixtures' expected outputs). ort 2.0.0-rc.15
# speaks the ONNX Runtime 1.31 API. The agent looks for
# .venv/lib/python3*/site-packages/onnxruntime/capi/libonnxruntime.so* unless ORT_DYLIB_PATH
# is set.
ORT_VERSION="1.31.1"
PYTHON="${PYTHON:-python3}"
if [ ! -x .venv/bin/python ]; then
  "$PYTHON" -m venv .venv
fi
installed="$(.venv/bin/python -c 'import importlib.metadata as m; print(m.version("onnxruntime"))' 2>/dev/null || true)"
if [ "$installed" != "$ORT_VERSION" ]; then
  .venv/bin/python -m pip install --quiet --disable-pip-version-check "onnxruntime==${ORT_VERSION}"
fi
# schemathesis, for scripts/api-fuzz.sh (the OpenAPI document against what the server accepts).
SCHEMATHESIS_VERSION="4.32.5"
installed="$(.venv/bin/python -c 'import importlib.metadata as m; print(m.version("schemathesis"))' 2>/dev/null || true)"
if [ "$installed" != "$SCHEMATHESIS_VERSION" ]; then
  .venv/bin/python -m pip install --quiet --disable-pip-version-check "schemathesis==${SCHEMATHESIS_VERSION}"
fi
# Nav2's particle filter (PyPI `amcl`, GPL, used only by the comparison script) and an MCAP
# reader, for scripts/amcl_compare.py (our AMCL beside Nav2's on the same run logs).
AMCL_VERSION="0.1.2"
MCAP_VERSION="1.6.0"
installed="$(.venv/bin/python -c 'import importlib.metadata as m; print(m.version("amcl"), m.version("mcap"))' 2>/dev/null || true)"
if [ "$installed" != "$AMCL_VERSION $MCAP_VERSION" ]; then
  .venv/bin/python -m pip install --quiet --disable-pip-version-check "amcl==${AMCL_VERSION}" "mcap==${MCAP_VERSION}" zstandard
fi
if ! compgen -G ".venv/lib/python3*/site-packages/onnxruntime/capi/libonnxruntime.so*" >/dev/null; then
  echo "error: onnxruntime ${ORT_VERSION} installed, but no libonnxruntime.so* under .venv/lib/python3*/site-packages/onnxruntime/capi/" >&2
  exit 1
fi

# Headless Chromium for the dashboard's browser tests (Debian packages; Playwright never
# downloads a browser here) and the tests' npm packages (playwright-core, pinned in
# web/package-lock.json).
if ! command -v chromium >/dev/null 2>&1; then
  if [ "$(id -u)" = 0 ] && command -v apt-get >/dev/null 2>&1; then
    apt-get update -qq && DEBIAN_FRONTEND=noninteractive apt-get install -y -qq chromium chromium-driver >/dev/null
  else
    echo "warning: chromium missing; install the Debian packages chromium and chromium-driver for the browser tests" >&2
  fi
fi
(cd web && npm ci --no-audit --no-fund --prefer-offline >/dev/null)

