#!/usr/bin/env bash
# Where the time goes: sampling profiles (`perf record -e cpu-clock`, one thread pinned to core 0)
# of the benchmarks below issue 22's fp32 goal of 85 % of the FMA peak, and of bf16 inference
# against issue 61's 12 ms a window (its products against twice the peak), grouped into
# products, packing, epilogues and element-wise work, and the products' own rates implied by the
# FLOPs they do. Writes the section between the "profile" markers of bench/RESULTS.md
# (bench/make_results.py keeps it when compare.sh rewrites the file).
#   bench/profile.sh
# Run it on a quiet machine (about 4 minutes after the builds).
set -euo pipefail
cd "$(dirname "$0")/.."
source tools/deps.sh
tjepa_ensure_packages "${TJEPA_BUILD_PACKAGES[@]}" linux-perf
# Two builds of the benchmarks: the release preset's (what compare.sh times), and the same with
# TJEPA_PROFILE_SYMBOLS, which keeps attention's micro-kernels, the GEMM epilogue, its GELU and
# bf16's conversion of A out of line so that the profile can tell them from the products and the
# softmax (inlined, their samples carry the caller's name).
cmake --preset release -DTJEPA_BUILD_BENCHMARKS=ON -DTJEPA_BUILD_TESTS=OFF -DTJEPA_BUILD_EXAMPLES=ON >/dev/null
cmake --build --preset release --target tjepa_bench -j "$(nproc)"
cmake -S . -B build/profile-bin -G Ninja -DCMAKE_BUILD_TYPE=Release -DTJEPA_NATIVE=ON -DTJEPA_BUILD_BENCHMARKS=ON \
  -DTJEPA_BUILD_TESTS=OFF -DTJEPA_BUILD_EXAMPLES=OFF -DCMAKE_CXX_FLAGS=-DTJEPA_PROFILE_SYMBOLS >/dev/null
cmake --build build/profile-bin --target tjepa_bench -j "$(nproc)"

release=build/release/bench/tjepa_bench
bench=build/profile-bin/bench/tjepa_bench
out=build/profile
mkdir -p "$out"
git rev-parse --short HEAD >"$out/commit.txt"
one() { OMP_NUM_THREADS=1 OMP_PROC_BIND=false taskset -c 0 "$@"; }

timed='BM_FmaPeak|BM_Bf16DotPeak|BM_EncoderForward(Frozen)?/368/|BM_EncoderForwardFrozenBf16/368/|BM_EncoderForwardBackwardBf16/|BM_EncoderForwardBackward/368/8/0/|BM_AttentionForwardBackward(OneSample)?/L:368/'
for b in release profile; do
  echo "timings, $b build" >&2
  exe=$bench
  [ "$b" = release ] && exe=$release
  one "$exe" --benchmark_filter="$timed" --benchmark_repetitions=3 --benchmark_report_aggregates_only=true \
    --benchmark_format=json >"$out/timings_$b.json"
done

# name, benchmark filter, seconds of sampling
profiles=(
  "encoder_frozen|BM_EncoderForwardFrozen/368/1/|5"
  "encoder_per_call|BM_EncoderForward/368/1/|5"
  "attention_b1|BM_AttentionForwardBackward/L:368/batch:1\$|5"
  "attention_b8|BM_AttentionForwardBackward/L:368/batch:8/|5"
  "encoder_train|BM_EncoderForwardBackward/368/8/0/|10"
)
# bf16 where the build has AVX512-BF16 (without it the benchmark skips).
grep -qw avx512_bf16 /proc/cpuinfo &&
  profiles+=("encoder_frozen_bf16|BM_EncoderForwardFrozenBf16/368/1/|5" "encoder_train_bf16|BM_EncoderForwardBackwardBf16/368/8/0/|10")
for p in "${profiles[@]}"; do
  IFS='|' read -r name filter seconds <<<"$p"
  echo "profile $name" >&2
  one perf record -q -e cpu-clock -F 4999 -o "$out/$name.data" "$bench" --benchmark_filter="$filter" \
    --benchmark_min_time="$seconds" >"$out/$name.log" 2>&1 || { cat "$out/$name.log" >&2; exit 1; }
  perf report -i "$out/$name.data" --no-children --sort symbol --stdio --percent-limit 0 2>/dev/null >"$out/$name.txt"
done

/usr/bin/python3 bench/profile_report.py "$out" >"$out/section.md"
/usr/bin/python3 bench/put_section.py profile "$out/section.md"
echo "wrote the profile section of bench/RESULTS.md" >&2
