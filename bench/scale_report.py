#!/usr/bin/python3
"""bench/scale.sh's outputs (DIR: tjepa_scale's JSON lines per skin and precision, PyTorch's
compare_torch.py lines per thread count, the FMA peak) -> the "scale" section of bench/RESULTS.md
(Markdown on stdout).

The serial part: with a fraction f of the one-thread time T1 on one thread only (Amdahl), t threads
take T1·(f + (1 - f)/t), so a measured speed-up S_t gives f = (t/S_t - 1)/(t - 1), and that f
predicts 1/(f + (1 - f)/n) at n threads. Per phase the same reading of its 1- and 2-thread times,
serial = 2·T2 - T1, is the time the phase spends on one thread only (negative where it sped up by
more than 2x: cache effects or noise; the column sums to the step's own 2·T2 - T1)."""
import datetime
import json
import pathlib
import subprocess
import sys

d = pathlib.Path(sys.argv[1])
PREDICT = (4, 8, 16, 64)


def sh(cmd):
    try:
        return subprocess.run(cmd, shell=True, capture_output=True, text=True).stdout.strip()
    except OSError:
        return "?"


def load_jsonl(path):
    return [json.loads(line) for line in path.read_text().splitlines() if line.strip().startswith("{")]


def serial_fraction(t, speedup):
    return (t / speedup - 1) / (t - 1)


def predicted(f, n):
    return 1 / (f + (1 - f) / n)


def step_speedup(steps, t):
    """The t-thread step's speed-up over 1 thread, {threads: step row}: the paired one where the run
    has it (tjepa_scale's repetition-by-repetition ratio), else the ratio of the medians; None
    without both rows."""
    if 1 not in steps or t not in steps:
        return None
    return steps[t].get("paired_speedup") or steps[1]["ms"] / steps[t]["ms"]


peak = float((d / "peak.txt").read_text().strip())
bf16_file = d / "bf16_peak.txt"
bf16_peak = float(bf16_file.read_text().strip()) if bf16_file.exists() else None
# Where AMX ran the bf16 products (BM_AmxPeak measured: the build has AMX and it was enabled), the
# bf16 rows' ceiling is the tiles' peak.
amx_file = d / "amx_peak.txt"
amx_peak = float(amx_file.read_text().strip()) if amx_file.exists() else None
bf16_ceiling = amx_peak or bf16_peak
runs = {}  # (skin, precision) -> rows
for path in sorted(d.glob("tjepa_*.jsonl"), key=lambda p: (p.name.split("_")[1], "bf16" in p.name)):  # fp32 first
    rows = load_jsonl(path)
    if rows:
        runs[(rows[0]["skin"], rows[0]["precision"])] = rows
torch = {}  # (N, style, threads) -> ms
for path in sorted(d.glob("torch_t*.jsonl")):
    for r in load_jsonl(path):
        if "name" in r and r["name"].startswith("jepa_step"):
            style = "dinov2" if r["name"].startswith("jepa_step_dinov2") else "timm"
            torch[(int(r["name"].split("/")[1]), style, r["threads"])] = r["ms"]

N_OF = {"allegro": 368, "deco": 528}
cpu = sh("grep -m1 'model name' /proc/cpuinfo | cut -d: -f2- | sed 's/^ *//'")
family = sh("grep -m1 'cpu family' /proc/cpuinfo | cut -d: -f2 | tr -d ' '")
model = sh("grep -m1 '^model\\s' /proc/cpuinfo | cut -d: -f2 | tr -d ' '")
amx = "AMX" if "amx_tile" in sh("grep -m1 flags /proc/cpuinfo") else "no AMX"
reps = next(iter(runs.values()))[-1].get("reps", "?") if runs else "?"
core_file = d / "openblas_core.txt"
openblas = core_file.read_text().strip() if core_file.exists() else "?"

print("<!-- scale:begin -->")
print("## Threads and the serial part of the JEPA step (issue 61)\n")
measured = (d / "commit.txt").read_text().strip() if (d / "commit.txt").exists() else sh("git rev-parse --short HEAD")
day = (d / "date.txt").read_text().strip() if (d / "date.txt").exists() else datetime.date.today().isoformat()
print(f"`bench/scale.sh`, {day}, commit {measured}, "
      f"{cpu} (family {family}, model {model}, {amx}), {sh('nproc')} cores; `BM_FmaPeak` in the same run: "
      f"{peak:.0f} GFLOP/s on one core"
      + (f", `BM_Bf16DotPeak` (vdpbf16ps) {bf16_peak:.0f} ({bf16_peak / peak:.2f}× the FMA's)" if bf16_peak else "")
      + (f", `BM_AmxPeak` (AMX tiles, which run the bf16 products here) {amx_peak:.0f} ({amx_peak / peak:.1f}×)"
         if amx_peak else "")
      + ". `build/release/bench/tjepa_scale --skin <skin> --precision <p> "
      f"--threads 1,...,{sh('nproc')} --reps {reps}`: one JEPA step (bench/jepa_setup.hpp: ViT-Tiny, batch 8, "
      "no drop-path) timed phase by phase by its own StageClock marks, the thread counts taking turns "
      f"repetition by repetition, the thread team woken before each step's clock starts (a trainer's threads "
      f"come to a step warm from the last); medians. PyTorch (OpenBLAS kernels: {openblas}, bench/torch_env.sh): "
      "`bench/compare_torch.py --only jepa --threads t` "
      "(timm-style drop-path 0.3, every branch computed: the same work), and its DINOv2 drop-path "
      "variant (branches on 5 of 8 samples: less work) in the last column.\n")
print("Serial fraction f from the measured speed-up S_t at t threads: f = (t/S_t − 1)/(t − 1) (Amdahl); "
      "the speed-ups f predicts at more threads beside it. % of peak: of t cores' BM_FmaPeak"
      + (f" (bf16 rows: of t cores' {'BM_AmxPeak' if amx_peak else 'BM_Bf16DotPeak'}, the bf16 products' ceiling; "
         "the step's GFLOP/s count its products in fp32 and bf16 alike)" if bf16_ceiling else "") + ".\n")
print("Paired: the median over repetitions of the 1-thread step over the t-thread step of the same repetition "
      "(a second apart, so a slow spell of the machine longer than that cancels), with its quartiles; f and "
      "the predictions are from it where the run has it, else from the ratio of the medians.\n")
print("| skin (N) | precision | threads | step ms | GFLOP/s | % of peak | speed-up of the medians | "
      "paired speed-up (quartiles) | f | "
      + " | ".join(f"predicted at {n}" for n in PREDICT)
      + " | PyTorch ms | tjepa speed-up over PyTorch | PyTorch ms, DINOv2 drop-path |")
print("|---|---|---|---|---|---|---|---|---|" + "---|" * len(PREDICT) + "---|---|---|")
for (skin, precision), rows in runs.items():
    steps = {r["threads"]: r for r in rows if r["phase"] == "step"}
    t1 = steps[1]["ms"] if 1 in steps else None
    for t, r in sorted(steps.items()):
        s = t1 / r["ms"] if t1 else None
        paired = r.get("paired_speedup") if t > 1 else None
        f = serial_fraction(t, step_speedup(steps, t)) if s and t > 1 else None
        pt = torch.get((N_OF[skin], "timm", t)) if precision == "fp32" else None
        pd = torch.get((N_OF[skin], "dinov2", t)) if precision == "fp32" else None
        cells = [f"{skin} ({N_OF[skin]})", precision, str(t), f"{r['ms']:.0f}", f"{r['gflops']:.0f}",
                 f"{100 * r['gflops'] / ((bf16_ceiling if precision == 'bf16' and bf16_ceiling else peak) * t):.0f}%", f"{s:.2f}×" if s else "",
                 f"{paired:.2f}× ({r['paired_speedup_quartiles'][0]:.2f}-{r['paired_speedup_quartiles'][1]:.2f})"
                 if paired else "",
                 f"{100 * f:.1f}%" if f is not None else ""]
        cells += [f"{predicted(f, n):.1f}×" if f is not None else "" for n in PREDICT]
        cells += [f"{pt:.0f}" if pt else "", f"{pt / r['ms']:.2f}×" if pt else "", f"{pd:.0f}" if pd else ""]
        print("| " + " | ".join(cells) + " |")

ceiling = {}  # (skin, precision) -> (alone ms, [each core's ms at once])
for skin, precision in runs:
    alone = d / f"ceiling_{skin}_{precision}_alone.jsonl"
    each = [load_jsonl(c) for c in sorted(d.glob(f"ceiling_{skin}_{precision}_core*.jsonl"))]
    first = load_jsonl(alone) if alone.exists() else []
    if first and each and all(each):
        ceiling[(skin, precision)] = (first[0]["ms"], [c[0]["ms"] for c in each])
if ceiling:
    print("\n### The machine's own ceiling\n")
    print("Each skin's step on 1 thread alone (core 0), then one such step on every core at once, as "
          "independent processes (`taskset -c <core> tjepa_scale --threads 1`): they share no work and "
          "nothing in them is serial, so what the cores give together, Σ alone/each, is the most any thread "
          "count can give on this machine. f here is the serial fraction the threaded step's own speed-up "
          "would show if the ceiling were all of it.\n")
    print("| skin (N) | precision | 1 thread alone ms | each core's step, all at once, ms | together | "
          "f of the ceiling alone | threaded step's speed-up (above; paired where measured) |")
    print("|---|---|---|---|---|---|---|")
    for (skin, precision), (alone, each) in ceiling.items():
        t = len(each)
        together = sum(alone / e for e in each)
        steps = {r["threads"]: r for r in runs[(skin, precision)] if r["phase"] == "step"}
        s_t = step_speedup(steps, t)
        threaded = f"{s_t:.2f}×" if s_t else ""
        print(f"| {skin} ({N_OF[skin]}) | {precision} | {alone:.0f} | {', '.join(f'{e:.0f}' for e in each)} | "
              f"{together:.2f}× | {100 * serial_fraction(t, together):.1f}% | {threaded} |")

for (skin, precision), rows in runs.items():
    by = {(r["phase"], r.get("stage"), r["threads"]): r for r in rows}
    if not any(t == 2 for (_, _, t) in by):
        continue
    keys = []
    for r in rows:
        k = (r["phase"], r.get("stage"))
        if r["threads"] == 1 and k not in keys:
            keys.append(k)
    step1, step2 = by[("step", None, 1)]["ms"], by[("step", None, 2)]["ms"]
    total_serial = 2 * step2 - step1
    detailed = skin == "allegro" and precision == "fp32"
    print(f"\n### Phases, {skin} (N {N_OF[skin]}), {precision}, 1 and 2 threads\n")
    print("Serial = 2·T2 − T1: the time the phase runs on one thread only"
          + (" (the block stages, summed over a phase's blocks, below each phase)." if detailed else "."))
    print(f" The step: {step1:.0f} ms on 1 thread, {step2:.0f} ms on 2, serial {total_serial:.0f} ms "
          f"(f = {100 * total_serial / step1:.1f}%).\n")
    print("| phase | stage | calls | 1 thread ms | 2 threads ms | speed-up | serial ms | share of the serial time |")
    print("|---|---|---|---|---|---|---|---|")
    # Each phase, then its stages (the step lists a phase's stages before the phase itself).
    phases = [p for p, stage in keys if stage is None and p != "step"]
    for phase in phases:
        for stage in [None] + ([st for p, st in keys if p == phase and st] if detailed else []):
            a, b = by[(phase, stage, 1)], by.get((phase, stage, 2))
            if not b or b["ms"] <= 0:
                continue
            serial = 2 * b["ms"] - a["ms"]
            share = f"{100 * serial / total_serial:.0f}%" if total_serial > 0 and not stage else ""
            print(f"| {'' if stage else phase} | {stage or ''} | {a['calls']} | {a['ms']:.2f} | {b['ms']:.2f} | "
                  f"{a['ms'] / b['ms']:.2f}× | {serial:.2f} | {share} |")
print("<!-- scale:end -->")
