#!/usr/bin/env bash
# Fuzzes every file reader (tests/fuzz/targets.hpp) with libFuzzer under ASan + UBSan for a fixed
# time each, as many at once as there are cores, starting from the corpora in tests/fuzz/corpus (copied: new inputs stay
# in build/fuzz/corpus). Fails on any finding; the crashing input is left in build/fuzz/findings.
#   tools/fuzz.sh [seconds per target, default 30] [target...]
set -euo pipefail
cd "$(dirname "$0")/.."
source tools/deps.sh
tjepa_ensure_packages "${TJEPA_BUILD_PACKAGES[@]}" clang libclang-rt-14-dev
seconds=${1:-30}
shift || true
targets=("$@")
[ ${#targets[@]} -gt 0 ] || targets=(safetensors checkpoint npy text_recording layout_csv edges_csv run_config reference_checkpoint trial_table)
cmake --preset fuzz >/dev/null
cmake --build --preset fuzz -j "$(nproc)"
bin=build/fuzz/tests/fuzz/tjepa_fuzz
mkdir -p build/fuzz/findings build/fuzz/logs
run() {
  local t=$1 corpus=build/fuzz/corpus/$1
  mkdir -p "$corpus"
  if TJEPA_FUZZ_TARGET=$t "$bin" -max_total_time="$seconds" -rss_limit_mb=4096 -print_final_stats=1 \
      -artifact_prefix="build/fuzz/findings/$t-" "$corpus" "tests/fuzz/corpus/$t" >"build/fuzz/logs/$t.log" 2>&1; then
    echo "$t: $(grep -o 'number_of_executed_units: *[0-9]*' "build/fuzz/logs/$t.log" | grep -o '[0-9]*$') executions in ${seconds}s, no finding"
  else
    echo "$t: FINDING (build/fuzz/logs/$t.log)"; tail -n 40 "build/fuzz/logs/$t.log"; return 1
  fi
}
status=0
pids=()
for t in "${targets[@]}"; do
  run "$t" & pids+=($!)
  if [ ${#pids[@]} -ge "$(nproc)" ]; then wait "${pids[0]}" || status=1; pids=("${pids[@]:1}"); fi
done
for p in "${pids[@]}"; do wait "$p" || status=1; done
exit $status
