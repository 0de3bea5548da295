#!/usr/bin/env python3
"""The profile section of bench/RESULTS.md, from bench/profile.sh's outputs in DIR:
timings_release.json and timings_profile.json (Google Benchmark, medians of 3, of the release
build and of the profiling build) and one `perf report --sort symbol` text per
profile. Usage: profile_report.py DIR > section.md

Each profile's samples are grouped by symbol into the categories below; the set-up outside the
timed loop (random initialization, the kernel's page faults as buffers are first touched) is
left out of the shares. The products' implied rate is the benchmark's counted FLOPs (matmul
only, as every table of RESULTS.md) over the time its product kernels take: what the product
micro-kernels run at, with everything else removed. bf16 profiles (products on AVX512-BF16's
vdpbf16ps, two multiply-adds per fp32 lane) are measured against the bf16 peak: BM_Bf16DotPeak,
measured in the same run (twice the FMA peak where the build has no such benchmark); their goals
are issue 61's (12 ms a window for inference on one core, 1.8x the fp32 encoder's speed for
training) rather than a share of the peak."""
import datetime
import json
import pathlib
import re
import subprocess
import sys

DIM, DEPTH, L = 192, 12, 368  # ViT-Tiny at the Allegro/Xela skin's 368 tokens (bench/model.cpp)

# (category, symbol pattern); the first match wins. None: set-up, left out of the shares.
CATEGORIES = [
    # memset: the benchmarks' buffers grown and zeroed by the warm-up call, which Google Benchmark
    # repeats for each of its trials (`perf record --call-graph dwarf` of the bf16 training encoder put
    # all of it in those resizes and in the parameters' allocation).
    (None, r"^\[k\]|init_params|__cos|__sin|__ieee754_log|^__log_fma$|Rng::|random_floats|Batch::Batch|"
           r"EncoderSetup|normal_distribution|^benchmark::|^__memset"),
    ("attention products", r"attn::micro_kernel"),
    ("attention packing", r"attn::pack|transpose16<float, tjepa::detail::attn"),
    ("attention softmax and element-wise", r"attention_forward<|attention_backward<|attn::"),
    ("GEMM products", r"[sb]gemm::depth_loop|[sb]gemm::micro_kernel|[sb]gemm::compute_rows"),
    ("GEMM epilogue (bias, residual, accumulate)", r"finish_tile|prefetch_tile"),
    ("GELU and its gradient", r"gelu"),
    # bf16: A converted to bf16 pairs before its products (pack_a, and pack_a_cols for the weight
    # gradients' dYᵀ; out of line in the profiling build).
    ("bf16 conversion of A", r"bgemm::pack_a"),
    # mlp_forward_tiled's own samples: the weight packing inlined into it (the row-tiled MLP packs
    # both weights before its tiles run).
    ("GEMM weight packing", r"sgemm::pack|transpose16<float, tjepa::detail::sgemm|pack_panel|mlp_forward_tiled"),
    ("LayerNorm", r"layer_norm"),
    ("other", r"."),
]

# name: (title, benchmark, flops of GEMM products, flops of attention products per call, the
# products' peak (1: the FMA peak; 2: the bf16 peak), the goals: a share of that peak, "N ms" a call, or "Nx BENCH":
# N times as fast as the profiling build's BENCH)
GEMM = DEPTH * 24.0 * L * DIM * DIM
ATTN = DEPTH * 4.0 * L * L * DIM
PROFILES = {
    "encoder_frozen": ("encoder forward, L 368, batch 1, frozen weights (inference)",
                       "BM_EncoderForwardFrozen/368/1/real_time", GEMM, ATTN, 1, (0.85, "22 ms")),
    "encoder_per_call": ("encoder forward, L 368, batch 1, weights packed per call (target encoder)",
                         "BM_EncoderForward/368/1/real_time", GEMM, ATTN, 1, 0.85),
    "attention_b1": ("attention forward+backward, L 368, batch 1",
                     "BM_AttentionForwardBackward/L:368/batch:1", 0.0, 1.0, 1, 0.85),
    "attention_b8": ("attention forward+backward, L 368, batch 8",
                     "BM_AttentionForwardBackward/L:368/batch:8/real_time", 0.0, 1.0, 1, 0.85),
    "encoder_train": ("encoder forward+backward, L 368, batch 8 (the training step's encoder)",
                      "BM_EncoderForwardBackward/368/8/0/real_time", 3 * 8 * GEMM, 3.5 * 8 * ATTN, 1, 0.85),
    "encoder_train_bf16": ("bf16 encoder forward+backward, L 368, batch 8 (% of the bf16 peak)",
                           "BM_EncoderForwardBackwardBf16/368/8/0/real_time", 3 * 8 * GEMM, 3.5 * 8 * ATTN, 2,
                           "1.8x BM_EncoderForwardBackward/368/8/0/real_time"),
    "encoder_frozen_bf16": ("bf16 encoder forward, L 368, batch 1, frozen weights (inference; % of the bf16 peak)",
                            "BM_EncoderForwardFrozenBf16/368/1/real_time", GEMM, ATTN, 2, "12 ms"),
}


def category(symbol: str):
    for name, pattern in CATEGORIES:
        if re.search(pattern, symbol):
            return name
    return "other"


def shares(path: pathlib.Path):
    total = {}
    for line in path.read_text().splitlines():
        m = re.match(r"\s*([\d.]+)%\s+(\[.\])\s+(.*\S)", line)
        if not m:
            continue
        symbol = m[2] + " " + m[3] if m[2] == "[k]" else m[3]
        c = category(symbol)
        total[c] = total.get(c, 0.0) + float(m[1])
    setup = total.pop(None, 0.0)
    counted = sum(total.values())
    if counted <= 0:
        raise SystemExit(f"{path}: no samples outside the set-up (did perf record run?)")
    return {c: v / counted for c, v in total.items()}, setup


def main(out: pathlib.Path):
    def medians(build):
        runs = json.loads((out / f"timings_{build}.json").read_text())["benchmarks"]
        return {b["run_name"]: b for b in runs if b.get("aggregate_name") == "median"}

    median, release = medians("profile"), medians("release")
    peak = median["BM_FmaPeak"]["GFLOP/s"]

    def peak_of(factor, timings):  # the products' peak of a profile (factor 2: bf16) in a build's run
        fma = timings["BM_FmaPeak"]["GFLOP/s"]
        if factor == 1:
            return fma
        return timings["BM_Bf16DotPeak"]["GFLOP/s"] if "BM_Bf16DotPeak" in timings else 2 * fma

    sh = lambda c: subprocess.run(c, shell=True, capture_output=True, text=True).stdout.strip()
    cpu = sh("grep -m1 'model name' /proc/cpuinfo | cut -d: -f2").strip()
    family = sh("grep -m1 'cpu family' /proc/cpuinfo | cut -d: -f2").strip()
    model = sh("grep -m1 '^model\\s' /proc/cpuinfo | cut -d: -f2").strip()
    commit_file = out / "commit.txt"  # the commit the binaries were built at (profile.sh)
    commit = commit_file.read_text().strip() if commit_file.exists() else sh("git rev-parse --short HEAD")
    print("<!-- profile:begin -->")
    print("## Where the time goes (issue 22's fp32 85 % goal, issue 61's bf16 12 ms)\n")
    print(f"- date: {datetime.date.today()}; machine: {cpu} (cpu family {family}, model {model}); "
          f"tjepa git {commit}; {sh('perf --version')}")
    print("- command: `bench/profile.sh` (one thread pinned to core 0; `perf record -e cpu-clock`, "
          "samples grouped by symbol; the benchmarks' set-up (random initialization, memset: buffers zeroed as the "
          "warm-up grows them) and the kernel's samples "
          "(mostly page faults as buffers are first touched) left out of the shares: their share of all "
          "samples in the last column)")
    bf16 = (f"BM_Bf16DotPeak {median['BM_Bf16DotPeak']['GFLOP/s']:.1f} GFLOP/s, this run"
            if "BM_Bf16DotPeak" in median else "twice that")
    print(f"- peak: {peak:.1f} GFLOP/s (BM_FmaPeak, this run; bf16 rows: {bf16}). The profiles, their "
          "'% of peak' and the "
          "products' rates are the profiling build's (`-DTJEPA_PROFILE_SYMBOLS`: attention's micro-kernels, "
          "the GEMM epilogue, its GELU and the bf16 conversion of A out of line); the release build's % of peak, timed in the same run, beside it. *Products' rate*: "
          "the benchmark's counted FLOPs over the time in the product micro-kernels alone.\n")
    cats = [c for c, _ in CATEGORIES if c is not None]
    print("| profile | % of peak | release build | " + " | ".join(cats) + " | set-up (left out) |")
    print("|---|---|---|" + "---|" * len(cats) + "---|")
    derived = []
    for name, (title, bench, gemm_flops, attn_flops, factor, goal) in PROFILES.items():
        path = out / f"{name}.txt"
        if not path.exists() or bench not in median:
            continue
        s, setup = shares(path)
        rate = median[bench]["GFLOP/s"]
        pct = rate / peak_of(factor, median)
        rel = (f"{100 * release[bench]['GFLOP/s'] / peak_of(factor, release):.0f}%"
               if bench in release else "?")
        print(f"| {title} | {100 * pct:.0f}% | {rel} | " + " | ".join(f"{100 * s.get(c, 0.0):.1f}%" for c in cats)
              + f" | {setup:.1f}% |")
        products = s.get("GEMM products", 0.0) + s.get("attention products", 0.0)
        total_flops = gemm_flops + attn_flops
        line = (f"- {title}: {100 * pct:.1f}% of the {'bf16 ' if factor > 1 else ''}peak "
                f"({median[bench]['real_time']:.2f} ms a call); products {100 * products:.0f}% of the time")
        if gemm_flops > 0 and s.get("GEMM products", 0) > 0:
            g = pct * (gemm_flops / total_flops) / s["GEMM products"]
            line += f" (GEMM products at {100 * g:.0f}% of the peak"
            if s.get("attention products", 0) > 0:
                a = pct * (attn_flops / total_flops) / s["attention products"]
                line += f", attention products at {100 * a:.0f}%"
            line += ")"
        elif products > 0:
            line += f" (attention products at {100 * pct / products:.0f}% of the peak)"
        # The rest keeps its time (1 - products of today's); the products' time left for the goal
        # (a share of the peak, or a time a call: the share that time is), as a share of today's:
        line += f"; the rest takes {100 * (1 - products):.0f}%. With the rest's time as it is"
        for i, g in enumerate(goal if isinstance(goal, tuple) else (goal,)):
            ms = None  # the goal as a time a call
            if isinstance(g, str) and g.endswith(" ms"):
                ms, what = float(g.split()[0]), f"{g} a call"
            elif isinstance(g, str):  # "Nx BENCH"
                times, other = g.split(" ", 1)
                if other not in median:
                    continue
                ms = median[other]["real_time"] / float(times.rstrip("x"))
                what = f"{times} the speed of {other.split('/')[0]} ({ms:.2f} ms a call)"
            else:
                what = f"{100 * g:.0f} % of the peak"
            target = g if ms is None else pct * median[bench]["real_time"] / ms
            left = pct / target - (1 - products)
            need = pct / left if left > 0 else float("inf")
            line += (", " if i == 0 else "; ") + what + " needs the products at "
            line += f"{100 * need:.0f}% of the peak" if left > 0 else "more than any rate"
            line += " (more than the peak: out of reach by faster products alone)" if need > 1 else ""
            if ms is not None:  # the floor: every counted FLOP at the peak, nothing else
                line += f"; every product at the peak and nothing else would take {total_flops / (peak_of(factor, median) * 1e6):.2f} ms"
        line += "."
        derived.append(line)
    print()
    for line in derived:
        print(line)
    one = release.get("BM_AttentionForwardBackwardOneSample/L:368/repeats:8/real_time")
    b8 = release.get("BM_AttentionForwardBackward/L:368/batch:8/real_time")
    b1 = release.get("BM_AttentionForwardBackward/L:368/batch:1")
    if one and b8 and b1:
        peak = release["BM_FmaPeak"]["GFLOP/s"]
        print(f"- release build, attention forward+backward at L 368, per sample: batch 1 {b1['real_time']:.3f} ms "
              f"({100 * b1['GFLOP/s'] / peak:.0f}%), one sample 8 times {one['real_time'] / 8:.3f} ms "
              f"({100 * one['GFLOP/s'] / peak:.0f}%), 8 distinct samples {b8['real_time'] / 8:.3f} ms "
              f"({100 * b8['GFLOP/s'] / peak:.0f}%): the same arithmetic costs "
              f"{100 * (b8['real_time'] / one['real_time'] - 1):.0f}% more when each sample's activations "
              "(2.3 MB with their gradients, more than the core's L2) come from farther away.")
    print("<!-- profile:end -->")


if __name__ == "__main__":
    main(pathlib.Path(sys.argv[1]))
