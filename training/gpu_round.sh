#!/usr/bin/env bash
# Learning rounds on a machine with many cores and a GPU, inside a fixed wall budget. Each round:
# record (a DAgger recording with the current LPE-Net driving and an expert recording, both with
# the §4.2 encounters, in parallel on all cores), then train every model of MODELS at once on the
# one GPU on all the rounds' recordings so far (aggregated, as DAgger prescribes), warm-started
# from the previous round's checkpoint, and export each with its card. The next round's DAgger
# recording is driven by this round's DRIVER model. Each round's models go into one tar per model
# under $ROUND_OUT (r<round>-<kind>-<backbone>.tar) as the round ends, plus logs.tar (every
# round's logs and summaries).
#
# Run from the repository root with a built eval binary and an ONNX Runtime library:
#   EVAL=target/release/eval ORT_DYLIB_PATH=/path/libonnxruntime.so.X \
#     ROUND_OUT=/tmp/round bash training/gpu_round.sh
# Knobs (environment): ROUNDS (1), RECORD_MIN (3.5, per round), TRAIN_MIN (3.5, per round),
# IMAGE_PX (128), JOBS (cores / 2 per recording), POLICY (models/lpe.onnx: the first round's
# driver), DRIVER (the model of MODELS that drives later rounds: the first lpe one), GEN (200
# generated buildings per recording), SEED (61), DATA (data/round), PY (python3), TRAIN_WORKERS
# (cores / models - 1 per run), MODELS ("lpe:small lpe:small-spatial dlm:small-spatial"),
# INIT_DIR (warm start of the first round: <INIT_DIR>/<kind>-<backbone>/checkpoint_best.pt where
# it exists), LR (1e-3; later rounds, warm-started, use LR_LATER, 3e-4), GEN_FIRST (1000: round
# r records on buildings GEN_FIRST + (r-1) GEN.., the expert 2000 higher: never the same twice),
# ENCOUNTER_KINDS (the scripted encounters' kinds, comma-separated, e.g. furniture,glass_door;
# default the six of `eval record`; person_head_on only when named), KEEP_EPOCHS (1: every epoch's checkpoint comes back too, in
# r<round>-<kind>-<backbone>-epochs<k>.tar of at most 15 MB each, at most EPOCH_MB (45) MB in
# all, thinned evenly, the last epoch always kept: candidates to judge in closed loop).
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
ENCOUNTER_KINDS=${ENCOUNTER_KINDS:-}
kinds=(); [ -n "$ENCOUNTER_KINDS" ] && kinds=(--encounter-kinds "$ENCOUNTER_KINDS")
ROUNDS=${ROUNDS:-1}
KEEP_EPOCHS=${KEEP_EPOCHS:-0}
EPOCH_MB=${EPOCH_MB:-45}
LR_LATER=${LR_LATER:-3e-4}
DRIVER=${DRIVER:-$(tr ' ' '\n' <<<"$MODELS" | grep '^lpe:' | head -n 1 || true)}
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

# One tar per model and round: checkpoint, ONNX, card, curves, summary.
pack() {
    local dir=$1 tarball=$2
    [ -d "$dir" ] && tar -C "$dir" -cf "$tarball" \
        $(cd "$dir" && ls checkpoint_best.pt ./*.onnx card.json history.json summary.json loss.png 2>/dev/null)
    return 0
}

# Every epoch's checkpoint, in tars of at most 15 MB (the device tool returns files of up to
# 16 MB), at most EPOCH_MB MB in all: where more were written, an even selection, the last kept.
pack_epochs() {
    local dir=$1 stem=$2 files=() size_mb keep step i k=0 batch=() batch_mb=0
    mapfile -t files < <(cd "$dir" && ls checkpoint_e*.pt 2>/dev/null)
    [ "${#files[@]}" -gt 0 ] || return 0
    size_mb=$(( ($(stat -c %s "$dir/${files[0]}") + 1048575) / 1048576 ))
    keep=$(( EPOCH_MB / size_mb )); [ "$keep" -ge 1 ] || keep=1
    step=$(( (${#files[@]} + keep - 1) / keep ))
    local chosen=()
    for ((i = ${#files[@]} - 1; i >= 0; i -= step)); do chosen=("${files[i]}" "${chosen[@]}"); done
    for f in "${chosen[@]}"; do
        if [ $(( batch_mb + size_mb )) -gt 15 ] && [ "${#batch[@]}" -gt 0 ]; then
            tar -C "$dir" -cf "$stem-epochs$k.tar" "${batch[@]}"; k=$((k + 1)); batch=(); batch_mb=0
        fi
        batch+=("$f"); batch_mb=$(( batch_mb + size_mb ))
    done
    [ "${#batch[@]}" -gt 0 ] && tar -C "$dir" -cf "$stem-epochs$k.tar" "${batch[@]}"
    return 0
}

# One round: recordings, in parallel, each on half the cores, stopped by the wall budget at an
# episode boundary (then exactly the recording of --samples K), then training on everything so far.
round() {
    local r=$1 policy=$2 lr=$3 init_dir=$4
    local dir="$DATA/r$r" gen_first=$((GEN_FIRST + (r - 1) * GEN)) seed=$((SEED + 10 * (r - 1)))
    mkdir -p "$dir"
    log "round $r: recording for $RECORD_MIN min: DAgger ($policy, beta 0.5) and expert, $IMAGE_PX px, $JOBS jobs each"
    "$EVAL" record --policy "$policy" --beta 0.5 --generated "$GEN" --generated-first-seed "$gen_first" \
        --encounters 1.0 "${kinds[@]}" --episode-s 30 --every 2 --noise 0.1 --image-px "$IMAGE_PX" \
        --seed "$seed" --jobs "$JOBS" --samples 2000000 --max-minutes "$RECORD_MIN" \
        --out "$dir/dagger" > "$LOGS/r$r-record-dagger.log" 2>&1 &
    local dagger=$!
    "$EVAL" record --generated "$GEN" --generated-first-seed "$((gen_first + 2000))" \
        --encounters 0.5 "${kinds[@]}" --episode-s 60 --every 2 --noise 0.3 --image-px "$IMAGE_PX" \
        --seed "$((seed + 1))" --jobs "$JOBS" --samples 2000000 --max-minutes "$RECORD_MIN" \
        --out "$dir/expert" > "$LOGS/r$r-record-expert.log" 2>&1 &
    local expert=$!
    wait "$dagger" || { tail -20 "$LOGS/r$r-record-dagger.log"; return 1; }
    wait "$expert" || { tail -20 "$LOGS/r$r-record-expert.log"; return 1; }
    tail -n 4 "$LOGS/r$r-record-dagger.log" "$LOGS/r$r-record-expert.log" | grep -v '^$'
    data+=("$dir/dagger" "$dir/expert")

    log "round $r: training $MODELS for $TRAIN_MIN min each on ${#data[@]} recordings, $TRAIN_WORKERS data workers each"
    local pids=() m kind backbone speed init keep=()
    [ "$KEEP_EPOCHS" = 1 ] && keep=(--keep-epochs)
    for m in $MODELS; do
        kind=${m%%:*}; backbone=${m#*:}
        speed=(); [ "$kind" = lpe ] && speed=(--balance-speed)
        init=(); [ -n "$init_dir" ] && [ -f "$init_dir/$kind-$backbone/checkpoint_best.pt" ] \
            && init=(--init "$init_dir/$kind-$backbone/checkpoint_best.pt")
        $PY -m training.train --kind "$kind" --backbone "$backbone" --data "${data[@]}" \
            --out "$dir/train/$kind-$backbone" --minutes "$TRAIN_MIN" --batch 256 --lr "$lr" "${speed[@]}" "${init[@]}" \
            --workers "$TRAIN_WORKERS" --threads 2 --seed "$((7 + r))" "${keep[@]}" > "$LOGS/r$r-train-$kind-$backbone.log" 2>&1 &
        pids+=($!)
    done
    local status=0 p
    for p in "${pids[@]}"; do wait "$p" || status=1; done
    for m in $MODELS; do
        kind=${m%%:*}; backbone=${m#*:}
        grep -E '^epoch|Error|error' "$LOGS/r$r-train-$kind-$backbone.log" | head -n 40 || true
        [ -f "$dir/train/$kind-$backbone/summary.json" ] \
            && cp "$dir/train/$kind-$backbone/summary.json" "$LOGS/r$r-summary-$kind-$backbone.json"
        # Each round's models leave at once, so that a call cut off by its time limit still
        # returns every finished round (the rounds are compared in closed loop afterwards).
        pack "$dir/train/$kind-$backbone" "$ROUND_OUT/r$r-$kind-$backbone.tar"
        [ "$KEEP_EPOCHS" = 1 ] && pack_epochs "$dir/train/$kind-$backbone" "$ROUND_OUT/r$r-$kind-$backbone"
    done
    tar -C "$LOGS" -cf "$ROUND_OUT/logs.tar" .
    return "$status"
}

data=()
policy=$POLICY; lr=$LR; init_dir=$INIT_DIR; status=0
for r in $(seq 1 "$ROUNDS"); do
    round "$r" "$policy" "$lr" "$init_dir" || { status=1; break; }
    policy="$DATA/r$r/train/${DRIVER%%:*}-${DRIVER#*:}/${DRIVER%%:*}.onnx"
    lr=$LR_LATER; init_dir="$DATA/r$r/train"
    last=$r
done

tar -C "$LOGS" -cf "$ROUND_OUT/logs.tar" .
ls -la "$ROUND_OUT"
log "done after ${last:-0} of $ROUNDS rounds (status $status)"
exit "$status"
