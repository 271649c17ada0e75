#!/usr/bin/env bash
# One learning round on a machine with many cores and a GPU, inside a fixed wall budget:
# record (a DAgger recording with the current LPE-Net driving and an expert recording, both with
# the §4.2 encounters, in parallel on all cores) and then train LPE-Net (small and small-spatial
# backbones) and DLM-Net (small-spatial) on both recordings at once on the one GPU, export each
# with its card. Everything it made goes into one tar per model under $ROUND_OUT, plus logs.tar.
#
# Run from the repository root with a built eval binary and an ONNX Runtime library:
#   EVAL=target/release/eval ORT_DYLIB_PATH=/path/libonnxruntime.so.X \
#     ROUND_OUT=/tmp/round bash training/gpu_round.sh
# Knobs (environment): RECORD_MIN (3.5), TRAIN_MIN (3.5), IMAGE_PX (128), JOBS (cores / 2 per
# recording), POLICY (models/lpe.onnx), GEN (200 generated buildings per recording), SEED (61),
# DATA (data/round), PY (python3), TRAIN_WORKERS (cores / 3 - 1 per run), MODELS
# ("lpe:small lpe:small-spatial dlm:small-spatial"), INIT_DIR (warm start: <INIT_DIR>/<kind>-<backbone>/
# checkpoint_best.pt where it exists, e.g. the previous round's), LR (1e-3), GEN_FIRST (1000 and
# GEN_FIRST + 2000 for the expert recording: keep rounds on different buildings).
# The small CPU check runs it with tiny budgets (see training/README.md).
set -euo pipefail

EVAL=${EVAL:-target/release/eval}
PY=${PY:-python3}
ROUND_OUT=${ROUND_OUT:?set ROUND_OUT to the folder for the results}
RECORD_MIN=${RECORD_MIN:-3.5}
TRAIN_MIN=${TRAIN_MIN:-3.5}
IMAGE_PX=${IMAGE_PX:-128}
POLICY=${POLICY:-models/lpe.onnx}
GEN=${GEN:-200}
GEN_FIRST=${GEN_FIRST:-1000}
LR=${LR:-1e-3}
INIT_DIR=${INIT_DIR:-}
SEED=${SEED:-61}
DATA=${DATA:-data/round}
MODELS=${MODELS:-lpe:small lpe:small-spatial dlm:small-spatial}
CORES=$(nproc)
JOBS=${JOBS:-$(( CORES / 2 > 0 ? CORES / 2 : 1 ))}
n_models=$(wc -w <<<"$MODELS")
TRAIN_WORKERS=${TRAIN_WORKERS:-$(( CORES / n_models - 1 > 0 ? CORES / n_models - 1 : 0 ))}

if [ -z "${ORT_DYLIB_PATH:-}" ]; then
    # The ONNX Runtime library of the Python package (GPU images carry one).
    ORT_DYLIB_PATH=$($PY -c 'import glob, os, onnxruntime; print(sorted(glob.glob(os.path.join(os.path.dirname(onnxruntime.__file__), "capi", "libonnxruntime.so*")))[0])')
    export ORT_DYLIB_PATH
fi
LOGS="$DATA/logs"
mkdir -p "$ROUND_OUT" "$DATA" "$LOGS"
log() { echo "[$(date +%T)] $*"; }

log "machine: $CORES cores; $($PY -c 'import torch; print("torch", torch.__version__, "cuda", torch.cuda.is_available(), torch.cuda.get_device_name(0) if torch.cuda.is_available() else "")')"
log "ONNX Runtime: $ORT_DYLIB_PATH"
test -f "$POLICY"
# Fail in seconds, not after the recording: the learner loads and drives a few cycles.
"$EVAL" record --policy "$POLICY" --generated 1 --generated-first-seed 999 --episode-s 5 --samples 20 \
    --image-px "$IMAGE_PX" --jobs 1 --out "$DATA/check" > "$LOGS/record-check.log" 2>&1 \
    || { cat "$LOGS/record-check.log"; exit 1; }
rm -rf "$DATA/check"

# 1. Recordings, in parallel, each on half the cores, stopped by the wall budget at an episode
#    boundary (then exactly the recording of --samples K). Seeds and building ranges differ.
log "recording for $RECORD_MIN min: DAgger ($POLICY, beta 0.5) and expert, $IMAGE_PX px, $JOBS jobs each"
"$EVAL" record --policy "$POLICY" --beta 0.5 --generated "$GEN" --generated-first-seed "$GEN_FIRST" \
    --encounters 1.0 --episode-s 30 --every 2 --noise 0.1 --image-px "$IMAGE_PX" \
    --seed "$SEED" --jobs "$JOBS" --samples 2000000 --max-minutes "$RECORD_MIN" \
    --out "$DATA/dagger" > "$LOGS/record-dagger.log" 2>&1 &
dagger=$!
"$EVAL" record --generated "$GEN" --generated-first-seed "$((GEN_FIRST + 2000))" \
    --encounters 0.5 --episode-s 60 --every 2 --noise 0.3 --image-px "$IMAGE_PX" \
    --seed "$((SEED + 1))" --jobs "$JOBS" --samples 2000000 --max-minutes "$RECORD_MIN" \
    --out "$DATA/expert" > "$LOGS/record-expert.log" 2>&1 &
expert=$!
wait "$dagger" || { tail -20 "$LOGS/record-dagger.log"; exit 1; }
wait "$expert" || { tail -20 "$LOGS/record-expert.log"; exit 1; }
tail -n 2 "$LOGS/record-dagger.log" "$LOGS/record-expert.log" | grep -v '^$'
$PY training/dataset.py "$DATA/dagger" | tail -n 12
$PY training/dataset.py "$DATA/expert" | tail -n 12

# 2. Training, all models at once on the one GPU, the cores shared among their data workers.
log "training $MODELS for $TRAIN_MIN min each, $TRAIN_WORKERS data workers each"
pids=()
for m in $MODELS; do
    kind=${m%%:*}; backbone=${m#*:}
    speed=(); [ "$kind" = lpe ] && speed=(--balance-speed)
    init=(); [ -n "$INIT_DIR" ] && [ -f "$INIT_DIR/$kind-$backbone/checkpoint_best.pt" ] \
        && init=(--init "$INIT_DIR/$kind-$backbone/checkpoint_best.pt")
    $PY -m training.train --kind "$kind" --backbone "$backbone" --data "$DATA/dagger" "$DATA/expert" \
        --out "$DATA/train/$kind-$backbone" --minutes "$TRAIN_MIN" --batch 256 --lr "$LR" "${speed[@]}" "${init[@]}" \
        --workers "$TRAIN_WORKERS" --threads 2 --seed 7 > "$LOGS/train-$kind-$backbone.log" 2>&1 &
    pids+=($!)
done
status=0
for p in "${pids[@]}"; do wait "$p" || status=1; done

# 3. One tar per model (checkpoint, ONNX, card, curves, summary) and the logs.
for m in $MODELS; do
    kind=${m%%:*}; backbone=${m#*:}; dir="$DATA/train/$kind-$backbone"
    grep -E '^epoch|^summary|Error|error' "$LOGS/train-$kind-$backbone.log" | head -n 40 || true
    [ -d "$dir" ] && tar -C "$dir" -cf "$ROUND_OUT/$kind-$backbone.tar" \
        $(cd "$dir" && ls checkpoint_best.pt ./*.onnx card.json history.json summary.json loss.png 2>/dev/null)
done
tar -C "$LOGS" -cf "$ROUND_OUT/logs.tar" .
ls -la "$ROUND_OUT"
log "done (status $status)"
exit "$status"
