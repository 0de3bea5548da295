#!/usr/bin/env python3
"""Paired A/B of tjepa_streaming builds: runs each binary in turn, round after round, on the same
cores with the same arguments, and reports each one's median p50 per tick (and per stage, from
--stages) with the paired speed-up over the first binary: per round, the first binary's p50 over
this one's, the runs seconds apart, so that a slow spell of the machine longer than a round
cancels. On a VM whose speed moves by 10 % from minute to minute, only such pairs show a change
of a few percent.

  bench/pair_streaming.py [--rounds 8] [--ticks 150] [--threads 2] [--args "--reference-size --precision bf16"] \\
      NAME=BINARY NAME=BINARY ...

A base build of another commit: `git worktree add /tmp/base COMMIT && cmake -S /tmp/base --preset release
-DTJEPA_BUILD_EXAMPLES=ON && cmake --build /tmp/base/build/release --target tjepa_streaming`."""
import argparse
import os
import re
import shlex
import statistics
import subprocess
import sys

STAGES = ["norm1", "qkv", "barrier", "attention", "proj", "norm2", "mlp"]  # barrier: 2+ threads only


def run(binary, args):
    env = dict(os.environ, OMP_PROC_BIND="false")
    cmd = ["taskset", "-c", f"0-{args.threads - 1}", binary, "--ticks", str(args.ticks), "--threads",
           str(args.threads), "--stages", *shlex.split(args.args)]
    out = subprocess.run(cmd, env=env, check=True, capture_output=True, text=True).stdout
    p50 = re.search(r"latency per tick: p50 (\d+) us", out)
    if not p50:
        sys.exit(f"pair_streaming: no 'latency per tick' line from {binary}:\n{out}")
    stages = {m.group(1): float(m.group(2)) for m in re.finditer(r"^(\w+)\s+([\d.]+)\s", out, flags=re.M)}
    return float(p50.group(1)), stages


def quartiles(values):
    q = statistics.quantiles(values, n=4) if len(values) > 1 else [values[0]] * 3
    return q[0], q[2]


def parse_builds(specs, tool):
    """NAME=BINARY arguments as (name, binary) pairs; an error naming the argument otherwise."""
    builds = []
    for b in specs:
        name, sep, binary = b.partition("=")
        if not sep or not os.access(binary, os.X_OK):
            sys.exit(f"{tool}: '{b}': expected NAME=BINARY with an executable BINARY")
        builds.append((name, binary))
    return builds


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--rounds", type=int, default=8)
    parser.add_argument("--ticks", type=int, default=150)
    parser.add_argument("--threads", type=int, default=2)
    parser.add_argument("--args", default="--reference-size --precision bf16")
    parser.add_argument("builds", nargs="+", metavar="NAME=BINARY")
    args = parser.parse_args()
    builds = parse_builds(args.builds, "pair_streaming")
    p50 = {n: [] for n, _ in builds}
    stages = {n: {s: [] for s in STAGES} for n, _ in builds}
    for _ in range(args.rounds):
        for name, binary in builds:
            t, st = run(binary, args)
            p50[name].append(t)
            for s in STAGES:
                if s in st:
                    stages[name][s].append(st[s])
    base = builds[0][0]
    print(f"`bench/pair_streaming.py --rounds {args.rounds} --ticks {args.ticks} --threads {args.threads} "
          f"--args \"{args.args}\"`: medians over the rounds; paired: the median of {base}'s p50 over this build's, "
          "round by round, with its quartiles.\n")
    print("| build | p50 µs | paired speed-up over " + base + " (quartiles) | " +
          " | ".join(f"{s} µs" for s in STAGES) + " |")
    print("|---|---|---|" + "---|" * len(STAGES))
    for name, _ in builds:
        ratios = [a / b for a, b in zip(p50[base], p50[name])]
        lo, hi = quartiles(ratios)
        cells = [f"{statistics.median(v):.0f}" if v else "" for v in stages[name].values()]
        print(f"| {name} | {statistics.median(p50[name]):.0f} | {statistics.median(ratios):.3f}× ({lo:.3f}-{hi:.3f}) | " +
              " | ".join(cells) + " |")


if __name__ == "__main__":
    main()
