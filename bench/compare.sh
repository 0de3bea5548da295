#!/usr/bin/env bash
# Runs tjepa's benchmarks and PyTorch's (bench/compare_torch.py) side by side, at 1 and 2
# threads (the kernels, the encoder, and the whole JEPA step at N 368 and at the DECO-50 scale,
# 528 grouped tokens; bf16 where tjepa_bench has it), and the streaming latency runs, and writes
# bench/RESULTS.md: the tables and each of issues 8's and 22's goals, met or the distance to it.
# Run it on a quiet machine: `bench/compare.sh`.
# (Sections written by other scripts or by hand, between "<!-- NAME:begin/end -->" markers, are kept.)
# PyTorch comes from Debian's python3-torch (installed here if missing, as root); it is never a
# dependency of the library or its tests. libopenblas0-pthread is ensured too: without it Debian's
# PyTorch falls back to the netlib reference BLAS and the comparison measures that instead.
set -euo pipefail
cd "$(dirname "$0")/.."
source tools/deps.sh
tjepa_ensure_packages "${TJEPA_BUILD_PACKAGES[@]}" python3-torch libopenblas0-pthread
cmake --preset release -DTJEPA_BUILD_BENCHMARKS=ON -DTJEPA_BUILD_TESTS=OFF -DTJEPA_BUILD_EXAMPLES=ON >/dev/null
cmake --build --preset release --target tjepa_bench tjepa_streaming -j "$(nproc)"

out=build/compare
mkdir -p "$out"
source bench/torch_env.sh
torch_openblas_core "$out/openblas_core.txt"
kernels='BM_FmaPeak|BM_EncoderForward/|BM_EncoderForwardFrozen/|BM_EncoderForwardBf16/|BM_EncoderForwardBackward/.*/0/|BM_AttentionForward/|BM_AttentionForwardBackward/'
for t in 1 2; do
  # The whole JEPA step (bench/train.cpp: BM_JepaTrainStep, BM_JepaTrainStepDeco and their Bf16
  # variants) takes its thread count as the first argument: run the one of this pass (a variant
  # without arguments runs on the OpenMP threads set here).
  filter="$kernels|BM_JepaTrainStep[A-Za-z0-9]*(/$t/|/[a-z]|\$)"
  echo "tjepa, $t thread(s)" >&2
  OMP_NUM_THREADS=$t OMP_PROC_BIND=false build/release/bench/tjepa_bench --benchmark_filter="$filter" \
    --benchmark_repetitions=3 --benchmark_report_aggregates_only=true --benchmark_format=json \
    > "$out/tjepa_t$t.json"
  echo "PyTorch, $t thread(s)" >&2
  OMP_NUM_THREADS=$t OPENBLAS_NUM_THREADS=$t MKL_NUM_THREADS=$t OMP_WAIT_POLICY=PASSIVE \
    /usr/bin/python3 bench/compare_torch.py --threads "$t" > "$out/torch_t$t.jsonl"
done
# The inference goal (issue 8): latency per control-loop tick, p99 against p50, and allocations.
# Pinned to core 0 (here the virtio interrupts go to core 1: see `grep virtio /proc/interrupts`).
# At 100 Hz under SCHED_FIFO (root only) as a robot's control loop runs, busy-waiting between ticks
# (spin: the core stays awake and its caches warm) with the controls (an FMA loop in registers and
# 1 MiB and 4 MiB memory sweeps, timed the same way: the machine's own spread); then sleeping
# between ticks, and back to back. make_results.py reads the raw outputs.
echo "tjepa_streaming" >&2
rt=()
if [ "$(id -u)" = 0 ]; then rt=(--realtime); fi
rm -f "$out"/stream_*.txt
stream() { OMP_NUM_THREADS=1 taskset -c 0 build/release/examples/tjepa_streaming --ticks 2000 "$@"; }
for r in 1 2 3; do
  stream --rate 100 "${rt[@]}" --spin --controls > "$out/stream_spin_$r.txt" || true
  stream --rate 100 "${rt[@]}" > "$out/stream_sleep_$r.txt" || true
  stream --rate 0 > "$out/stream_rate0_$r.txt" || true
  stream --rate 100 "${rt[@]}" --spin --precision bf16 > "$out/stream_bf16-spin_$r.txt" || true
done
/usr/bin/python3 bench/make_results.py "$out" > "$out/RESULTS.md"
mv "$out/RESULTS.md" bench/RESULTS.md
echo "wrote bench/RESULTS.md" >&2
