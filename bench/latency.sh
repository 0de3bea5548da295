#!/usr/bin/env bash
# Latency of the Pipeline (downstream/pipeline.hpp) at batch 1 on 1 thread pinned to core 0, and on
# t threads pinned to cores 0..t-1 for every t up to the cores present (issue 61, item 5): the
# demo-size encoder (d 96, 4 blocks) and the reference-size one (d 192, 12 blocks, ViT-Tiny) on the
# 368-taxel hand, each with a probe head (force and indenter, the cost of a trained one), fp32 and
# bf16, the FMA peak of the same run beside them, and the floor it sets: the encoder's FLOPs at t
# cores' peak (bf16 at twice fp32's rate). Writes the section between the "latency" markers of
# bench/RESULTS.md.
#   bench/latency.sh [TICKS]        (default 1000 ticks after 20 warm-up ticks; about 6 minutes on 2 cores)
set -euo pipefail
cd "$(dirname "$0")/.."
ticks=${1:-1000}
source tools/deps.sh
tjepa_ensure_packages "${TJEPA_BUILD_PACKAGES[@]}"
cmake --preset release -DTJEPA_BUILD_BENCHMARKS=ON -DTJEPA_BUILD_EXAMPLES=ON >/dev/null
cmake --build --preset release --target tjepa_streaming tjepa_bench -j "$(nproc)"
one() { OMP_NUM_THREADS=1 OMP_PROC_BIND=false taskset -c 0 "$@"; }
cores=$(nproc)
out=build/latency
mkdir -p "$out"
peak=$(one build/release/bench/tjepa_bench --benchmark_filter='^BM_FmaPeak$' --benchmark_format=json |
  python3 -c 'import json,sys; b=json.load(sys.stdin)["benchmarks"][0]; print("%.0f" % (b["GFLOP/s"] if "GFLOP/s" in b else b["FLOPS"]/1e9))')
dirty=$(git status --porcelain --untracked-files=no include examples bench | grep -q . && echo " with uncommitted changes" || true)
cpu=$(grep -m1 'model name' /proc/cpuinfo | cut -d: -f2- | sed 's/^ *//')
{
  echo "<!-- latency:begin -->"
  echo "## Pipeline latency (issues 59, 61)"
  echo
  echo "\`bench/latency.sh\`, $(date -u +%Y-%m-%d), commit $(git rev-parse --short HEAD)$dirty, $cpu; \`BM_FmaPeak\` in the same run: $peak GFLOP/s on one core."
  echo "\`OMP_PROC_BIND=false taskset -c 0-<t-1> build/release/examples/tjepa_streaming --ticks $ticks <size> --precision <p> --threads <t>\`: Pipeline::push per frame (drift, preprocessing, window, tokenizer, encoder on all 368 tokens, probe head), one window per frame, back to back. Floor: the encoder's forward FLOPs (2·N·(12·d² + 2·N·d) a block, N 368) at t cores' \`BM_FmaPeak\`, twice that rate for bf16; % of peak = floor / p50."
  echo
  echo "| encoder | precision | threads | p50 µs | p99 µs | max µs | windows/s at p99 | floor µs | % of peak at p50 | speed-up over 1 thread | allocations in steady state |"
  echo "|---|---|---|---|---|---|---|---|---|---|---|"
  for size in demo reference; do
    flag=""
    [ "$size" = reference ] && flag="--reference-size"
    for p in fp32 bf16; do
      for t in $(seq 1 "$cores"); do
        log="$out/$size-$p-t$t.txt"
        OMP_PROC_BIND=false taskset -c "0-$((t - 1))" build/release/examples/tjepa_streaming --ticks "$ticks" $flag \
          --precision "$p" --threads "$t" >"$log"
        python3 - "$out/$size-$p-t1.txt" "$log" "$size" "$p" "$t" "$peak" <<'PY'
import re, sys
def read(path):
    text = open(path).read()
    lat = re.search(r"latency per tick: p50 (\d+) us, p99 (\d+) us, max (\d+) us", text)
    return text, [int(g) for g in lat.groups()]
_, (p50_1, _, _) = read(sys.argv[1])
text, (p50, p99, mx) = read(sys.argv[2])
size, p, t, peak = sys.argv[3], sys.argv[4], int(sys.argv[5]), float(sys.argv[6])
alloc = re.search(r"allocations in steady state: (\d+)", text)
head = re.search(r"encoder d=(\d+), (\d+) blocks", text)
d, blocks, N = int(head.group(1)), int(head.group(2)), 368
native = "no AVX512-BF16" not in text
note = "" if native else " (computed in fp32: no AVX512-BF16)"
flops = blocks * 2 * N * (12 * d * d + 2 * N * d)
rate = peak * 1e9 * t * (2 if p == "bf16" and native else 1)
floor = flops / rate * 1e6
print(f"| {size} (d {d}, {blocks} blocks) | {p}{note} | {t} | {p50} | {p99} | {mx} | {1e6 / p99:.0f} | {floor:.0f} | "
      f"{100 * floor / p50:.0f}% | {p50_1 / p50:.2f}× | {alloc.group(1)} |")
PY
      done
    done
  done
  echo "<!-- latency:end -->"
} >"$out/section.md"
python3 bench/put_section.py latency "$out/section.md"
cat "$out/section.md"
