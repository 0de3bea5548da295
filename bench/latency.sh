#!/usr/bin/env bash
# Latency of the Pipeline (downstream/pipeline.hpp) at batch 1, one thread pinned to core 0: the
# demo-size encoder (d 96, 4 blocks) and the reference-size one (d 192, 12 blocks, ViT-Tiny) on the
# 368-taxel hand, each with a probe head (force and indenter, the cost of a trained one), fp32 and
# bf16, the FMA peak of the same run beside them. Writes the section between the "latency" markers
# of bench/RESULTS.md.
#   bench/latency.sh [TICKS]        (default 1000 ticks after 20 warm-up ticks; about 3 minutes)
set -euo pipefail
cd "$(dirname "$0")/.."
ticks=${1:-1000}
source tools/deps.sh
tjepa_ensure_packages "${TJEPA_BUILD_PACKAGES[@]}"
cmake --preset release -DTJEPA_BUILD_BENCHMARKS=ON -DTJEPA_BUILD_EXAMPLES=ON >/dev/null
cmake --build --preset release --target tjepa_streaming tjepa_bench -j "$(nproc)"
one() { OMP_NUM_THREADS=1 OMP_PROC_BIND=false taskset -c 0 "$@"; }
out=build/latency
mkdir -p "$out"
peak=$(one build/release/bench/tjepa_bench --benchmark_filter='^BM_FmaPeak$' --benchmark_format=json |
  python3 -c 'import json,sys; b=json.load(sys.stdin)["benchmarks"][0]; print("%.0f" % (b["GFLOP/s"] if "GFLOP/s" in b else b["FLOPS"]/1e9))')
cpu=$(grep -m1 'model name' /proc/cpuinfo | cut -d: -f2- | sed 's/^ *//')
{
  echo "<!-- latency:begin -->"
  echo "## Pipeline latency (issue 59)"
  echo
  echo "\`bench/latency.sh\`, $(date -u +%Y-%m-%d), commit $(git rev-parse --short HEAD), $cpu; \`BM_FmaPeak\` in the same run: $peak GFLOP/s on one core."
  echo "\`OMP_NUM_THREADS=1 taskset -c 0 build/release/examples/tjepa_streaming --ticks $ticks <size> --precision <p>\`: Pipeline::push per frame (drift, preprocessing, window, tokenizer, encoder on all 368 tokens, probe head), one window per frame, back to back."
  echo
  echo "| encoder | precision | p50 µs | p99 µs | max µs | windows/s at p99 | allocations in steady state |"
  echo "|---|---|---|---|---|---|---|"
  for size in demo reference; do
    flag=""
    [ "$size" = reference ] && flag="--reference-size"
    for p in fp32 bf16; do
      log="$out/$size-$p.txt"
      one build/release/examples/tjepa_streaming --ticks "$ticks" $flag --precision "$p" >"$log"
      python3 - "$log" "$size" "$p" <<'PY'
import re, sys
text = open(sys.argv[1]).read()
lat = re.search(r"latency per tick: p50 (\d+) us, p99 (\d+) us, max (\d+) us", text)
alloc = re.search(r"allocations in steady state: (\d+)", text)
head = re.search(r"encoder d=(\d+), (\d+) blocks", text)
note = " (computed in fp32: no AVX512-BF16)" if "no AVX512-BF16" in text else ""
p50, p99, mx = (int(g) for g in lat.groups())
print(f"| {sys.argv[2]} (d {head.group(1)}, {head.group(2)} blocks) | {sys.argv[3]}{note} | {p50} | {p99} | {mx} | {1e6 / p99:.0f} | {alloc.group(1)} |")
PY
    done
  done
  echo "<!-- latency:end -->"
} >"$out/section.md"
python3 bench/put_section.py latency "$out/section.md"
cat "$out/section.md"
