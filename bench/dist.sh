#!/usr/bin/env bash
# Data-parallel scaling on this machine (bench/dist.cpp under mpirun), written into bench/RESULTS.md
# between the "dist" markers (bench/make_results.py keeps that section when it rewrites the file):
# the reference-scale JEPA step at 1 rank x 2 threads, 2 ranks x 1 thread and 1 rank x 1 thread,
# medians of 3 runs of 5 timed steps each, the allreduce's share, and the step time and
# communication per step on paper for 16 nodes of 64 cores over 25 Gb/s Ethernet.
#   bench/dist.sh [global batch, default 8]
# Run it on a quiet machine.
set -euo pipefail
cd "$(dirname "$0")/.."
source tools/deps.sh
tjepa_ensure_packages "${TJEPA_TEST_PACKAGES[@]}"
B=${1:-8}
cmake --preset release -DTJEPA_USE_MPI=ON -DTJEPA_BUILD_BENCHMARKS=ON -DTJEPA_BUILD_EXAMPLES=ON >/dev/null
cmake --build --preset release --target tjepa_bench_dist -j "$(nproc)"
export OMPI_ALLOW_RUN_AS_ROOT=1 OMPI_ALLOW_RUN_AS_ROOT_CONFIRM=1
out=build/dist
mkdir -p "$out"
: >"$out/runs.txt"
for r in 1 2 3; do
  OMP_NUM_THREADS=2 mpirun -np 1 --bind-to none -x OMP_NUM_THREADS build/release/bench/tjepa_bench_dist "$B" 5 | tee -a "$out/runs.txt"
  OMP_NUM_THREADS=1 mpirun -np 2 --bind-to core -x OMP_NUM_THREADS build/release/bench/tjepa_bench_dist "$B" 5 | tee -a "$out/runs.txt"
  OMP_NUM_THREADS=1 mpirun -np 1 --bind-to core -x OMP_NUM_THREADS build/release/bench/tjepa_bench_dist "$B" 5 | tee -a "$out/runs.txt"
done
python3 - "$out/runs.txt" "$B" >"$out/section.md" <<'PY'
import re, statistics, subprocess, sys, datetime
runs = {}
for line in open(sys.argv[1]):
    m = re.match(r"(\d+) rank\(s\) x (\d+) thread\(s\), global batch (\d+): ([\d.]+) ms per step, ([\d.]+) windows/s; "
                 r"allreduce ([\d.]+) ms \(([\d.]+) % of the step\) of (\d+) gradient values", line)
    if m:
        runs.setdefault((int(m[1]), int(m[2])), []).append((float(m[4]), float(m[5]), float(m[6]), float(m[7]), int(m[8])))
B = int(sys.argv[2])
sh = lambda c: subprocess.run(c, shell=True, capture_output=True, text=True).stdout.strip()
cpu = sh("grep -m1 'model name' /proc/cpuinfo | cut -d: -f2").strip()
print("<!-- dist:begin -->")
print("## Data parallel (MPI)\n")
print(f"- date: {datetime.date.today()}; machine: {cpu}, {sh('nproc')} vCPU; tjepa git {sh('git rev-parse --short HEAD')}; "
      f"{sh('mpirun --version | head -1')}")
print(f"- command: `bench/dist.sh` (bench/dist.cpp: the reference-scale JEPA step, ViT-Tiny d 192 x 12 blocks, "
      f"predictor 4 blocks, N 368, m·τ 30, 2L+2G masks, drop-path 0.3, global batch {B}; medians of 3 runs of 5 timed steps)\n")
print("| ranks x threads | ms per step | windows/s | allreduce ms | allreduce share |")
print("|---|---|---|---|---|")
med = {}
for (ranks, threads), v in sorted(runs.items()):
    ms, wps, ar, share = (statistics.median(x[i] for x in v) for i in range(4))
    med[(ranks, threads)] = (ms, wps, ar, share, v[0][4])
    print(f"| {ranks} x {threads} | {ms:.0f} | {wps:.2f} | {ar:.1f} | {share:.1f} % |")
values = next(iter(med.values()))[4]
S = values * 4
print(f"\nGradients summed per step: {values} values (context encoder and predictor, fp32), {S / 1e6:.1f} MB, one "
      "MPI_Allreduce per parameter set, before clipping.")
if (1, 1) in med:
    per_core = med[(1, 1)][1]
    R, cores, bw, lat = 16, 64, 25e9 / 8, 50e-6
    ring = 2 * (R - 1) / R * S / bw + 2 * (R - 1) * lat
    print("\n**On paper: 16 nodes x 64 cores, 25 Gb/s Ethernet.** Ring allreduce: each node sends and receives "
          f"2·(R−1)/R·S = {2 * (R - 1) / R * S / 1e6:.1f} MB per step, {1e3 * 2 * (R - 1) / R * S / bw:.1f} ms at "
          f"3.125 GB/s, plus 2·(R−1) = 30 message latencies of about 50 µs: **{1e3 * ring:.0f} ms per step**. "
          f"Compute, from this run's one-core rate ({per_core:.2f} windows/s) scaled by 64 cores per node with no loss "
          "(an upper bound):")
    print("\n| global batch | windows per node | compute ms per step | allreduce ms | share if not overlapped | windows/s (16 nodes) |")
    print("|---|---|---|---|---|---|")
    for gb in (256, 2048):
        comp = gb / R / (per_core * cores)
        print(f"| {gb} | {gb // R} | {1e3 * comp:.0f} | {1e3 * ring:.0f} | {100 * ring / (comp + ring):.0f} % | "
              f"{gb / (comp + ring):.0f} |")
    comp = 256 / R / (per_core * cores)
    print(f"\nAt the paper's batch of 256 the allreduce would cost {100 * ring / (comp + ring):.0f} % of a step unless "
          "it overlapped the backward pass (not implemented: the gradients are summed after backward, one call per "
          "parameter set); at DECO-50's 2048 it is a few per cent. Sparsh-skin's 85 million windows (500 epochs) "
          f"would take at least {85e6 / (256 / (comp + ring)) / 3600:.1f} h at the batch of 256 (the paper: 6.1 h on "
          "four A100s).")
print("<!-- dist:end -->")
PY
python3 bench/put_section.py dist "$out/section.md"
echo "wrote the data-parallel section of bench/RESULTS.md" >&2
