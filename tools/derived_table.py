#!/usr/bin/env python3
"""Rewrites a trial table's CSV recordings into derived ones, for the experiments of
docs/real_data.md ("Space-time targets, and where FabricSlide's classes are"):

--chunks C --chunk-frames L  space-time tokens: each token is one taxel over L frames, so masks hide
    and predict (taxel, time chunk) pairs over a space-time graph instead of whole taxels. Frame s
    of a written recording holds, for chunk c = 0..C-1, frame s + c*L of the source, taxel by
    taxel: taxel c*N + i is taxel i's chunk c, and a window of L written frames is a window of C*L
    source frames. Needs --layout and --edges (`tjepa layout FILE --export`): the layout written
    has C copies of the taxels (ids c*N + id, x shifted by 10 edge lengths a chunk, part and group
    kept, row and col dropped); the edges are the source's inside every chunk plus taxel i's chunk
    c to its chunk c + 1 (the shortest edge's weight).
--difference  first differences: frame s is frame s + 1 minus frame s of the source, taxel by taxel
    (each taxel's level removed, its changes kept).

  tjepa layout tests/data/fabricslide/layout.csv --export runs/fab.csv      # + runs/fab.edges.csv
  tools/derived_table.py --table runs/fabric_val_f150.csv --columns 3:19 --layout runs/fab.csv \\
      --edges runs/fab.edges.csv --chunks 2 --chunk-frames 5 --out runs/st2_val
  tjepa eval --trials runs/st2_val/table.csv --layout runs/st2_val/layout.csv \\
      --edges runs/st2_val/edges.csv --axes 1 --columns 0:32 --tau 5 ...
  tools/derived_table.py --table runs/fabric_val_f150.csv --columns 3:19 --difference --out runs/diff_val
  tjepa eval --trials runs/diff_val/table.csv --layout tests/data/fabricslide/layout.csv --axes 1 --columns 0:16 ...

Recordings: CSV with one header line, one frame a line, --columns A:B the taxels (one axis each),
written as out/data/<name> with out/table.csv naming them (labels, splits and groups kept). A trial
too short for the transform, a short line or a value that is not a number is an error naming the
file and the line.
"""
import argparse
import csv
import os
import sys


def fail(msg):
    sys.exit(f"derived_table: {msg}")


def read_csv(path):
    try:
        with open(path, newline="") as f:
            return [r for r in csv.reader(f)]
    except OSError as e:
        fail(f"{path}: {e.strerror}")


def writer(f):
    return csv.writer(f, lineterminator="\n")


def space_time_graph(a, N, out):
    """Writes out/layout.csv and out/edges.csv: C copies of the layout, joined chunk to chunk."""
    lay = read_csv(a.layout)
    head = lay[0]
    for k in ("id", "x", "y"):
        if k not in head:
            fail(f"{a.layout}:1: no '{k}' column (write it with tjepa layout --export)")
    ids = []
    for n, r in enumerate(lay[1:], 2):
        try:
            ids.append(int(dict(zip(head, r))["id"]))
        except (KeyError, ValueError):
            fail(f"{a.layout}:{n}: expected an integer id")
    if sorted(ids) != list(range(N)):
        fail(f"{a.layout}: expected the ids 0..{N - 1}, one a taxel of --columns {a.columns}")
    edges = read_csv(a.edges)
    if edges[0][:2] != ["src", "dst"]:
        fail(f"{a.edges}:1: expected the header src,dst[,weight]")
    by_src = [[] for _ in range(N)]
    for n, r in enumerate(edges[1:], 2):
        try:
            by_src[int(r[0])].append((int(r[1]), r[2:3]))
        except (ValueError, IndexError):
            fail(f"{a.edges}:{n}: expected src,dst[,weight] with ids 0..{N - 1}")
    step = min((float(r[2]) for r in edges[1:] if len(r) > 2), default=1.0)
    keep = [k for k in head if k in ("id", "x", "y", "z", "part", "group")]
    C = a.chunks
    with open(os.path.join(out, "layout.csv"), "w", newline="") as f:
        w = writer(f)
        w.writerow(keep)
        for c in range(C):
            for r in lay[1:]:
                row = dict(zip(head, r))
                row["id"] = str(c * N + int(row["id"]))
                row["x"] = f"{float(row['x']) + c * 10 * step:g}"
                w.writerow([row[k] for k in keep])
    with open(os.path.join(out, "edges.csv"), "w", newline="") as f:
        w = writer(f)
        w.writerow(["src", "dst", "weight"])
        for c in range(C):
            for i in range(N):
                for j, weight in by_src[i]:
                    w.writerow([c * N + i, c * N + j] + weight)
                if c + 1 < C:
                    w.writerow([c * N + i, (c + 1) * N + i, f"{step:g}"])


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--table", required=True, help="trial table: file,label[,split][,group]")
    ap.add_argument("--columns", required=True, help="A:B, the recordings' taxel columns")
    ap.add_argument("--out", required=True, help="folder: table.csv and data/ (and layout.csv, edges.csv)")
    ap.add_argument("--chunks", type=int, help="C >= 2, time chunks a window is cut into")
    ap.add_argument("--chunk-frames", type=int, help="L >= 1, frames a chunk")
    ap.add_argument("--layout", help="layout CSV with id,x,y (tjepa layout --export), for --chunks")
    ap.add_argument("--edges", help="its edges CSV src,dst[,weight], for --chunks")
    ap.add_argument("--difference", action="store_true", help="first differences in time")
    a = ap.parse_args()
    try:
        lo, hi = (int(x) for x in a.columns.split(":"))
    except ValueError:
        fail(f"--columns {a.columns}: expected A:B")
    if not 0 <= lo < hi:
        fail(f"--columns {a.columns}: expected 0 <= A < B")
    N = hi - lo
    if a.difference == (a.chunks is not None):
        fail("give either --difference or --chunks (with --chunk-frames, --layout, --edges)")
    if a.chunks is not None:
        if a.chunks < 2 or a.chunk_frames is None or a.chunk_frames < 1 or not a.layout or not a.edges:
            fail("--chunks C needs C >= 2, --chunk-frames L >= 1, --layout and --edges")
        C, L = a.chunks, a.chunk_frames
        need, header = (C - 1) * L + 1, [f"t{c}_{i}" for c in range(C) for i in range(N)]
    else:
        if a.chunk_frames is not None or a.layout or a.edges:
            fail("--chunk-frames, --layout and --edges apply to --chunks only")
        need, header = 2, [f"d{i}" for i in range(N)]
    os.makedirs(os.path.join(a.out, "data"), exist_ok=True)
    if a.chunks is not None:
        space_time_graph(a, N, a.out)

    table = read_csv(a.table)
    base = os.path.dirname(os.path.abspath(a.table))
    with open(os.path.join(a.out, "table.csv"), "w", newline="") as f:
        w = writer(f)
        w.writerow(table[0])
        for r in table[1:]:
            src = os.path.normpath(os.path.join(base, r[0]))
            rows = read_csv(src)[1:]
            if len(rows) < need:
                fail(f"{src}: {len(rows)} frames, fewer than the {need} the transform needs")
            vals = []
            for n, x in enumerate(rows, 2):
                if len(x) < hi:
                    fail(f"{src}:{n}: {len(x)} columns, --columns {a.columns} needs {hi}")
                vals.append([v.strip() for v in x[lo:hi]])
            name = os.path.basename(src)
            with open(os.path.join(a.out, "data", name), "w", newline="") as g:
                cw = writer(g)
                cw.writerow(header)
                if a.chunks is not None:
                    for s in range(len(vals) - (C - 1) * L):
                        cw.writerow([v for c in range(C) for v in vals[s + c * L]])
                else:
                    num = []
                    for n, x in enumerate(vals, 2):
                        try:
                            num.append([float(v) for v in x])
                        except ValueError:
                            fail(f"{src}:{n}: a value of --columns {a.columns} is not a number")
                    for s in range(1, len(num)):
                        cw.writerow([f"{num[s][i] - num[s - 1][i]:g}" for i in range(N)])
            w.writerow([os.path.join("data", name)] + r[1:])
    print(f"wrote {a.out}/table.csv ({len(table) - 1} trials) and data/"
          + (f", layout.csv ({a.chunks * N} taxels), edges.csv" if a.chunks is not None else ""))


if __name__ == "__main__":
    main()
