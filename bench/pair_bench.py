#!/usr/bin/env python3
"""Paired A/B of tjepa_bench builds: runs each binary in turn (the order reversed every other
round), round after round, on the same cores with the same benchmark filter, and reports each
benchmark's median time per build with the paired speed-up over the first build: per round, the
first build's time over this one's, seconds apart, so that a slow spell of the machine longer than
a round cancels (bench/pair_streaming.py does the same for tjepa_streaming). --ratio A B adds,
per build, benchmark A's time over benchmark B's in the same run (the bf16 step's speed-up over
fp32, say), its median and quartiles over the rounds.

  bench/pair_bench.py [--rounds 8] [--threads 1] --filter 'BM_JepaTrainStep/1/|BM_JepaTrainStepBf16/1/' \\
      [--ratio BM_JepaTrainStep/1/ BM_JepaTrainStepBf16/1/] NAME=BINARY NAME=BINARY ...

With --scale SKIN:PRECISION (repeatable) the binaries are tjepa_scale builds instead
(bench/scale.cpp): each run is `tjepa_scale --skin SKIN --precision PRECISION --threads T --reps 3`
per --scale given, and its whole step's median is the benchmark `step/SKIN/PRECISION`.

A base build of another commit: `git worktree add /tmp/base COMMIT && cmake -S /tmp/base --preset release
-DTJEPA_BUILD_BENCHMARKS=ON && cmake --build /tmp/base/build/release --target tjepa_bench`."""
import argparse
import csv
import io
import json
import os
import statistics
import subprocess
import sys

from pair_streaming import parse_builds, quartiles


def cores(args):
    return f"{args.first_core}-{args.first_core + args.threads - 1}"


def run_scale(binary, args, env):
    times = {}
    for pair in args.scale:
        skin, precision = pair.split(":")
        cmd = ["taskset", "-c", cores(args), binary, "--skin", skin, "--precision", precision,
               "--threads", str(args.threads), "--reps", "3"]
        out = subprocess.run(cmd, env=env, check=True, capture_output=True, text=True).stdout
        steps = [json.loads(line)["ms"] for line in out.splitlines()
                 if line.startswith("{") and json.loads(line)["phase"] == "step"]
        if len(steps) != 1:
            sys.exit(f"pair_bench: {binary}: {len(steps)} step lines for {pair}, not one")
        times[f"step/{skin}/{precision}"] = steps[0]
    return times


def run(binary, args):
    env = dict(os.environ, OMP_NUM_THREADS=str(args.threads), OMP_PROC_BIND="false")
    if args.scale:
        return run_scale(binary, args, env)
    cmd = ["taskset", "-c", cores(args), binary, f"--benchmark_filter={args.filter}",
           "--benchmark_format=csv"]
    out = subprocess.run(cmd, env=env, check=True, capture_output=True, text=True).stdout
    times = {}
    for row in csv.reader(io.StringIO(out[out.find("name,"):])):
        if row and row[0] != "name" and row[0].startswith("BM_"):
            if row[4] != "ms":
                sys.exit(f"pair_bench: {binary}: {row[0]} reports its time in {row[4]}, not ms")
            times[row[0]] = float(row[2])
    if not times:
        sys.exit(f"pair_bench: {binary}: no benchmark matches '{args.filter}'")
    return times


def pick(times, prefix, binary):
    hits = [name for name in times if name.startswith(prefix)]
    if len(hits) != 1:
        sys.exit(f"pair_bench: {binary}: --ratio '{prefix}' matches {len(hits)} of {sorted(times)}, not one")
    return times[hits[0]]


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--rounds", type=int, default=8)
    parser.add_argument("--threads", type=int, default=1)
    parser.add_argument("--first-core", type=int, default=0,
                        help="cores first-core.. (1 keeps one thread off core 0, where a VM's interrupts may land)")
    parser.add_argument("--filter")
    parser.add_argument("--scale", action="append", metavar="SKIN:PRECISION")
    parser.add_argument("--ratio", nargs=2, metavar=("A", "B"))
    parser.add_argument("builds", nargs="+", metavar="NAME=BINARY")
    args = parser.parse_args()
    if bool(args.filter) == bool(args.scale):
        parser.error("give --filter (tjepa_bench builds) or --scale (tjepa_scale builds), one of them")
    builds = parse_builds(args.builds, "pair_bench")
    runs = {n: [] for n, _ in builds}
    for r in range(args.rounds):
        for name, binary in builds if r % 2 == 0 else builds[::-1]:
            runs[name].append(run(binary, args))
        print(f"round {r + 1} of {args.rounds}", file=sys.stderr)
    first = builds[0][0]
    benchmarks = sorted(runs[first][0])
    print(f"{args.rounds} rounds, {args.threads} thread(s), taskset -c {cores(args)}")
    print("| benchmark | build | median ms | paired speed-up over " + first + " (quartiles) |")
    print("|---|---|---|---|")
    for bm in benchmarks:
        for name, _ in builds:
            t = [run_[bm] for run_ in runs[name]]
            s = [a[bm] / b[bm] for a, b in zip(runs[first], runs[name])]
            lo, hi = quartiles(s)
            print(f"| {bm} | {name} | {statistics.median(t):.1f} | {statistics.median(s):.3f}× ({lo:.3f}-{hi:.3f}) |")
    if args.ratio:
        a, b = args.ratio
        print(f"\n| build | {a} over {b}, median (quartiles) |")
        print("|---|---|")
        for name, binary in builds:
            q = [pick(t, a, binary) / pick(t, b, binary) for t in runs[name]]
            lo, hi = quartiles(q)
            print(f"| {name} | {statistics.median(q):.3f}× ({lo:.3f}-{hi:.3f}) |")


if __name__ == "__main__":
    main()
