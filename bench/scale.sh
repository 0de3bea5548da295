#!/usr/bin/env bash
# The JEPA step on 1, 2, ... threads (every count up to the cores present), phase by phase: where
# its time goes, the time each phase spends on one thread only, the serial fraction f the
# speed-ups imply and the speed-ups that f predicts at 4, 8, 16 and 64 threads, with PyTorch's step
# at the same thread counts beside it (issue 61). Both skins of bench/jepa_setup.hpp (N 368, and
# DECO-50's 528 grouped tokens), fp32 and, where the build has AVX512-BF16, bf16. Writes the section
# between the "scale" markers of bench/RESULTS.md (bench/make_results.py keeps it).
#   bench/scale.sh [REPS]     (default 9 repetitions per thread count; about 10 minutes on 2 cores)
# Run it on a quiet machine.
set -euo pipefail
cd "$(dirname "$0")/.."
reps=${1:-9}
source tools/deps.sh
tjepa_ensure_packages "${TJEPA_BUILD_PACKAGES[@]}" python3-torch libopenblas0-pthread
cmake --preset release -DTJEPA_BUILD_BENCHMARKS=ON -DTJEPA_BUILD_TESTS=OFF -DTJEPA_BUILD_EXAMPLES=ON >/dev/null
cmake --build --preset release --target tjepa_bench tjepa_scale -j "$(nproc)"
out=build/scale
rm -rf "$out"
mkdir -p "$out"
cores=$(nproc)
threads=$(seq -s, 1 "$cores")
# What was measured, for the report: the commit (and whether the tree differed from it) and the day.
echo "$(git rev-parse --short HEAD)$(git status --porcelain --untracked-files=no include bench | grep -q . && echo ' with uncommitted changes')" >"$out/commit.txt"
date -u +%Y-%m-%d >"$out/date.txt"
# One core's peaks: fp32 FMAs, vdpbf16ps where the build has AVX512-BF16 (the bf16 products'
# ceiling: on some CPUs below the FMA's), and AMX tiles where they run the bf16 products.
peak() {  # peak BENCHMARK FILE: the median GFLOP/s of 3 repetitions, 1 thread, core 0
  OMP_NUM_THREADS=1 taskset -c 0 build/release/bench/tjepa_bench --benchmark_filter="^$1\$" \
    --benchmark_repetitions=3 --benchmark_report_aggregates_only=true --benchmark_format=json |
    /usr/bin/python3 -c 'import json,sys; b=[x for x in json.load(sys.stdin)["benchmarks"] if x.get("aggregate_name")=="median" and "GFLOP/s" in x]; b and print("%.1f" % b[0]["GFLOP/s"])' \
    >"$2"
  [ -s "$2" ] || rm -f "$2"
}
peak BM_FmaPeak "$out/peak.txt"
peak BM_Bf16DotPeak "$out/bf16_peak.txt"
peak BM_AmxPeak "$out/amx_peak.txt"  # where the build has AMX and the tiles are enabled (TJEPA_AMX)
for skin in allegro deco; do
  for precision in fp32 bf16; do
    echo "tjepa_scale --skin $skin --precision $precision --threads $threads" >&2
    if ! OMP_PROC_BIND=false build/release/bench/tjepa_scale --skin "$skin" --precision "$precision" \
      --threads "$threads" --reps "$reps" >"$out/tjepa_${skin}_$precision.jsonl" 2>"$out/tjepa_${skin}_$precision.err"; then
      cat "$out/tjepa_${skin}_$precision.err" >&2  # bf16 on a build without AVX512-BF16: skipped
      rm -f "$out/tjepa_${skin}_$precision.jsonl"
      [ "$precision" = bf16 ] || exit 1
    fi
  done
done
# The machine's own ceiling: one 1-thread step alone on core 0, then one on every core at once
# (independent processes: nothing shared, nothing serial), per skin and precision. What the cores
# give together there, Σ alone/each, is the most any thread count can give on this machine: on a
# VM the cores share caches, memory and power with each other and with other tenants.
one() {  # one() CORE SKIN PRECISION: the step's line of a 1-thread run on CORE
  OMP_NUM_THREADS=1 taskset -c "$1" build/release/bench/tjepa_scale --skin "$2" --precision "$3" --threads 1 \
    --reps "$reps" | grep '"phase":"step"'
}
if [ "$cores" -gt 1 ]; then
  for skin in allegro deco; do
    for precision in fp32 bf16; do
      [ -f "$out/tjepa_${skin}_$precision.jsonl" ] || continue
      echo "the ceiling: $skin $precision, one step alone, then one on each of $cores cores at once" >&2
      one 0 "$skin" "$precision" >"$out/ceiling_${skin}_${precision}_alone.jsonl"
      for c in $(seq 0 $((cores - 1))); do
        one "$c" "$skin" "$precision" >"$out/ceiling_${skin}_${precision}_core$c.jsonl" &
      done
      wait
    done
  done
fi
source bench/torch_env.sh
torch_openblas_core "$out/openblas_core.txt"
for t in $(seq 1 "$cores"); do
  echo "PyTorch, $t thread(s)" >&2
  OMP_NUM_THREADS=$t OPENBLAS_NUM_THREADS=$t MKL_NUM_THREADS=$t OMP_WAIT_POLICY=PASSIVE \
    /usr/bin/python3 bench/compare_torch.py --only jepa --threads "$t" >"$out/torch_t$t.jsonl"
done
/usr/bin/python3 bench/scale_report.py "$out" >"$out/section.md"
/usr/bin/python3 bench/put_section.py scale "$out/section.md"
echo "wrote the scale section of bench/RESULTS.md" >&2
