#!/usr/bin/python3
"""Turns the JSON of bench/compare.sh into bench/RESULTS.md (Markdown on stdout)."""
import datetime
import json
import pathlib
import platform
import re
import subprocess
import sys

PEAK_PER_CORE = 233.0  # GFLOP/s, fp32 FMA peak of one core of this machine (AVX-512)

d = pathlib.Path(sys.argv[1])


def sh(cmd):
    try:
        return subprocess.run(cmd, shell=True, capture_output=True, text=True).stdout.strip()
    except OSError:
        return "?"


def tjepa_key(run_name):
    """Maps a Google Benchmark run name to the key compare_torch.py uses."""
    nums = [int(x) for x in re.findall(r"(?::|/)(\d+)", run_name)]
    if run_name.startswith("BM_EncoderForwardBackward/"):
        return f"train_step/B{nums[1]}/L{nums[0]}"
    if run_name.startswith("BM_EncoderForward/"):
        return f"encoder_forward/B{nums[1]}/L{nums[0]}"
    if run_name.startswith("BM_AttentionForwardBackward/"):
        return f"attention_forward_backward/B{nums[1]}/L{nums[0]}"
    if run_name.startswith("BM_AttentionForward/"):
        return f"attention_forward/B{nums[1]}/L{nums[0]}"
    return None


scale = {"ns": 1e-6, "us": 1e-3, "ms": 1.0, "s": 1e3}
rows = {}
for t in (1, 2):
    for b in json.loads((d / f"tjepa_t{t}.json").read_text())["benchmarks"]:
        if b.get("aggregate_name") != "median":
            continue
        key = tjepa_key(b["run_name"])
        if key:
            rows.setdefault((key, t), {})["tjepa_ms"] = b["real_time"] * scale[b["time_unit"]]
    for line in (d / f"torch_t{t}.jsonl").read_text().splitlines():
        r = json.loads(line)
        e = rows.setdefault((r["name"], t), {})
        e["torch_ms"], e["gflop"] = r["ms"], r["gflop"]

print("# Benchmark results\n")
print(f"- date: {datetime.date.today().isoformat()}")
cpu = sh("lscpu | sed -n 's/^Model name: *//p'")
torch_version = sh("/usr/bin/python3 -c 'import torch; print(torch.__version__)'")
print(f"- machine: {cpu}, {sh('nproc')} vCPU, "
      f"{platform.system()} {platform.release()}")
print(f"- tjepa: git {sh('git rev-parse --short HEAD')}, {sh('c++ --version | head -1')}, "
      "preset `release` (-O3 -march=native), OpenMP threads = column 'threads'")
print(f"- PyTorch: {torch_version} "
      "(Debian python3-torch), plain nn modules with manual attention (bench/compare_torch.py), "
      "torch.set_num_threads(threads), OMP_WAIT_POLICY=PASSIVE, OPENBLAS_NUM_THREADS=threads")
print("- command: `bench/compare.sh` (medians of 3 repetitions for tjepa; median of >= 2 s of runs for PyTorch)")
print(f"- FLOPs: matmul FLOPs only; encoder forward 12·(24·L·d² + 4·L²·d); training step = 3× forward; "
      f"attention forward 4·L²·d, forward+backward 3.5× that. Peak: {PEAK_PER_CORE:g} GFLOP/s per core.\n")
print("| benchmark | threads | tjepa ms | tjepa GFLOP/s | % of peak | PyTorch ms | PyTorch GFLOP/s | speed-up |")
print("|---|---|---|---|---|---|---|---|")
for (key, t), e in sorted(rows.items(), key=lambda kv: (kv[0][0].split("/")[0], kv[0][0], kv[0][1])):
    if "tjepa_ms" not in e or "torch_ms" not in e:
        continue
    g = e["gflop"]
    ours = g / (e["tjepa_ms"] / 1e3)
    theirs = g / (e["torch_ms"] / 1e3)
    print(f"| {key} | {t} | {e['tjepa_ms']:.2f} | {ours:.0f} | {100 * ours / (PEAK_PER_CORE * t):.0f}% | "
          f"{e['torch_ms']:.2f} | {theirs:.0f} | {e['torch_ms'] / e['tjepa_ms']:.2f}× |")
