#!/usr/bin/env python3
"""What a frozen encoder's tokens keep of their own taxel's window, and of the label.

Reads the embeddings `tjepa embed --trials ...` writes ([W, N, d] .npy and its .windows.csv) and
the raw recordings they came from, and prints for each encoder, on the held-out windows (split
"test"), with ridge read-outs fitted on the training windows:
  - own level R²: token i's embedding -> the mean over frames of taxel i's window (per axis),
  - own shape R²: token i's embedding -> the rest of that window (the window minus its mean),
    averaged over the taxels;
  - one token -> label: top-1 of a ridge on one token's embedding (one-hot targets), mean over
    the tokens;
  - all tokens -> label: top-1 of a ridge on the N·d values of a window;
  - effective rank: exp(entropy) of the eigenvalues of the tokens' covariance over windows, each
    token centred on its own mean (what varies between windows, not between positions).
and the ridge on the raw windows beside them. Needs numpy (Debian's python3-numpy).

Example (FabricSlide; see docs/real_data.md):
  tools/token_info.py --columns 3:19 runs/tokinfo/random.npy runs/tokinfo/jepa.npy
"""
import argparse
import collections
import csv
import sys

import numpy as np


def fail(msg):
    sys.exit(f"token_info.py: {msg}")


def read_recording(path, columns, skip_rows, lines_per_frame):
    """[T, C] float64 of the recording's taxel columns; text as `tjepa --columns` reads it."""
    try:
        lines = open(path).read().splitlines()
    except OSError as e:
        fail(f"{path}: {e.strerror}")
    lines = [l for l in lines[skip_rows:] if l.strip()]
    if len(lines) % lines_per_frame:
        fail(f"{path}: {len(lines)} data lines is not a multiple of --lines-per-frame {lines_per_frame}")
    frames = []
    for k in range(0, len(lines), lines_per_frame):
        values = " ".join(lines[k:k + lines_per_frame]).replace(",", " ").split()
        if len(values) < columns[1]:
            fail(f"{path}:{skip_rows + k + 1}: {len(values)} values, --columns needs {columns[1]}")
        try:
            frames.append([float(v) for v in values[columns[0]:columns[1]]])
        except ValueError as e:
            fail(f"{path}:{skip_rows + k + 1}: {e}")
    return np.array(frames)


def ridge(Xtr, Ttr, Xte, lam=1e-3):
    """Ridge on standardized features (lam relative to the number of rows); predictions for Xte."""
    mu, sd = Xtr.mean(0), Xtr.std(0) + 1e-8
    A, B = (Xtr - mu) / sd, (Xte - mu) / sd
    tm = Ttr.mean(0)
    G = A.T @ A + lam * len(A) * np.eye(A.shape[1])
    return B @ np.linalg.solve(G, A.T @ (Ttr - tm)) + tm


def r2(P, T):
    return 1.0 - ((P - T) ** 2).sum() / ((T - T.mean(0)) ** 2).sum()


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("embeddings", nargs="+", help="tjepa embed outputs (.npy), each with its .windows.csv")
    ap.add_argument("--columns", required=True, help="the taxels' value columns, a:b (end exclusive), as tjepa's")
    ap.add_argument("--axes", type=int, default=1, help="axes per taxel (tjepa's --axes)")
    ap.add_argument("--skip-rows", type=int, default=1, help="header lines (tjepa's --skip-rows; default 1)")
    ap.add_argument("--lines-per-frame", type=int, default=1, help="tjepa's --lines-per-frame")
    a = ap.parse_args()
    try:
        columns = tuple(int(x) for x in a.columns.split(":"))
        assert len(columns) == 2 and 0 <= columns[0] < columns[1]
    except (ValueError, AssertionError):
        fail(f"--columns {a.columns}: expected a:b with 0 <= a < b")
    if (columns[1] - columns[0]) % a.axes:
        fail(f"--columns {a.columns}: {columns[1] - columns[0]} values is not a multiple of --axes {a.axes}")
    taxels = (columns[1] - columns[0]) // a.axes

    if not a.embeddings[0].endswith(".npy"):
        fail(f"{a.embeddings[0]}: expected a .npy")
    index = a.embeddings[0][:-4] + ".windows.csv"
    try:
        rows = list(csv.DictReader(open(index)))
    except OSError as e:
        fail(f"{index}: {e.strerror} (tjepa embed writes it beside the .npy)")
    for need in ("file", "first_frame", "frames", "label", "split"):
        if rows and need not in rows[0]:
            fail(f"{index}: no column '{need}' (written by tjepa embed --trials?)")
    for path in a.embeddings[1:]:  # every encoder's rows must be the same windows, in the same order
        if not path.endswith(".npy"):
            fail(f"{path}: expected a .npy")
        own = path[:-4] + ".windows.csv"
        try:
            other = [(r["file"], r["first_frame"]) for r in csv.DictReader(open(own))]
        except (OSError, KeyError) as e:
            fail(f"{own}: cannot read its windows ({e})")
        if other != [(r["file"], r["first_frame"]) for r in rows]:
            fail(f"{own}: not the windows of {index} (embed both with the same --trials and --stride)")
    recordings = collections.OrderedDict((r["file"], None) for r in rows)
    for f in recordings:
        recordings[f] = read_recording(f, columns, a.skip_rows, a.lines_per_frame)
    tau = int(rows[0]["frames"])
    # [W, N, τ·m]: taxel k's window, frame-major with its axes inside (the tokenizer's order)
    W = np.stack([recordings[r["file"]][int(r["first_frame"]):int(r["first_frame"]) + tau]
                  .reshape(tau, taxels, a.axes).transpose(1, 0, 2).reshape(taxels, -1) for r in rows])
    level = W.reshape(len(rows), taxels, tau, a.axes).mean(2)  # [W, N, m]
    shape = (W.reshape(len(rows), taxels, tau, a.axes) - level[:, :, None, :]).reshape(len(rows), taxels, -1)
    tr = np.array([r["split"] == "train" for r in rows])
    te = np.array([r["split"] == "test" for r in rows])
    if not tr.any() or not te.any():
        fail(f"{index}: needs windows of both splits, train and test")
    labels = sorted(set(r["label"] for r in rows))
    y = np.array([labels.index(r["label"]) for r in rows])
    Y = np.eye(len(labels))[y]

    def top1(X):
        return 100.0 * (ridge(X[tr], Y[tr], X[te]).argmax(1) == y[te]).mean()

    print(f"{len(rows)} windows ({tr.sum()} train, {te.sum()} test) of {taxels} taxels x {tau} frames x "
          f"{a.axes} axes, {len(labels)} labels")
    print(f"ridge on the raw windows -> label: top-1 {top1(W.reshape(len(rows), -1)):.1f} %")
    print("| encoder | own level R² | own shape R² | one token -> label | all tokens -> label | effective rank |")
    print("|---|---|---|---|---|---|")
    for path in a.embeddings:
        E = np.load(path, mmap_mode="r")
        if E.ndim != 3 or E.shape[0] != len(rows) or E.shape[1] != taxels:
            fail(f"{path}: shape {E.shape}, expected [{len(rows)}, {taxels}, d] as {index}")
        lev, shp, one = [], [], []
        for i in range(taxels):
            X = np.asarray(E[:, i, :], dtype=np.float64)
            lev.append(r2(ridge(X[tr], level[tr, i], X[te]), level[te, i]))
            shp.append(r2(ridge(X[tr], shape[tr, i], X[te]), shape[te, i]))
            one.append(top1(X))
        allt = top1(np.asarray(E, dtype=np.float64).reshape(len(rows), -1))
        S = np.asarray(E[::max(1, len(rows) // 20000)], dtype=np.float64)
        S = (S - S.mean(0)).reshape(-1, E.shape[2])
        ev = np.clip(np.linalg.eigvalsh(S.T @ S / len(S)), 0, None)
        p = ev / ev.sum()
        erank = float(np.exp(-(p[p > 0] * np.log(p[p > 0])).sum()))
        print(f"| {path} | {np.mean(lev):.3f} | {np.mean(shp):.3f} | {np.mean(one):.1f} % | {allt:.1f} % | "
              f"{erank:.1f} / {E.shape[2]} |")


if __name__ == "__main__":
    main()
