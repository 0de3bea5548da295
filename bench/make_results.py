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


def bench_args(run_name):
    """A run name's arguments: "BM_X/368/1/iterations:4/real_time" -> [368, 1] (named "L:368" too)."""
    out = []
    for part in run_name.split("/")[1:]:
        m = re.fullmatch(r"(?:([A-Za-z_]\w*):)?(\d+)", part)
        if m and m.group(1) not in ("iterations", "repeats", "threads", "min_time", "min_warmup_time"):
            out.append(int(m.group(2)))
    return out


def jepa_key(run_name, t):
    """BM_JepaTrainStep[Deco][Bf16]/<threads> -> ("jepa_step/368" or "/528", threads, bf16); the thread
    count is the first argument (bench/train.cpp), or the run's OpenMP threads t without one."""
    m = re.match(r"BM_JepaTrainStep(\w*)", run_name)
    if not m:
        return None
    variant = m.group(1)
    if variant.replace("Deco", "").replace("Bf16", ""):
        return None  # another benchmark of that prefix
    args = bench_args(run_name)
    return (f"jepa_step/{528 if 'Deco' in variant else 368}", args[0] if args else t, "Bf16" in variant)


def tjepa_key(run_name):
    """Maps a Google Benchmark run name to the key compare_torch.py uses."""
    nums = [int(x) for x in re.findall(r"(?::|/)(\d+)", run_name)]
    if run_name.startswith("BM_EncoderForwardBf16/"):
        return None  # the bf16 table's (bf16_key)
    if run_name.startswith("BM_EncoderForwardBackward/"):
        return f"train_step/B{nums[1]}/L{nums[0]}"
    if run_name.startswith("BM_EncoderForward/"):
        return f"encoder_forward/B{nums[1]}/L{nums[0]}"
    if run_name.startswith("BM_EncoderForwardFrozen/"):  # compared with PyTorch's encoder_forward (below)
        return f"encoder_forward_frozen/B{nums[1]}/L{nums[0]}"
    if run_name.startswith("BM_AttentionForwardBackward/"):
        return f"attention_forward_backward/B{nums[1]}/L{nums[0]}"
    if run_name.startswith("BM_AttentionForward/"):
        return f"attention_forward/B{nums[1]}/L{nums[0]}"
    return None


def bf16_key(run_name):
    """BM_EncoderForwardBf16/<L>/<B> -> the fp32 key encoder_forward/B<B>/L<L>."""
    if run_name.startswith("BM_EncoderForwardBf16/"):
        a = bench_args(run_name)
        return f"encoder_forward/B{a[1]}/L{a[0]}" if len(a) >= 2 else None
    return None


scale = {"ns": 1e-6, "us": 1e-3, "ms": 1.0, "s": 1e3}
rows = {}
torch_info = {}
for t in (1, 2):
    path = d / f"tjepa_t{t}.json"
    for b in (json.loads(path.read_text())["benchmarks"] if path.exists() else []):
        if b.get("aggregate_name") != "median":
            continue
        ms_ = b["real_time"] * scale[b["time_unit"]]
        if t == 1 and b["run_name"].startswith("BM_FmaPeak"):
            PEAK_PER_CORE = b["GFLOP/s"]  # a rate counter: Google Benchmark writes it per second
        jk = jepa_key(b["run_name"], t)
        if jk:
            key, threads, bf16 = jk
            e = rows.setdefault((key, threads), {})
            e["tjepa_bf16_ms" if bf16 else "tjepa_ms"] = ms_
            if not bf16 and "K" in b:
                e["tjepa_K"] = int(b["K"])
            if not bf16 and "GFLOP/s" in b:
                e["tjepa_gflops"] = b["GFLOP/s"] / 1e9  # Google Benchmark writes the rate per second
            continue
        key = bf16_key(b["run_name"])
        if key:
            rows.setdefault((key, t), {})["tjepa_bf16_ms"] = ms_
            continue
        key = tjepa_key(b["run_name"])
        if key:
            rows.setdefault((key, t), {})["tjepa_ms"] = ms_
    path = d / f"torch_t{t}.jsonl"
    for line in (path.read_text().splitlines() if path.exists() else []):
        if not line.strip():
            continue
        r = json.loads(line)
        if "ms" not in r:  # {"info": "torch", "blas": [...]}
            torch_info[t] = r
            continue
        name = r["name"]
        if name.startswith("jepa_step_dinov2/"):  # the reference's DINOv2 drop-path: its own column
            rows.setdefault(("jepa_step/" + name.split("/")[1], t), {})["torch_dinov2_ms"] = r["ms"]
            continue
        e = rows.setdefault((name, t), {})
        e["torch_ms"], e["gflop"] = r["ms"], r["gflop"]
        for k in ("B", "K", "targets"):
            if k in r:
                e[k] = r[k]
# The frozen-weight encoder (weights packed once) does the work of PyTorch's encoder_forward.
for (key, t), e in list(rows.items()):
    if key.startswith("encoder_forward_frozen/"):
        torch_row = rows.get((key.replace("_frozen", ""), t), {})
        e.update({k: torch_row[k] for k in ("torch_ms", "gflop") if k in torch_row})
blas = sorted({b for i in torch_info.values() for b in i.get("blas", [])})
blas_name = ", ".join(blas) if blas else "not recorded"

print("# Benchmark results\n")
print(f"- date: {datetime.date.today().isoformat()}")
cpu = sh("lscpu | sed -n 's/^Model name: *//p'")
# Hosts of one model name differ (an EPYC of family 25 runs AVX-512 on 256-bit units, one of
# family 26 on 512-bit units): the family and model numbers say which core ran.
family = sh("sed -n 's/^cpu family[^:]*: *//p' /proc/cpuinfo | head -1")
model = sh("sed -n 's/^model[[:space:]]*: *//p' /proc/cpuinfo | head -1")
if family and model:
    cpu += f" (cpu family {family}, model {model})"
torch_version = sh("/usr/bin/python3 -c 'import torch; print(torch.__version__)'")
print(f"- machine: {cpu}, {sh('nproc')} vCPU, "
      f"{platform.system()} {platform.release()}")
dirty = " (with uncommitted changes)" if sh("git status --porcelain --untracked-files=no include bench/*.cpp examples") else ""
print(f"- tjepa: git {sh('git rev-parse --short HEAD')}{dirty}, {sh('c++ --version | head -1')}, "
      "preset `release` (-O3 -march=native), OpenMP threads = column 'threads'")
print(f"- PyTorch: {torch_version} "
      "(Debian python3-torch), plain nn modules with manual attention (bench/compare_torch.py), "
      "torch.set_num_threads(threads), OMP_WAIT_POLICY=PASSIVE, OPENBLAS_NUM_THREADS=threads; "
      f"BLAS that ran: {blas_name}; OpenBLAS kernels: "
      f"{(d / 'openblas_core.txt').read_text().strip() if (d / 'openblas_core.txt').exists() else '?'} (bench/torch_env.sh)")
print("- command: `bench/compare.sh` (medians of 3 repetitions for tjepa; median of >= 2 s of runs for PyTorch)")
print(f"- FLOPs: matmul FLOPs only; encoder forward 12·(24·L·d² + 4·L²·d); training step = 3× forward; "
      f"attention forward 4·L²·d, forward+backward 3.5× that. Peak: {PEAK_PER_CORE:.1f} GFLOP/s per core, "
      f"{'measured in this run (BM_FmaPeak: 12 chains of native-width FMAs, 1 thread)' if PEAK_PER_CORE != REFERENCE_PEAK else 'the reference machine'}"
      f"; '% of peak' and the goals use it (the issue's reference machine: {REFERENCE_PEAK:g}).\n")
print("| benchmark | threads | tjepa ms | tjepa GFLOP/s | % of peak | PyTorch ms | PyTorch GFLOP/s | speed-up |")
print("|---|---|---|---|---|---|---|---|")
for (key, t), e in sorted(rows.items(), key=lambda kv: (kv[0][0].split("/")[0], kv[0][0], kv[0][1])):
    if "tjepa_ms" not in e or "torch_ms" not in e or key.startswith("jepa_step/"):
        continue
    g = e["gflop"]
    ours = g / (e["tjepa_ms"] / 1e3)
    theirs = g / (e["torch_ms"] / 1e3)
    print(f"| {key} | {t} | {e['tjepa_ms']:.2f} | {ours:.0f} | {100 * ours / (PEAK_PER_CORE * t):.0f}% | "
          f"{e['torch_ms']:.2f} | {theirs:.0f} | {e['torch_ms'] / e['tjepa_ms']:.2f}× |")


# --- The whole JEPA step (issue 22) ---------------------------------------------------------------

def windows(e, ms_):
    return e.get("B", 8) / (ms_ / 1e3)


jepa = sorted(((k, t), e) for (k, t), e in rows.items() if k.startswith("jepa_step/") and
              ("tjepa_ms" in e or "torch_ms" in e))
if jepa:
    print("\n## Whole JEPA step\n")
    print("One Tactile-JEPA pre-training step, batch 8, fp32: the target encoder (EMA copy, drop-path too) "
          "on all N tokens, the context encoder on the K context tokens, the 4-block predictor on each "
          "target (the targets of one size in one pass), MSE, backward, clipping at 10, AdamW, EMA; "
          "ViT-Tiny d 192, 12 blocks; the masks tjepa's MaskCollator draws (seed 3, "
          "batch 0; PyTorch gets fixed masks of the same sizes). N 368: the Allegro/Xela skin, m·τ = 30 "
          "per token (`BM_JepaTrainStep/<threads>`); N 528: DECO-50, 2124 taxels in groups of 4 and 5, "
          "τ = 3 (`BM_JepaTrainStepDeco/<threads>`). PyTorch (`jepa_step/<N>` in bench/compare_torch.py) "
          "is written the way I-JEPA-style reference code runs the step, with timm-style drop-path 0.3 "
          "(every sample's branch computed, then masked); tjepa runs without drop-path (bench/train.cpp), "
          "so both compute every branch (tjepa would skip a dropped sample's branch). "
          "The last columns time the reference's own DINOv2 NestedTensorBlock drop-path (at rates > 0.1 "
          "each branch runs on int(0.7·B) = 5 of the 8 samples), when measured. GFLOP: bench/train.cpp's "
          "convention (target encoder 1× forward, context encoder and predictor 3×), the same for both.\n")
    print("| N | threads | K | targets | tjepa ms | tjepa windows/s | tjepa GFLOP/s | % of peak | PyTorch ms | "
          "PyTorch windows/s | speed-up | PyTorch ms, DINOv2 drop-path | speed-up over it |")
    print("|---|---|---|---|---|---|---|---|---|---|---|---|---|")
    for (key, t), e in jepa:
        a, b, c = e.get("tjepa_ms"), e.get("torch_ms"), e.get("torch_dinov2_ms")
        g = e.get("gflop")
        f = lambda v, spec: "" if v is None else format(v, spec)
        gf = g / (a / 1e3) if g and a else e.get("tjepa_gflops")
        print(f"| {key.split('/')[1]} | {t} | {e.get('tjepa_K', e.get('K', ''))} | "
              f"{','.join(map(str, e.get('targets', [])))} | {f(a, '.0f')} | {f(a and windows(e, a), '.2f')} | "
              f"{f(gf, '.0f')} | {f(gf and 100 * gf / (PEAK_PER_CORE * t), '.0f')}{'%' if gf else ''} | "
              f"{f(b, '.0f')} | {f(b and windows(e, b), '.2f')} | {f(a and b and b / a, '.2f')}{'×' if a and b else ''} | "
              f"{f(c, '.0f')} | {f(a and c and c / a, '.2f')}{'×' if a and c else ''} |")

bf16 = sorted(((k, t), e) for (k, t), e in rows.items() if "tjepa_bf16_ms" in e)
if bf16:
    print("\n## bf16\n")
    print("tjepa's bf16 precision policy (AVX512-BF16 `vdpbf16ps`, fp32 accumulation and master weights) "
          "against its own fp32 run of the same benchmark and against PyTorch fp32 "
          "(`BM_EncoderForwardBf16/<L>/<B>` against `BM_EncoderForward/<L>/<B>`, "
          "`BM_JepaTrainStep[Deco]Bf16` against `BM_JepaTrainStep[Deco]`).\n")
    print("| benchmark | threads | tjepa bf16 ms | tjepa fp32 ms | speed-up over fp32 | PyTorch ms | speed-up over PyTorch |")
    print("|---|---|---|---|---|---|---|")
    for (key, t), e in bf16:
        a, f32, b = e["tjepa_bf16_ms"], e.get("tjepa_ms"), e.get("torch_ms")
        f = lambda v, spec: "?" if v is None else format(v, spec)
        print(f"| {key} | {t} | {a:.2f} | {f(f32, '.2f')} | {f(f32 and f32 / a, '.2f')}× | {f(b, '.2f')} | "
              f"{f(b and b / a, '.2f')}× |")


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
         ("rate0", "--rate 0 (back to back)"), ("bf16-spin", "--precision bf16 --rate 100 {rt}--spin"))
streams = {mode: [s for s in (parse_stream(p) for p in sorted(d.glob(f"stream_{mode}_*.txt"))) if s]
           for mode, _ in MODES}
sizes = sorted({k for runs in streams.values() for s in runs for k in s["memory"]})
if any(streams.values()):
    realtime = "SCHED_FIFO" in "".join(p.read_text() for p in d.glob("stream_spin_*.txt"))
    print("\n## Inference latency\n")
    print("`OMP_NUM_THREADS=1 taskset -c 0 build/release/examples/tjepa_streaming --ticks 2000 <mode>`: the demo's "
          "encoder (d = 96, 4 blocks, 368 taxels, batch 1, weights packed once) and the attentive probe, one thread, "
          "pinned to core 0 (the virtio interrupts go to core 1 here). The controls time an FMA loop in registers "
          "and read-modify-write sweeps over 1 MiB (the size of one core's L2 on a Zen 4 or Zen 5) and 4 MiB buffers, each as long as the "
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
                     for mode, _ in MODES if streams[mode] and streams[mode] is not loop and mode != "bf16-spin")
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
              "was slower in proportion (commit b6c9a84), not one stage. What it would take: a machine "
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

# --- The goals of issue 22 (whole JEPA step, bf16) ---------------------------------------------------
goals22 = []


def goal22(name, value, ok):
    goals22.append((name, value, "met" if ok else "not measured" if value.startswith("?") else "**not met**"))


def ratio(key, t, num, den):
    e = rows.get((key, t), {})
    return e[num] / e[den] if e.get(num) and e.get(den) else None


for key, what in (("encoder_forward_frozen", "frozen weights (inference)"),
                  ("encoder_forward", "weights packed per call (training's target encoder)")):
    enc = [peak_fraction(f"{key}/B1/L{L}", 1) for L in (368, 528, 2124)]
    enc = [v for v in enc if v is not None]
    goal22(f"fp32 encoder forward B1, 1 thread, {what}: ≥ 85% of the FMA peak (L 368, 528, 2124; lowest)",
           f"{100 * min(enc):.0f}%" if enc else "?", bool(enc) and min(enc) >= 0.85)
kern = {f"{k}/B{B}/L{L}": peak_fraction(f"{k}/B{B}/L{L}", 1) for k in ("attention_forward", "attention_forward_backward")
        for B in (1, 8) for L in (368, 528, 2124)}
kern = {k: v for k, v in kern.items() if v is not None}
low = min(kern, key=kern.get) if kern else None
goal22("fp32 attention kernels, 1 thread: ≥ 85% of the FMA peak (forward and forward+backward, B 1 and 8, "
       "L 368, 528, 2124; lowest)", f"{100 * kern[low]:.0f}% ({low})" if low else "?", bool(kern) and kern[low] >= 0.85)
for N in (368, 528):
    for t in (1, 2):
        x = ratio(f"jepa_step/{N}", t, "torch_ms", "tjepa_ms")
        goal22(f"JEPA step N {N}, {t} thread(s), fp32: ≥ 1.5× PyTorch", f"{fmt(x, '.2f')}×", x is not None and x >= 1.5)
for L in (368, 528):
    x = ratio(f"encoder_forward/B1/L{L}", 1, "tjepa_ms", "tjepa_bf16_ms")
    goal22(f"bf16 encoder forward B1 L{L}, 1 thread: ≥ 1.7× tjepa fp32", f"{fmt(x, '.2f')}×", x is not None and x >= 1.7)
for N in (368, 528):
    for t in (1, 2):
        x = ratio(f"jepa_step/{N}", t, "tjepa_ms", "tjepa_bf16_ms")
        goal22(f"bf16 JEPA step N {N}, {t} thread(s): ≥ 1.5× tjepa fp32", f"{fmt(x, '.2f')}×", x is not None and x >= 1.5)
        x = ratio(f"jepa_step/{N}", t, "torch_ms", "tjepa_bf16_ms")
        goal22(f"bf16 JEPA step N {N}, {t} thread(s): ≥ 2.5× PyTorch", f"{fmt(x, '.2f')}×", x is not None and x >= 2.5)
b16 = streams.get("bf16-spin", [])
if b16:
    r16 = sorted(s["ratio"] for s in b16)
    m16 = r16[len(r16) // 2]
    a16 = max(s["allocations"] if s["allocations"] is not None else 1 for s in b16)
    goal22("bf16 inference at 100 Hz: p99/p50 ≤ 1.10 (median of the runs) and zero allocations",
           f"{m16:.3f} (runs: {', '.join(f'{r:.3f}' for r in r16)}; p50 {b16[0]['p50']} µs), allocations {a16}",
           m16 <= 1.10 and a16 == 0)
else:
    goal22("bf16 inference at 100 Hz: p99/p50 ≤ 1.10 and zero allocations", "?", False)
print("\n## Goals (issue 22)\n")
print("Computed from the tables above by bench/make_results.py ('?': not measured in this run). "
      "PyTorch is the timm-style drop-path column of the JEPA step table.\n")
print("| goal | measured | |")
print("|---|---|---|")
for name, value, ok in goals22:
    print(f"| {name} | {value} | {ok} |")
# The profile section is bench/profile.sh's (it needs perf), the data-parallel one bench/dist.sh's
# (it needs mpirun), the latency one bench/latency.sh's, the threads one bench/scale.sh's, the
# AlexNet, -O2, Xeon and AMX ones and the notes on earlier runs are written by hand: all kept from the
# current file, below.
_previous = pathlib.Path(__file__).with_name("RESULTS.md")
_previous_text = _previous.read_text() if _previous.exists() else ""
_kept = [m.group(0) for m in (re.search(rf"<!-- {n}:begin -->.*?<!-- {n}:end -->", _previous_text, flags=re.S)
                              for n in ("profile", "dist", "latency", "row_owned", "scale", "mlp_backward", "o2", "xeon", "amx", "cnn",
                                        "notes")) if m]
if any("85%" in name and ok != "met" for name, _, ok in goals22) and "<!-- profile:begin -->" in _previous_text:
    print("\nWhere the fp32 goals of 85 % of the peak are not met, the section \"Where the time goes\" "
          "(bench/profile.sh) shows where the rest of the time is: the products against the packing, epilogues "
          "and element-wise work around them.")
print("\nAttention memory is O(L·d) by construction: the forward and backward run over query and key "
      "tiles with an online softmax and keep only the per-row log-sum-exp, never an L×L matrix "
      "(include/tjepa/kernels/attention.hpp).")
for _section in _kept:
    print("\n" + _section)
