#!/usr/bin/python3
"""PyTorch side of tjepa's side-by-side benchmarks (Debian's python3-torch, CPU, fp32).

The model is written with plain nn modules and manual attention (softmax(QK^T/sqrt(d))V), the way
the reference ViT-Tiny does it, so the numbers measure what a PyTorch user of the reference code
gets on this machine. Never a dependency of the library or its tests.

    OMP_WAIT_POLICY=PASSIVE OPENBLAS_NUM_THREADS=1 /usr/bin/python3 bench/compare_torch.py --threads 1
prints one JSON object per benchmark: {"name", "threads", "ms" (median), "gflop", "gflops"}, the
JEPA steps also "windows_per_s"; first a line {"info": "torch", ...} naming the BLAS library that ran.

The whole Tactile-JEPA pre-training step (jepa_step/<N>) is written the way I-JEPA-style reference
code runs it: tokenizer + position table on all N tokens, the context
encoder on the gathered K context tokens, the target encoder (the EMA copy, train mode, no grad) on
all N tokens with its final LayerNorm, the predictor once per target size with the context repeated
per target, MSE per target averaged over the targets, backward, clip_grad_norm_(10), AdamW, EMA.
Fixed random masks of the sizes tjepa's MaskCollator draws in BM_JepaTrainStep(Deco) (bench/train.cpp).
"""
import argparse
import copy
import json
import math
import os
import sys
import time

import torch
import torch.nn as nn
import torch.nn.functional as F

D, HEADS, DEPTH, MLP = 192, 3, 12, 4


class Attention(nn.Module):
    def __init__(self, d=D, heads=HEADS, bias=True):
        super().__init__()
        self.heads, self.scale = heads, (d // heads) ** -0.5
        self.qkv = nn.Linear(d, 3 * d, bias=bias)
        self.proj = nn.Linear(d, d, bias=bias)

    def forward(self, x):
        B, L, C = x.shape
        qkv = self.qkv(x).reshape(B, L, 3, self.heads, C // self.heads).permute(2, 0, 3, 1, 4)
        q, k, v = qkv[0], qkv[1], qkv[2]
        a = (q @ k.transpose(-2, -1)) * self.scale
        a = a.softmax(dim=-1)
        return self.proj((a @ v).transpose(1, 2).reshape(B, L, C))


class AttentiveProbe(nn.Module):
    """V-JEPA's AttentivePooler (one learned query, one CrossAttentionBlock) and the 2-layer MLP head
    of the paper's Sec. IV-B, as bench/model.cpp's BM_ProbeTrainStep builds it: keys and values
    projected for every token, as the reference does."""

    def __init__(self, d=D, heads=HEADS, out=16):
        super().__init__()
        self.heads = heads
        self.query_tokens = nn.Parameter(torch.randn(1, 1, d) * 0.02)
        self.norm1 = nn.LayerNorm(d, eps=1e-6)
        self.q = nn.Linear(d, d)
        self.kv = nn.Linear(d, 2 * d)
        self.proj = nn.Linear(d, d)
        self.norm2 = nn.LayerNorm(d, eps=1e-6)
        self.mlp = nn.Sequential(nn.Linear(d, MLP * d), nn.GELU(), nn.Linear(MLP * d, d))
        self.head = nn.Sequential(nn.Linear(d, d), nn.GELU(), nn.Linear(d, out))

    def forward(self, x):
        B, L, C = x.shape
        q0 = self.query_tokens.expand(B, -1, -1)
        q = self.q(q0).reshape(B, 1, self.heads, C // self.heads).transpose(1, 2)
        kv = self.kv(self.norm1(x)).reshape(B, L, 2, self.heads, C // self.heads).permute(2, 0, 3, 1, 4)
        q1 = q0 + self.proj(manual_attention(q, kv[0], kv[1]).transpose(1, 2).reshape(B, 1, C))
        q2 = q1 + self.mlp(self.norm2(q1))
        return self.head(q2[:, 0])


def probe_gflop(B, L, to_tokens, d=D):
    """The reference's matmul FLOPs of one probe training step: the k/v projection 4 L d^2 per window
    forward, as much again for its weight gradient and, to the tokens, once more (the query's row,
    the attention and the MLPs are O(d^2) per window and not counted)."""
    return B * (3 if to_tokens else 2) * 4 * L * d * d / 1e9


def drop_path(x, p):
    """timm's stochastic depth: each sample's branch kept with probability 1 - p, scaled by 1/(1 - p)."""
    keep = 1.0 - p
    mask = x.new_empty((x.shape[0],) + (1,) * (x.ndim - 1)).bernoulli_(keep).div_(keep)
    return x * mask


def drop_add_residual_subset(x, branch, p):
    """DINOv2's drop_add_residual_stochastic_depth (its Block in training at rate > 0.1): the branch
    runs only on a random subset of max(int(B (1 - p)), 1) samples and is added back scaled by B/subset."""
    b = x.shape[0]
    n = max(int(b * (1 - p)), 1)
    idx = torch.randperm(b)[:n]
    r = branch(x[idx])
    return torch.index_add(x.flatten(1), 0, idx, r.flatten(1), alpha=b / n).view_as(x)


class Block(nn.Module):
    """Pre-norm ViT block; drop_path > 0 in training: timm-style per-sample stochastic depth
    (style "timm": the branch is computed for every sample and multiplied by the keep mask) or the
    reference's DINOv2 NestedTensorBlock (style "dinov2": at rates > 0.1 computed on a subset)."""

    def __init__(self, d=D, bias=True, drop_path=0.0, style="timm"):
        super().__init__()
        self.norm1, self.attn = nn.LayerNorm(d, eps=1e-6), Attention(d, bias=bias)
        self.norm2 = nn.LayerNorm(d, eps=1e-6)
        self.fc1, self.fc2 = nn.Linear(d, MLP * d, bias=bias), nn.Linear(MLP * d, d, bias=bias)
        self.drop_path, self.style = drop_path, style

    def attn_branch(self, x):
        return self.attn(self.norm1(x))

    def mlp_branch(self, x):
        return self.fc2(F.gelu(self.fc1(self.norm2(x))))

    def forward(self, x):
        p = self.drop_path if self.training else 0.0
        if p > 0.1 and self.style == "dinov2":
            x = drop_add_residual_subset(x, self.attn_branch, p)
            return drop_add_residual_subset(x, self.mlp_branch, p)
        if p > 0.0:
            x = x + drop_path(self.attn_branch(x), p)
            return x + drop_path(self.mlp_branch(x), p)
        x = x + self.attn_branch(x)
        return x + self.mlp_branch(x)


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


# --- The whole Tactile-JEPA pre-training step -------------------------------------------------------

PRED_DEPTH = 4


def deco50_group_sizes():
    """DECO-50's 528 tokens (bench/model.cpp BM_TokenizerGrouped): per hand 252 2x2 groups of 4 taxels
    and the six 3x3 regions split into 4 + 5 (2124 taxels)."""
    sizes = []
    for _hand in range(2):
        sizes += [4] * 252
        for _region in range(6):
            sizes += [4, 5]
    return sizes


class TaxelTokenizer(nn.Module):
    """Per taxel (the paper's eq. 1, Sec. III-B; tjepa's Tokenizer::per_taxel): one affine map
    R^{m·tau} -> R^d shared by all taxels, then LayerNorm."""

    def __init__(self, width, d=D):
        super().__init__()
        self.proj, self.norm = nn.Linear(width, d), nn.LayerNorm(d, eps=1e-6)

    def forward(self, x):  # [B, N, m·tau]
        return self.norm(self.proj(x))


class GroupedTokenizer(nn.Module):
    """Grouped (DECO-50, tjepa's Tokenizer::grouped, the reference's DecoHypertaxelTokenizer "direct"):
    one Linear(n·k -> d) + LayerNorm per group size n on the first n·k values of a group's row."""

    def __init__(self, group_sizes, k, d=D):
        super().__init__()
        self.k = k
        self.sizes = sorted(set(group_sizes))
        self.maps = nn.ModuleDict({str(n): nn.Sequential(nn.Linear(n * k, d), nn.LayerNorm(d, eps=1e-6))
                                   for n in self.sizes})
        order = []
        for n in self.sizes:
            idx = [g for g, s in enumerate(group_sizes) if s == n]
            self.register_buffer(f"idx{n}", torch.tensor(idx))
            order += idx
        self.register_buffer("inverse", torch.argsort(torch.tensor(order)))

    def forward(self, x):  # [B, G, n_max·k], padded
        parts = [self.maps[str(n)](x[:, getattr(self, f"idx{n}"), : n * self.k]) for n in self.sizes]
        return torch.cat(parts, dim=1)[:, self.inverse]


def gather_tokens(x, idx):
    """x [B, N, C], idx [B, n] -> [B, n, C] (the reference's apply_masks)."""
    return torch.gather(x, 1, idx.unsqueeze(-1).expand(-1, -1, x.shape[-1]))


class JepaEncoder(nn.Module):
    """Tokenizer, learned position table, 12 blocks with drop-path, final LayerNorm."""

    def __init__(self, tokenizer, N, drop=0.3, style="timm", depth=DEPTH, d=D):
        super().__init__()
        self.tokenizer = tokenizer
        self.pos_embed = nn.Parameter(torch.zeros(1, N, d))
        nn.init.trunc_normal_(self.pos_embed, std=0.02)
        self.blocks = nn.ModuleList([Block(d, True, drop, style) for _ in range(depth)])
        self.norm = nn.LayerNorm(d, eps=1e-6)

    def forward(self, x, keep=None):
        t = self.tokenizer(x) + self.pos_embed
        if keep is not None:
            t = gather_tokens(t, keep)
        for b in self.blocks:
            t = b(t)
        return self.norm(t)


class JepaPredictor(nn.Module):
    """The reference's SignalJEPAPredictor: input projection, the context repeated once per target
    ("(p b)"), mask token + the given (target encoder's) position rows at the targets, 4 blocks without
    biases, LayerNorm, output projection at the target rows."""

    def __init__(self, depth=PRED_DEPTH, d=D):
        super().__init__()
        self.input_projection = nn.Linear(d, d)
        self.mask_token = nn.Parameter(torch.zeros(1, 1, d))
        self.blocks = nn.ModuleList([Block(d, bias=False) for _ in range(depth)])
        self.norm = nn.LayerNorm(d, eps=1e-6)
        self.output_projection = nn.Linear(d, d)

    def forward(self, z, pos, masks):  # z [B, K, d], pos [1, N, d], masks [p, B, t]
        p, B, _ = masks.shape
        K = z.shape[1]
        x = self.input_projection(z).repeat(p, 1, 1)
        pos = pos.expand(B, -1, -1)
        tokens = torch.cat([gather_tokens(pos, m) for m in masks], dim=0) + self.mask_token
        x = torch.cat([x, tokens], dim=1)
        for b in self.blocks:
            x = b(x)
        return self.output_projection(self.norm(x)[:, K:])  # [(p B), t, d]


def sample_masks(B, N, K, target_sizes, gen):
    """Fixed masks of tjepa's sizes: per sample K context and t_j target token ids (random, sorted)."""
    ctx = torch.stack([torch.randperm(N, generator=gen)[:K].sort().values for _ in range(B)])
    targets = [torch.stack([torch.randperm(N, generator=gen)[:t].sort().values for _ in range(B)])
               for t in target_sizes]
    return ctx, targets


class JepaStep:
    """One optimizer step of Tactile-JEPA (the paper's Sec. III-B and IV-D) in plain PyTorch."""

    def __init__(self, tokenizer, N, drop, style, total_steps=50000):
        self.context = JepaEncoder(tokenizer, N, drop, style).train()
        self.target = copy.deepcopy(self.context).train()
        self.target.requires_grad_(False)
        self.predictor = JepaPredictor().train()
        params = [p for m in (self.context, self.predictor) for p in m.parameters()]
        self.params = params
        self.opt = torch.optim.AdamW([{"params": [p for p in params if p.dim() >= 2]},
                                      {"params": [p for p in params if p.dim() < 2], "weight_decay": 0.0,
                                       "WD_exclude": True}], lr=1e-4, betas=(0.9, 0.999), eps=1e-8)
        self.total, self.s = total_steps, 0

    def schedule(self):
        """Cosine learning rate and weight decay, momentum linear 0.994 -> 1 (their cost only)."""
        c = 0.5 * (1 + math.cos(math.pi * min(self.s / self.total, 1.0)))
        for g in self.opt.param_groups:
            g["lr"] = 1e-6 + (1e-4 - 1e-6) * c
            if not g.get("WD_exclude"):
                g["weight_decay"] = 0.4 + (0.04 - 0.4) * c
        return 0.994 + (1.0 - 0.994) * self.s / self.total

    def __call__(self, x, ctx, targets):
        self.opt.zero_grad(set_to_none=True)
        with torch.no_grad():
            h = self.target(x)  # [B, N, d], after the target encoder's final LayerNorm
        z = self.context(x, ctx)  # [B, K, d]
        by_size = {}
        for m in targets:
            by_size.setdefault(m.shape[-1], []).append(m)
        losses = []
        for same in by_size.values():  # the predictor batches the targets of one size
            masks = torch.stack(same)  # [p, B, t]
            pred = self.predictor(z, self.target.pos_embed, masks)
            y = torch.cat([gather_tokens(h, m) for m in masks], dim=0)
            losses.append(F.mse_loss(pred, y, reduction="none").view(len(same), -1).mean(dim=1))
        loss = torch.cat(losses).mean()
        loss.backward()
        torch.nn.utils.clip_grad_norm_(self.params, 10.0)
        momentum = self.schedule()
        self.opt.step()
        with torch.no_grad():
            for pt, pc in zip(self.target.parameters(), self.context.parameters()):
                pt.mul_(momentum).add_(pc.detach(), alpha=1.0 - momentum)
        self.s += 1
        return loss


def jepa_step_gflop(B, N, K, target_sizes, depth=DEPTH, pred_depth=PRED_DEPTH, d=D):
    """bench/train.cpp's convention: target encoder forward on N tokens, context encoder 3x forward on
    K tokens, predictor 3x forward on K + t tokens per target; GEMMs and attention products only."""
    block = lambda L: L * (24 * d * d + 4 * L * d)
    f = B * depth * block(N) + 3 * B * depth * block(K)
    f += sum(3 * B * pred_depth * block(K + t) for t in target_sizes)
    return f / 1e9


def blas_libraries():
    """The BLAS/LAPACK shared objects mapped into this process (after a matmul has run)."""
    try:
        with open("/proc/self/maps") as f:
            paths = {line.split()[-1] for line in f if "/" in line}
    except OSError:
        return []
    names = ("blas", "lapack", "mkl", "blis")
    return sorted(os.path.realpath(p) for p in paths if any(n in os.path.basename(p).lower() for n in names))


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--threads", type=int, default=1)
    ap.add_argument("--min-time", type=float, default=2.0)
    ap.add_argument("--only", choices=("all", "kernels", "jepa", "probe", "alexnet"), default="all",
                    help="kernels: encoder and attention; jepa: the whole JEPA steps; probe: the attentive "
                         "probe's training step; alexnet: BYOL's AlexNet trunk (bench/cnn.cpp)")
    # The JEPA step's masks: the sizes tjepa's collator draws in bench/train.cpp (seed 3, batch 0).
    ap.add_argument("--jepa-batch", type=int, default=8)
    ap.add_argument("--jepa-k", type=int, default=163, help="context tokens, N = 368 (BM_JepaTrainStep)")
    ap.add_argument("--jepa-targets", default="53,53,53,53", help="target sizes, N = 368")
    ap.add_argument("--deco-k", type=int, default=326, help="context tokens, N = 528 (BM_JepaTrainStepDeco)")
    ap.add_argument("--deco-targets", default="38,38,39,39", help="target sizes, N = 528")
    ap.add_argument("--drop-path", type=float, default=0.3)
    ap.add_argument("--drop-path-style", choices=("timm", "dinov2", "both"), default="both",
                    help="timm: every sample's branch computed and masked (jepa_step/<N>); dinov2: the "
                         "reference's NestedTensorBlock, branches on a subset of the batch (jepa_step_dinov2/<N>)")
    args = ap.parse_args()
    torch.set_num_threads(args.threads)
    torch.manual_seed(0)
    out = []

    def emit(name, ms, gflop, **extra):
        rec = {"name": name, "threads": args.threads, "ms": round(ms, 3), "gflop": round(gflop, 4),
               "gflops": round(gflop / (ms / 1e3), 2), **extra}
        out.append(rec)
        print(json.dumps(rec), flush=True)

    torch.randn(64, 64) @ torch.randn(64, 64)  # loads the BLAS
    info = {"info": "torch", "version": torch.__version__, "threads": torch.get_num_threads(),
            "blas": blas_libraries()}
    print(json.dumps(info), flush=True)
    print(f"compare_torch.py: PyTorch {torch.__version__}, {torch.get_num_threads()} thread(s), BLAS: "
          f"{', '.join(info['blas']) or 'none found in /proc/self/maps'}", file=sys.stderr, flush=True)
    if not any("openblas" in b for b in info["blas"]):
        print("compare_torch.py: warning: not OpenBLAS (Debian falls back to the netlib reference BLAS "
              "without libopenblas0-pthread)", file=sys.stderr, flush=True)

    if args.only in ("all", "jepa"):
        styles = ("timm", "dinov2") if args.drop_path_style == "both" else (args.drop_path_style,)
        B = args.jepa_batch
        gen = torch.Generator().manual_seed(0)
        for N, K, sizes in ((368, args.jepa_k, args.jepa_targets), (528, args.deco_k, args.deco_targets)):
            sizes = [int(t) for t in sizes.split(",")]
            if N == 368:
                width = 30  # m·tau = 3·10
                make_tokenizer = lambda: TaxelTokenizer(width)
            else:
                groups = deco50_group_sizes()
                assert len(groups) == N
                width = max(groups) * 3  # tau = 3, m = 1: n_max·tau·m, padded
                make_tokenizer = lambda: GroupedTokenizer(groups, 3)
            x = torch.randn(B, N, width)
            ctx, targets = sample_masks(B, N, K, sizes, gen)
            for style in styles:
                torch.manual_seed(0)
                step = JepaStep(make_tokenizer(), N, args.drop_path, style)
                ms = timeit(lambda: step(x, ctx, targets), args.min_time)
                name = f"jepa_step/{N}" if style == "timm" else f"jepa_step_{style}/{N}"
                emit(name, ms, jepa_step_gflop(B, N, K, sizes), windows_per_s=round(B / (ms / 1e3), 3),
                     B=B, K=K, targets=sizes, drop_path=args.drop_path, drop_path_style=style)
    if args.only in ("all", "alexnet"):
        # torchvision's alexnet().features + avgpool, built here (no torchvision needed), on
        # [8, 3, 224, 224] (bench/cnn.cpp: BM_AlexNetForward/BM_AlexNetTrain, NHWC there).
        nn = torch.nn
        trunk = nn.Sequential(
            nn.Conv2d(3, 64, 11, 4, 2), nn.ReLU(inplace=True), nn.MaxPool2d(3, 2),
            nn.Conv2d(64, 192, 5, padding=2), nn.ReLU(inplace=True), nn.MaxPool2d(3, 2),
            nn.Conv2d(192, 384, 3, padding=1), nn.ReLU(inplace=True),
            nn.Conv2d(384, 256, 3, padding=1), nn.ReLU(inplace=True),
            nn.Conv2d(256, 256, 3, padding=1), nn.ReLU(inplace=True), nn.MaxPool2d(3, 2),
            nn.AdaptiveAvgPool2d(6), nn.Flatten())
        B = 8
        x = torch.randn(B, 3, 224, 224)
        gflop = 2 * 655566528 * B / 1e9  # AlexNet::flops
        with torch.no_grad():
            ms = timeit(lambda: trunk(x), args.min_time)
        emit(f"alexnet_forward/{B}", ms, gflop, images_per_s=round(B / (ms / 1e3), 2))
        df = torch.full((B, 9216), 1e-3)

        def train_step():
            trunk.zero_grad(set_to_none=False)
            trunk(x).backward(df)

        ms = timeit(train_step, args.min_time)
        emit(f"alexnet_train/{B}", ms, 3 * gflop, images_per_s=round(B / (ms / 1e3), 2))
    if args.only in ("all", "probe"):
        B, L = 32, 368  # BM_ProbeTrainStep/368/32/{0,1}
        probe = AttentiveProbe()
        x = torch.randn(B, L, D)
        dy = torch.randn(B, 16)
        for to_tokens in (False, True):
            xg = x.clone().requires_grad_(to_tokens)

            def probe_step():
                probe.zero_grad(set_to_none=False)
                xg.grad = None
                (probe(xg) * dy).sum().backward()

            ms = timeit(probe_step, args.min_time)
            emit(f"probe_train_step/B{B}/L{L}/{int(to_tokens)}", ms, probe_gflop(B, L, to_tokens),
                 windows_per_s=round(B / (ms / 1e3), 3))
    if args.only in ("jepa", "probe", "alexnet"):
        return

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
