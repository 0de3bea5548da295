#!/usr/bin/env python3
"""Pools one table of several `tjepa eval` runs (results.json) over their pre-training seeds.

    tools/pool_seeds.py TABLE RESULTS.json [RESULTS.json ...] [--rows NAME ...] [--contrast ROW AGAINST]
                        [--first-heads K]

TABLE is main, ablation, linear or ablation_linear, or trials for `tjepa eval --trials` runs (each
label share's table pooled on its own, for the shares every run has). Rows are matched by
name; each run's seeds come from its config ("seeds"; a run stopped early holds its first seeds,
and the script says so), and a seed found in two runs of the same row is an error. For each
primary metric: the heads' mean per seed, then mean ± sample sd over seeds, the rank of each row,
and the one-sided Welch test of the best row against the second (as downstream/welch.hpp: the
best's mean is better), and of each --contrast pair (ROW better than AGAINST). For a contrast
whose rows have the same heads, also the paired differences head by head (in `tjepa eval --trials`
a head seed draws the labelled trials, the same for every row): their mean, how many favour ROW,
their range. --first-heads K keeps each seed's first K heads (K 1 pools runs of one head with the
first head of runs of several: the same draws). Writes markdown on stdout. Pool only runs whose heads were trained alike: the script cannot tell (it prints each
run's command).
"""
import argparse
import json
import math
import sys


def incomplete_beta(a, b, x):
    """Regularized incomplete beta I_x(a, b) (continued fraction, Numerical Recipes)."""
    if x <= 0:
        return 0.0
    if x >= 1:
        return 1.0

    def cf(a, b, x):
        tiny = 1e-300
        qab, qap, qam = a + b, a + 1, a - 1
        c, d = 1.0, 1 - qab * x / qap
        d = 1 / (d if abs(d) > tiny else tiny)
        h = d
        for m in range(1, 300):
            m2 = 2 * m
            for aa in (m * (b - m) * x / ((qam + m2) * (a + m2)), -(a + m) * (qab + m) * x / ((a + m2) * (qap + m2))):
                d = 1 + aa * d
                d = 1 / (d if abs(d) > tiny else tiny)
                c = 1 + aa / c
                c = c if abs(c) > tiny else tiny
                h *= d * c
            if abs(d * c - 1) < 3e-16:
                break
        return h

    front = math.exp(math.lgamma(a + b) - math.lgamma(a) - math.lgamma(b) + a * math.log(x) + b * math.log(1 - x))
    return front * cf(a, b, x) / a if x < (a + 1) / (a + b + 2) else 1 - front * cf(b, a, 1 - x) / b


def welch_less(a, b):
    """One-sided Welch test of mean(a) < mean(b): (t, df, p)."""
    na, nb = len(a), len(b)
    ma, mb = sum(a) / na, sum(b) / nb
    va = sum((x - ma) ** 2 for x in a) / (na - 1) / na
    vb = sum((x - mb) ** 2 for x in b) / (nb - 1) / nb
    if va + vb == 0:
        return (0.0 if ma == mb else math.copysign(math.inf, ma - mb)), na + nb - 2, 0.5 if ma == mb else float(ma > mb)
    t = (ma - mb) / math.sqrt(va + vb)
    df = (va + vb) ** 2 / (va * va / (na - 1) + vb * vb / (nb - 1))
    tail = 0.5 * incomplete_beta(df / 2, 0.5, df / (df + t * t))  # P(T > |t|)
    return t, df, (tail if t < 0 else 1 - tail)


def pool(runs, args):
    """Pools one table of several runs: runs is a list of (path, command, seeds, table)."""
    metrics, rows, heads_of, order = None, {}, {}, []
    for path, command, seeds, table in runs:
        metrics = metrics or [m for m in table["metrics"] if m["primary"]]
        print(f"- {path}: `{command}`")
        for row in table["rows"]:
            if args.rows and row["name"] not in args.rows:
                continue
            if len(row["runs"]) > len(seeds):
                sys.exit(f"{path}: row '{row['name']}' has {len(row['runs'])} runs for {len(seeds)} seeds")
            if len(row["runs"]) < len(seeds):
                # tjepa eval runs the seeds in order and writes results.json after each: a stopped
                # run holds its first seeds.
                print(f"  - row '{row['name']}': {len(row['runs'])} of {len(seeds)} seeds (a stopped run): "
                      f"seeds {', '.join(str(x) for x in seeds[:len(row['runs'])])}")
            mine = rows.setdefault(row["name"], {})
            if row["name"] not in order:
                order.append(row["name"])
            for seed, heads in zip(seeds, row["runs"]):
                if args.first_heads:
                    if len(heads) < args.first_heads:
                        sys.exit(f"{path}: row '{row['name']}' seed {seed} has {len(heads)} heads, "
                                 f"--first-heads {args.first_heads}")
                    heads = heads[:args.first_heads]
                if seed in mine:
                    # The references (constant, ridge on raw windows) come out of every run alike:
                    # the same seed and heads give the same values, kept once.
                    if heads_of[row["name"]][seed] == heads:
                        print(f"  - row '{row['name']}' seed {seed}: the same heads as in an earlier file, kept once")
                        continue
                    sys.exit(f"{path}: row '{row['name']}' seed {seed} is in an earlier file too, with other values")
                mine[seed] = {m["key"]: sum(h[m["key"]] for h in heads) / len(heads) for m in metrics}
                heads_of.setdefault(row["name"], {})[seed] = heads
    names = args.rows or order
    for n in names + [n for pair in args.contrast or [] for n in pair]:
        if n not in rows:
            sys.exit(f"no row '{n}' (rows: {', '.join(order)})")

    # results.json keeps shares as fractions; a metric whose unit is % is printed in %.
    scale = {m["key"]: 100.0 if m.get("unit") == "%" else 1.0 for m in metrics}

    def values(name, key):
        return [scale[key] * rows[name][s][key] for s in sorted(rows[name])]

    def mean(v):
        return sum(v) / len(v)

    def test(m, better, worse):
        """One-sided Welch test that row better's mean beats row worse's in metric m."""
        a, b = values(better, m["key"]), values(worse, m["key"])
        if len(a) < 2 or len(b) < 2:
            return "not tested (fewer than 2 seeds)"
        if m["higher_is_better"]:
            a, b = [-x for x in a], [-x for x in b]
        t, df, p = welch_less(a, b)
        return f"one-sided Welch t = {abs(t):.2f}, df {df:.1f}, p = {p:.3g}"

    def paired(m, better, worse):
        """The head-by-head differences of two rows with the same seeds and heads, or ""."""
        a, b = heads_of[better], heads_of[worse]
        if sorted(a) != sorted(b) or any(len(a[s]) != len(b[s]) for s in a):
            return ""
        sign = 1 if m["higher_is_better"] else -1
        d = [sign * scale[m["key"]] * (x[m["key"]] - y[m["key"]]) for s in sorted(a) for x, y in zip(a[s], b[s])]
        return (f"; head by head (same draws): {better} ahead by {mean(d):.4g} on average, "
                f"in {sum(x > 0 for x in d)} of {len(d)}, from {min(d):.4g} to {max(d):.4g}")

    print()
    print("| row | seeds | " + " | ".join(f"{m['name']} ({m['unit']}) {'↑' if m['higher_is_better'] else '↓'}" for m in metrics) + " |")
    print("|---|---|" + "---|" * len(metrics))
    ranks = {}
    for m in metrics:
        sign = -1 if m["higher_is_better"] else 1
        ranked = sorted(names, key=lambda n: sign * mean(values(n, m["key"])))
        ranks[m["key"]] = {n: i + 1 for i, n in enumerate(ranked)}
    for n in names:
        cells = []
        for m in metrics:
            v = values(n, m["key"])
            sd = f" ± {math.sqrt(sum((x - mean(v)) ** 2 for x in v) / (len(v) - 1)):.3g}" if len(v) > 1 else ""
            cells.append(f"{mean(v):.4g}{sd} ({ranks[m['key']][n]})")
        print(f"| {n} | {','.join(str(s) for s in sorted(rows[n]))} | " + " | ".join(cells) + " |")
    print()
    for m in metrics:
        if len(names) >= 2:
            best, second = sorted(names, key=lambda n: ranks[m["key"]][n])[:2]
            print(f"- {m['name']}: best {best}, second {second}; {test(m, best, second)}")
        for row, against in args.contrast or []:
            print(f"- {m['name']}: {row} against {against}; {test(m, row, against)}{paired(m, row, against)}")


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("table", choices=["main", "ablation", "linear", "ablation_linear", "trials"])
    ap.add_argument("results", nargs="+")
    ap.add_argument("--rows", nargs="*", help="only these rows, in this order")
    ap.add_argument("--contrast", nargs=2, action="append", metavar=("ROW", "AGAINST"),
                    help="also test that ROW beats AGAINST (one-sided Welch), per metric")
    ap.add_argument("--first-heads", type=int, metavar="K", help="keep each seed's first K heads")
    args = ap.parse_args()
    if args.first_heads is not None and args.first_heads < 1:
        sys.exit(f"--first-heads {args.first_heads}: must be at least 1")

    runs = []
    for path in args.results:
        with open(path) as f:
            runs.append((path, json.load(f)))
    if args.table != "trials":
        tables = []
        for path, run in runs:
            if run.get(args.table) is None:
                sys.exit(f"{path}: no table '{args.table}'")
            tables.append((path, run.get("command", "?"), run["config"]["seeds"], run[args.table]))
        return pool(tables, args)
    # tjepa eval --trials: one table per label share, matched by share across the runs; the shares
    # every run has are pooled (a run of --label-fractions 0.1 beside one of 1 0.1 0.03: the 10 %).
    for path, run in runs:
        if "tables" not in run or "label_fractions" not in run:
            sys.exit(f"{path}: not the results of tjepa eval --trials (no 'tables')")
    first = runs[0][1]["label_fractions"]
    shares = [f for f in first if all(f in run["label_fractions"] for _, run in runs)]
    if not shares:
        listing = "; ".join(f"{path}: {run['label_fractions']}" for path, run in runs)
        sys.exit(f"no label share is in every run: {listing}")
    for path, run in runs:
        if run["label_fractions"] != shares:
            print(f"- {path}: label shares {run['label_fractions']}; pooled: {shares} (the shares every run has)")
    for f in shares:
        print(f"\n### {runs[0][1]['tables'][first.index(f)]['title']}\n")
        pool([(path, run.get("command", "?"), run["seeds"], run["tables"][run["label_fractions"].index(f)])
              for path, run in runs], args)

if __name__ == "__main__":
    main()
