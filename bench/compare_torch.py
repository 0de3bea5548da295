#!/usr/bin/python3
"""PyTorch side of tjepa's side-by-side benchmarks (Debian's python3-torch, CPU, fp32).

The model is written with plain nn modules and manual attention (softmax(QK^T/sqrt(d))V), the way
the reference ViT-Tiny does it, so the numbers measure what a PyTorch user of the reference code
gets on this machine. Never a dependency of the library or its tests.

    OMP_WAIT_POLICY=PASSIVE OPENBLAS_NUM_THREADS=1 /usr/bin/python3 bench/compare_torch.py --threads 1
prints one JSON object per benchmark: {"name", "threads", "ms" (median), "gflop", "gflops"}.
"""
import argparse
import json
import math
import time

import torch
import torch.nn as nn
import torch.nn.functional as F

D, HEADS, DEPTH, MLP = 192, 3, 12, 4


class Attention(nn.Module):
    def __init__(self, d=D, heads=HEADS):
        super().__init__()
        self.heads, self.scale = heads, (d // heads) ** -0.5
        self.qkv = nn.Linear(d, 3 * d)
        self.proj = nn.Linear(d, d)

    def forward(self, x):
        B, L, C = x.shape
        qkv = self.qkv(x).reshape(B, L, 3, self.heads, C // self.heads).permute(2, 0, 3, 1, 4)
        q, k, v = qkv[0], qkv[1], qkv[2]
        a = (q @ k.transpose(-2, -1)) * self.scale
        a = a.softmax(dim=-1)
        return self.proj((a @ v).transpose(1, 2).reshape(B, L, C))


class Block(nn.Module):
    def __init__(self, d=D):
        super().__init__()
        self.norm1, self.attn = nn.LayerNorm(d, eps=1e-6), Attention(d)
        self.norm2 = nn.LayerNorm(d, eps=1e-6)
        self.fc1, self.fc2 = nn.Linear(d, MLP * d), nn.Linear(MLP * d, d)

    def forward(self, x):
        x = x + self.attn(self.norm1(x))
        return x + self.fc2(F.gelu(self.fc1(self.norm2(x))))


class Encoder(nn.Module):
    def __init__(self, depth=DEPTH, d=D):
        super().__init__()
        self.blocks = nn.ModuleList([Block(d) for _ in range(depth)])
        self.norm = nn.LayerNorm(d, eps=1e-6)

    def forward(self, x):
        for b in self.blocks:
            x = b(x)
        return self.norm(x)


def encoder_gflop(L, B=1, depth=DEPTH, d=D):
    """Matmul FLOPs of a forward pass: 24 L d^2 (qkv, proj, fc1, fc2) + 4 L^2 d (QK^T, PV) per block."""
    return B * depth * (24 * L * d * d + 4 * L * L * d) / 1e9


def attention_gflop(L, B=1, d=D):
    return B * 4 * L * L * d / 1e9


def timeit(fn, min_time=2.0, min_reps=3):
    fn()  # warm-up
    times = []
    start = time.perf_counter()
    while len(times) < min_reps or time.perf_counter() - start < min_time:
        t0 = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t0)
    times.sort()
    return times[len(times) // 2] * 1e3


def manual_attention(q, k, v):
    a = (q @ k.transpose(-2, -1)) * (q.shape[-1] ** -0.5)
    return a.softmax(dim=-1) @ v


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--threads", type=int, default=1)
    ap.add_argument("--min-time", type=float, default=2.0)
    args = ap.parse_args()
    torch.set_num_threads(args.threads)
    torch.manual_seed(0)
    out = []

    def emit(name, ms, gflop):
        rec = {"name": name, "threads": args.threads, "ms": round(ms, 3), "gflop": round(gflop, 4),
               "gflops": round(gflop / (ms / 1e3), 2)}
        out.append(rec)
        print(json.dumps(rec), flush=True)

    enc = Encoder().eval()
    for L in (368, 528, 2124):
        x = torch.randn(1, L, D)
        with torch.no_grad():
            emit(f"encoder_forward/B1/L{L}", timeit(lambda: enc(x), args.min_time), encoder_gflop(L))

    train = Encoder().train()
    x = torch.randn(8, 368, D)
    target = torch.randn(8, 368, D)

    def step():
        train.zero_grad(set_to_none=False)
        loss = F.mse_loss(train(x), target)
        loss.backward()

    emit("train_step/B8/L368", timeit(step, args.min_time), 3 * encoder_gflop(368, B=8))

    for B in (1, 8):
        for L in (368, 528, 2124):
            q, k, v = (torch.randn(B, HEADS, L, D // HEADS) for _ in range(3))
            with torch.no_grad():
                emit(f"attention_forward/B{B}/L{L}", timeit(lambda: manual_attention(q, k, v), args.min_time),
                     attention_gflop(L, B))
            qg, kg, vg = (t.clone().requires_grad_(True) for t in (q, k, v))
            w = torch.randn(B, HEADS, L, D // HEADS)

            def fb():
                for t in (qg, kg, vg):
                    t.grad = None
                (manual_attention(qg, kg, vg) * w).sum().backward()

            emit(f"attention_forward_backward/B{B}/L{L}", timeit(fb, args.min_time), 3.5 * attention_gflop(L, B))


if __name__ == "__main__":
    main()
