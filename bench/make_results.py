#!/usr/bin/python3
"""Turns the JSON of bench/compare.sh into bench/RESULTS.md (Markdown on stdout)."""
import datetime
import json
import pathlib
import platform
import re
import subprocess
import sys

# GFLOP/s, fp32 FMA peak of one core: measured in the same run (BM_FmaPeak, 1 thread) when present;
# 233 is the reference machine's (two 512-bit FMA units at ~3.6 GHz). Hosts of the same name differ:
# one that runs AVX-512 on 256-bit units peaks at half that.
REFERENCE_PEAK = 233.0
PEAK_PER_CORE = REFERENCE_PEAK

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
        if t == 1 and b["run_name"].startswith("BM_FmaPeak"):
            PEAK_PER_CORE = b["GFLOP/s"]  # a rate counter: Google Benchmark writes it per second
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
      f"attention forward 4·L²·d, forward+backward 3.5× that. Peak: {PEAK_PER_CORE:.1f} GFLOP/s per core, "
      f"{'measured in this run (BM_FmaPeak: 12 chains of native-width FMAs, 1 thread)' if PEAK_PER_CORE != REFERENCE_PEAK else 'the reference machine'}"
      f"; '% of peak' and the goals use it (the issue's reference machine: {REFERENCE_PEAK:g}).\n")
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


# --- Inference latency (tjepa_streaming outputs) -------------------------------------------------

def parse_stream(path):
    """The encoder's p50/p99, its unpreempted ticks, allocations and the controls of one run."""
    text = path.read_text()
    r = {"file": path.name}
    m = re.search(r"latency per tick: p50 (\d+) us, p99 (\d+) us, max (\d+) us.*p99/p50 ([\d.]+)", text)
    if not m:
        return None
    r["p50"], r["p99"], r["ratio"] = int(m.group(1)), int(m.group(2)), float(m.group(4))
    tail = text[m.end():]
    m = re.search(r"(\d+) of (\d+) ticks preempted; the others: p50 (\d+) us, p99 (\d+) us, p99/p50 ([\d.]+)", tail)
    r["preempted"], r["ticks"], r["ratio_alone"] = (int(m.group(1)), int(m.group(2)), float(m.group(5))) if m else (0, 0, r["ratio"])
    m = re.search(r"allocations in steady state: (-?\d+)", text)
    r["allocations"] = int(m.group(1)) if m else None
    m = re.search(r"control, FMAs in registers: p50 \d+ us, p99 \d+ us, max \d+ us, p99/p50 ([\d.]+)", text)
    r["fma"] = float(m.group(1)) if m else None
    r["memory"] = {int(k): float(v) for k, v in
                   re.findall(r"control, (\d+) KiB memory sweeps: p50 \d+ us, p99 \d+ us, max \d+ us, p99/p50 ([\d.]+)", text)}
    return r


MODES = (("spin", "--rate 100 {rt}--spin --controls"), ("sleep", "--rate 100 {rt}(sleeping)"),
         ("rate0", "--rate 0 (back to back)"))
streams = {mode: [s for s in (parse_stream(p) for p in sorted(d.glob(f"stream_{mode}_*.txt"))) if s]
           for mode, _ in MODES}
sizes = sorted({k for runs in streams.values() for s in runs for k in s["memory"]})
if any(streams.values()):
    realtime = "SCHED_FIFO" in "".join(p.read_text() for p in d.glob("stream_spin_*.txt"))
    print("\n## Inference latency\n")
    print("`OMP_NUM_THREADS=1 taskset -c 0 build/release/examples/tjepa_streaming --ticks 2000 <mode>`: the demo's "
          "encoder (d = 96, 4 blocks, 368 taxels, batch 1, weights packed once) and the attentive probe, one thread, "
          "pinned to core 0 (the virtio interrupts go to core 1 here). The controls time an FMA loop in registers "
          "and read-modify-write sweeps over 1 MiB (fits the 2 MiB L2) and 4 MiB buffers, each as long as the "
          "median tick, the same way: the machine's own spread.\n")
    print("| mode | p50 µs | p99 µs | p99/p50 | ticks preempted | p99/p50 of the others | FMA control p99/p50 | "
          + "".join(f"{k} KiB sweep p99/p50 | " for k in sizes) + "allocations in steady state |")
    print("|---|---|---|---|---|---|---|" + "---|" * len(sizes) + "---|")
    for mode, label in MODES:
        label = label.format(rt="--realtime " if realtime else "")
        for s in streams[mode]:
            f = lambda v: "" if v is None else f"{v:.3f}"
            print(f"| `{label}` | {s['p50']} | {s['p99']} | {s['ratio']:.3f} | {s['preempted']} of {s['ticks']} | "
                  f"{s['ratio_alone']:.3f} | {f(s['fma'])} | " + "".join(f"{f(s['memory'].get(k))} | " for k in sizes)
                  + f"{s['allocations']} |")


# --- The goals (issue 8) ----------------------------------------------------------------------------

def ms(key, t, side="tjepa_ms"):
    return rows.get((key, t), {}).get(side)


def speedup(key, t):
    a, b = ms(key, t), ms(key, t, "torch_ms")
    return b / a if a and b else None


def peak_fraction(key, t):
    e = rows.get((key, t), {})
    return e["gflop"] / (e["tjepa_ms"] / 1e3) / (PEAK_PER_CORE * t) if "gflop" in e and "tjepa_ms" in e else None


goals = []


def goal(name, value, ok):
    goals.append((name, value, "met" if ok else "**not met**"))


def fmt(v, spec):
    return "?" if v is None else format(v, spec)


for L in (368, 528):
    for t in (1, 2):
        x = speedup(f"encoder_forward/B1/L{L}", t)
        goal(f"encoder forward B1 L{L}, {t} thread(s): ≥ 2× PyTorch", f"{fmt(x, '.2f')}×", x is not None and x >= 2)
enc = [peak_fraction(f"encoder_forward/B1/L{L}", 1) for L in (368, 528, 2124)]
enc = [v for v in enc if v is not None]
goal("encoder forward B1, 1 thread: ≥ 60% of the FMA peak (L 368, 528, 2124; lowest)",
     f"{100 * min(enc):.0f}%" if enc else "?", bool(enc) and min(enc) >= 0.6)
for B in (1, 8):
    x = peak_fraction(f"attention_forward_backward/B{B}/L528", 1)
    goal(f"attention forward+backward B{B} L528, 1 thread: ≥ 60% of the FMA peak",
         f"{fmt(None if x is None else 100 * x, '.0f')}%", x is not None and x >= 0.6)
for t in (1, 2):
    x = speedup("attention_forward/B1/L2124", t)
    goal(f"attention forward B1 L2124, {t} thread(s): ≥ 3× PyTorch", f"{fmt(x, '.2f')}×", x is not None and x >= 3)
for t in (1, 2):
    x = speedup("train_step/B8/L368", t)
    goal(f"training step B8 L368, {t} thread(s): ≥ 2× PyTorch", f"{fmt(x, '.2f')}×", x is not None and x >= 2)
a, b = ms("train_step/B8/L368", 1), ms("train_step/B8/L368", 2)
goal("training step B8 L368: 2 threads ≥ 1.8× one thread", f"{fmt(a / b if a and b else None, '.2f')}×",
     bool(a and b) and a / b >= 1.8)
all_runs = [s for runs in streams.values() for s in runs]
latency_note = None
if all_runs:
    allocs = [s["allocations"] for s in all_runs]
    goal("inference: zero allocations in steady state", f"{max(allocs)} (largest of {len(allocs)} runs)",
         all(a == 0 for a in allocs))
    loop = streams["spin"] or streams["sleep"] or streams["rate0"]
    median = lambda v: sorted(v)[len(v) // 2] if v else None
    ratios = sorted(s["ratio"] for s in loop)
    med = median(ratios)
    fma = median([s["fma"] for s in loop if s["fma"] is not None])
    mem = {k: median([s["memory"][k] for s in loop if k in s["memory"]]) for k in sizes}
    controls = "".join([f"; FMA control {fma:.3f}" if fma else ""] + [f", {k} KiB sweep {v:.3f}" for k, v in mem.items()])
    others = "".join(f"; {mode}: {median([s['ratio'] for s in streams[mode]]):.3f}"
                     for mode, _ in MODES if streams[mode] and streams[mode] is not loop)
    goal("inference at 100 Hz: p99 within 10% of p50 (median of the runs)",
         f"{med:.3f} (runs: {', '.join(f'{r:.3f}' for r in ratios)}{controls}, medians{others})", med <= 1.10)
    if med > 1.10 and mem:
        worst = max(mem.values())
        latency_note = (
            f"**Why the latency goal is not met here.** In the same runs, loops that do fixed work of the tick's "
            f"length, timed the same way, spread as follows (median p99/p50): FMAs in registers {fma:.3f}, "
            + ", ".join(f"a {k} KiB memory sweep {v:.3f}" for k, v in mem.items())
            + f"; the encoder's tick {med:.3f}. "
            + ("The tick spreads no more than the memory sweeps do, even the one that fits in L2: "
               "on this virtual machine any work that touches memory varies that much from tick to tick, "
               "so the 10% goal is the machine's to meet before it is the encoder's. "
               if med <= worst + 0.05 else
               "The tick spreads more than the memory sweeps: part of the distance is the encoder's. ")
            + "`tjepa_streaming --stages` times each stage of every tick: in the slowest 1% of ticks every stage "
              "is slower in proportion (bench/HISTORY.md), not one stage. What it would take: a machine "
              "without neighbours on its memory system (bare metal, an isolated core), where the controls "
              "themselves stay within 10%.")
print("\n## Goals (issue 8)\n")
print("Computed from the tables above by bench/make_results.py.\n")
print("| goal | measured | |")
print("|---|---|---|")
for name, value, ok in goals:
    print(f"| {name} | {value} | {ok} |")
if latency_note:
    print("\n" + latency_note)
print("\nAttention memory is O(L·d) by construction: the forward and backward run over query and key "
      "tiles with an online softmax and keep only the per-row log-sum-exp, never an L×L matrix "
      "(include/tjepa/model/kernels/attention.hpp).")
# The data-parallel section is bench/dist.sh's (it needs mpirun); keep it from the current file.
_previous = pathlib.Path(__file__).with_name("RESULTS.md")
if _previous.exists():
    _m = re.search(r"<!-- dist:begin -->.*?<!-- dist:end -->", _previous.read_text(), flags=re.S)
    if _m:
        print("\n" + _m.group(0))
