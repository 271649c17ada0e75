#!/usr/bin/env bash
# The training path's smoke tests, on the CPU (training/README.md): a tiny recording in the
# format `eval record` writes -> `python -m training.train` for each kind -> ONNX export with its
# card -> checked against ONNX Runtime; the layer-activation figure of the shipped models; and
# the weight average of exported models (training/average.py) on the fixtures; the card of a
# DLM-Net driven on other DLM parameters than it was trained on (export --drive-dlm-params); a
# newer closed-loop record put into a shipped card (training/recard.py).
# Installs PyTorch and the training dependencies into .venv first (scripts/setup.sh made it;
# about 4.6 GB, most of it the CUDA libraries PyPI's wheel carries). Not part of the README's
# test command: CI runs it after the Rust tests.
#
#   bash scripts/training-smoke.sh [SECONDS_PER_KIND]     # default 10
set -euo pipefail
cd "$(dirname "$0")/.."
secs=${1:-10}
PY=.venv/bin/python
if [ ! -x "$PY" ]; then
  echo "error: $PY missing: run scripts/setup.sh first" >&2
  exit 1
fi
# The versions these tests last passed with (training/requirements-smoke.txt, every dependency
# pinned; training/pyproject.toml gives the ranges).
if ! "$PY" -c 'import torch, onnx, matplotlib, tqdm, PIL' 2>/dev/null; then
  # No pip cache, and the large wheels one at a time (--no-deps, since the file lists every
  # dependency): the disk then holds what is installed plus one wheel, not all 3 GB of wheels
  # beside the 4.6 GB they install.
  pip_install=("$PY" -m pip install --quiet --disable-pip-version-check --no-cache-dir --no-deps)
  small=() large=()
  while read -r req; do
    case "$req" in
      '' | '#'*) ;;
      nvidia-* | cuda-bindings* | torch==*) large+=("$req") ;;
      *) small+=("$req") ;;
    esac
  done < training/requirements-smoke.txt
  "${pip_install[@]}" "${small[@]}"
  for req in "${large[@]}"; do
    "${pip_install[@]}" "$req"
  done
fi
"$PY" training/tests/test_smoke.py --seconds "$secs"
"$PY" training/tests/test_activations.py
"$PY" training/tests/test_dataset.py
"$PY" training/tests/test_average.py
"$PY" training/tests/test_init_camera.py
"$PY" training/tests/test_export_drive.py
"$PY" training/tests/test_recard.py
"$PY" training/tests/test_setoff_plot.py
"$PY" training/tests/test_leg_plot.py
