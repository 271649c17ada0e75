#!/usr/bin/env bash
# Coverage-guided fuzzing (libFuzzer via cargo-fuzz) of the inputs strangers control: floor-plan
# images and ROS map uploads, the Zenoh wire codec, scenario files (fuzz/, docs/security.md
# item 6). Runs each target for SECONDS (default 60) from seeds made of the shipped files plus
# the committed regression inputs (fuzz/regressions/<target>: every crash found, fixed), and
# fails on the first crash, leaving the input in fuzz/artifacts/<target>/.
#
#   bash scripts/fuzz.sh [SECONDS] [TARGET...]     # targets: map_image map_import wire_decode scenario
set -euo pipefail
cd "$(dirname "$0")/.."
secs=${1:-60}
shift || true
targets=("$@")
if [ ${#targets[@]} -eq 0 ]; then
  targets=(map_image map_import wire_decode scenario)
fi
if ! command -v cargo-fuzz > /dev/null; then
  cargo install cargo-fuzz --locked --version 0.13.2
fi
# cargo-fuzz passes unstable compiler flags; the stable toolchain accepts them with this.
export RUSTC_BOOTSTRAP=1
corpus=out/fuzz/corpus
python3 scripts/fuzz_seeds.py "$corpus"
for t in "${targets[@]}"; do
  mkdir -p "fuzz/regressions/$t"
  echo "== fuzzing $t for ${secs} s"
  # No sanitizer: the workspace has no unsafe code; coverage and the targets' own checks find
  # panics, hangs (-timeout) and memory blow-ups (-rss_limit_mb).
  cargo fuzz run --sanitizer none "$t" "$corpus/$t" "fuzz/regressions/$t" -- \
    -max_total_time="$secs" -timeout=10 -rss_limit_mb=2048 -print_final_stats=1
done
