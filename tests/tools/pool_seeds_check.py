#!/usr/bin/env python3
"""Checks tools/pool_seeds.py on made-up `tjepa eval --trials` results: the pooled mean ± sd per
row and share, the best-against-second test and a --contrast test against values worked by hand
(Welch's t for [1, 2, 3] against [2, 3, 4]: t = -1.2247, df 4, one-sided p = 0.144, the t
distribution's tail integrated numerically below), the head-by-head differences of a contrast,
--first-heads, the shares every run has, a row repeated with the same values (the references every
run writes) kept once, and clear errors for no common share, too few heads and a repeated row
whose values differ.
    pool_seeds_check.py TOOLS_DIR WORK_DIR"""
import json
import math
import os
import subprocess
import sys

tools, work = sys.argv[1], sys.argv[2]
os.makedirs(work, exist_ok=True)
# Shares as results.json keeps them; a % metric is printed times 100.
metrics = [{"key": "acc", "name": "top-1", "unit": "%", "higher_is_better": True, "primary": True}]


def run_file(seed, shares, a, b, extra_heads=()):
    """Rows A and B, one head reading a and b % (+10 per share), then the heads (a', b') of extra_heads."""
    heads = [(a, b), *extra_heads]
    tables = [{"title": f"share {s}", "metrics": metrics,
               "rows": [{"name": n, "runs": [[{"acc": (h[i] + 10 * k) / 100} for h in heads]]} for i, n in enumerate("AB")]}
              for k, s in enumerate(shares)]
    path = os.path.join(work, f"s{seed}{'h' if extra_heads else ''}.json")
    with open(path, "w") as f:
        json.dump({"command": f"tjepa eval --seeds {seed}", "seeds": [seed], "label_fractions": shares,
                   "tables": tables}, f)
    return path


# Seeds 0, 1, 2: row B reads 2, 3, 4 and row A 1, 2, 3 (share 1); both 10 higher at share 0.1.
files = [run_file(s, [1, 0.1], 1 + s, 2 + s) for s in range(3)]
out = subprocess.run([sys.executable, os.path.join(tools, "pool_seeds.py"), "trials", *files,
                      "--contrast", "A", "B"], capture_output=True, text=True, check=True).stdout


def tail(t, df, n=200000):
    """P(T > t) for Student's t with df degrees of freedom (Simpson's rule on [t, 60])."""
    c = math.gamma((df + 1) / 2) / (math.sqrt(df * math.pi) * math.gamma(df / 2))
    f = lambda x: c * (1 + x * x / df) ** (-(df + 1) / 2)
    h = (60 - t) / n
    return h / 3 * sum((1 if i in (0, n) else 4 if i % 2 else 2) * f(t + i * h) for i in range(n + 1))


p = tail(1 / math.sqrt(2 / 3), 4)  # the worked value: A's mean is below B's, so "A beats B" has p = 1 - tail
expected = [
    "### share 1", "### share 0.1",
    "| B | 0,1,2 | 3 ± 1 (1) |", "| A | 0,1,2 | 2 ± 1 (2) |", "| B | 0,1,2 | 13 ± 1 (1) |",
    f"top-1: best B, second A; one-sided Welch t = 1.22, df 4.0, p = {p:.3g}",
    f"top-1: A against B; one-sided Welch t = 1.22, df 4.0, p = {1 - p:.3g}; head by head (same draws): "
    "A ahead by -1 on average, in 0 of 3, from -1 to -1",
]
missing = [e for e in expected if e not in out]
if missing:
    sys.exit("pool_seeds.py printed:\n" + out + "\nwithout:\n" + "\n".join(missing))
assert out.count("one-sided Welch") == 4, out

# Shares in only some runs: the shares every run has are pooled, and the script says so; none in
# common is an error naming each run's shares.
part = run_file(3, [1, 0.25], 0, 0)
r = subprocess.run([sys.executable, os.path.join(tools, "pool_seeds.py"), "trials", files[0], part],
                   capture_output=True, text=True, check=True).stdout
if f"{part}: label shares [1, 0.25]; pooled: [1] (the shares every run has)" not in r or "### share 0.1" in r \
        or "| A | 0,3 | 0.5 ± 0.707 (2) |" not in r:
    sys.exit(f"partly shared label shares printed:\n{r}")
bad = run_file(4, [0.25], 0, 0)
r = subprocess.run([sys.executable, os.path.join(tools, "pool_seeds.py"), "trials", files[0], bad],
                   capture_output=True, text=True)
if r.returncode == 0 or "no label share is in every run" not in r.stderr or "[0.25]" not in r.stderr:
    sys.exit(f"no common share: exit {r.returncode}, stderr {r.stderr!r}")

# A second head per seed where A leads by 3: pooled, A - B is (-1 + 3) / 2 = 1 per seed, and the
# heads' differences run from -1 to 3; --first-heads 1 gives back the one-head pooling above.
two = [run_file(s, [1, 0.1], 1 + s, 2 + s, [(5 + s, 2 + s)]) for s in range(3)]
out2 = subprocess.run([sys.executable, os.path.join(tools, "pool_seeds.py"), "trials", *two, "--contrast", "A", "B"],
                      capture_output=True, text=True, check=True).stdout
for e in ["| A | 0,1,2 | 4 ± 1 (1) |", "| B | 0,1,2 | 3 ± 1 (2) |",
          "head by head (same draws): A ahead by 1 on average, in 3 of 6, from -1 to 3"]:
    if e not in out2:
        sys.exit("pool_seeds.py (two heads) printed:\n" + out2 + "\nwithout:\n" + e)
first = subprocess.run([sys.executable, os.path.join(tools, "pool_seeds.py"), "trials", *two, "--contrast", "A", "B",
                        "--first-heads", "1"], capture_output=True, text=True, check=True).stdout
if first.replace("h.json", ".json") != out:
    sys.exit(f"--first-heads 1 printed:\n{first}\nnot the one-head runs':\n{out}")
r = subprocess.run([sys.executable, os.path.join(tools, "pool_seeds.py"), "trials", files[0], "--first-heads", "2"],
                   capture_output=True, text=True)
if r.returncode == 0 or "seed 0 has 1 heads, --first-heads 2" not in r.stderr:
    sys.exit(f"--first-heads 2 on one head: exit {r.returncode}, stderr {r.stderr!r}")

# The same seed of a row in two files: kept once when its heads are the same (the constant and the
# ridge of two runs with one command's draws), an error when they differ.
with open(files[0]) as f:
    again = json.load(f)
same = os.path.join(work, "s0_again.json")
with open(same, "w") as f:
    json.dump(again, f)
r = subprocess.run([sys.executable, os.path.join(tools, "pool_seeds.py"), "trials", files[0], same],
                   capture_output=True, text=True, check=True).stdout
alone = subprocess.run([sys.executable, os.path.join(tools, "pool_seeds.py"), "trials", files[0]],
                       capture_output=True, text=True, check=True).stdout
if "row 'A' seed 0: the same heads as in an earlier file, kept once" not in r or \
        [l for l in r.splitlines() if l.startswith("|")] != [l for l in alone.splitlines() if l.startswith("|")]:
    sys.exit(f"a repeated row with the same values printed:\n{r}\nnot the single file's table:\n{alone}")
again["tables"][0]["rows"][0]["runs"][0][0]["acc"] += 0.01
other = os.path.join(work, "s0_other.json")
with open(other, "w") as f:
    json.dump(again, f)
r = subprocess.run([sys.executable, os.path.join(tools, "pool_seeds.py"), "trials", files[0], other],
                   capture_output=True, text=True)
if r.returncode == 0 or "row 'A' seed 0 is in an earlier file too, with other values" not in r.stderr:
    sys.exit(f"a repeated row with other values: exit {r.returncode}, stderr {r.stderr!r}")
print("pool_seeds.py: ok")
