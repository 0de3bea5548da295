#!/usr/bin/python3
"""The PyTorch fixture of tests/reference: Tactile-JEPA's model and training step in PyTorch, with the
module structure and state-dict names of the reference code (E-Kovtun/tactile, tactile_ssl:
XelaJEPAModule with context_encoder / target_encoder / predictor, XelaTransformer, PatchEmbed1d,
SignalJEPAPredictor), autograd for the backward pass. It runs fixed inputs and masks through
forward, backward and three optimizer steps and writes every intermediate as a safetensors file
under tests/data/reference/. The C++ tests compare tjepa with these files; torch is needed only to
regenerate them (tools/reference/regen.sh), never by the library or its tests.

Variants (one file each):
  per_taxel-reference-{f64,f32}  one token per taxel: Conv1d over the window with the temporal
                                 padding 2 of the reference's older checkpoints, taxel-type
                                 embedding, in-model normalization (xela_mean / xela_std), the
                                 reference's weight-decay timing (update 0 at the optimizer's
                                 constructor value, update s at wd(s))
  per_taxel-ijepa-f64            the same with I-JEPA's timing (update s at wd(s + 1))
  grouped-reference-{f64,f32}    DECO-50's grouped tokenizer (one Linear + LayerNorm per group
                                 size, tokenizer.direct{n}.{0,1}), no padding, no types

Every file holds: the input x [B, T, N, C] (raw: the model normalizes), the masks (context [B, K],
targets j [B, t_j]), the initial parameters under their state-dict names, then per step s = 0, 1,
2: lr, wd, momentum, loss, grad_norm (before clipping), and for step 0 the context encoder output,
the target encoder output, each target's prediction and every trainable gradient (before
clipping); after each step every parameter (context, target, predictor) and AdamW's moments
(opt.exp_avg.<name>, opt.exp_avg_sq.<name>).
"""
import argparse
import json
import math
import os

import torch
import torch.nn as nn
import torch.nn.functional as F

from safetensors_io import write_safetensors

EPS = 1e-6  # LayerNorm eps of every norm (the reference's partial(nn.LayerNorm, eps=1e-6))


class PatchEmbed1d(nn.Module):
    """The reference's per-taxel tokenizer: a Conv1d over time (kernel = stride = chunk), then LayerNorm."""

    def __init__(self, chans, chunk, dim, padding):
        super().__init__()
        self.proj = nn.Conv1d(chans, dim, kernel_size=chunk, stride=chunk, padding=padding)
        self.layer_norm = nn.LayerNorm(dim, eps=EPS)

    def forward(self, x):  # [(b n), c, t] -> [(b n), t', d]
        return self.layer_norm(self.proj(x).transpose(1, 2))


class GroupedTokenizer(nn.Module):
    """DECO-50's hypertaxel tokenizer, mode "direct": per group size n, Linear(n*k*m) + LayerNorm."""

    def __init__(self, groups, values_per_taxel, dim):
        super().__init__()
        self.groups = groups
        self.sizes = sorted({len(g) for g in groups})
        for n in self.sizes:  # tokenizer.direct{n}.0 (Linear), tokenizer.direct{n}.1 (LayerNorm)
            setattr(self, f"direct{n}", nn.Sequential(nn.Linear(n * values_per_taxel, dim), nn.LayerNorm(dim, eps=EPS)))

    def forward(self, x):  # [b, t, n, c] -> [b, G, d]; a group's row is (frame, member, axis)
        rows = []
        for g in self.groups:
            r = x[:, :, g, :].reshape(x.shape[0], -1)
            rows.append(getattr(self, f"direct{len(g)}")(r))
        return torch.stack(rows, dim=1)


class Attention(nn.Module):
    def __init__(self, dim, heads, bias):
        super().__init__()
        self.heads = heads
        self.qkv = nn.Linear(dim, 3 * dim, bias=bias)
        self.proj = nn.Linear(dim, dim, bias=bias)

    def forward(self, x):
        B, L, C = x.shape
        qkv = self.qkv(x).reshape(B, L, 3, self.heads, C // self.heads).permute(2, 0, 3, 1, 4)
        q, k, v = qkv[0] * (C // self.heads) ** -0.5, qkv[1], qkv[2]
        a = (q @ k.transpose(-2, -1)).softmax(dim=-1)
        return self.proj((a @ v).transpose(1, 2).reshape(B, L, C))


class Mlp(nn.Module):
    def __init__(self, dim, hidden, bias):
        super().__init__()
        self.fc1 = nn.Linear(dim, hidden, bias=bias)
        self.fc2 = nn.Linear(hidden, dim, bias=bias)

    def forward(self, x):
        return self.fc2(F.gelu(self.fc1(x)))


class Block(nn.Module):
    def __init__(self, dim, heads, mlp_ratio, bias):
        super().__init__()
        self.norm1 = nn.LayerNorm(dim, eps=EPS)
        self.attn = Attention(dim, heads, bias)
        self.norm2 = nn.LayerNorm(dim, eps=EPS)
        self.mlp = Mlp(dim, int(dim * mlp_ratio), bias)

    def forward(self, x):
        x = x + self.attn(self.norm1(x))
        return x + self.mlp(self.norm2(x))


class XelaTransformer(nn.Module):
    def __init__(self, cfg):
        super().__init__()
        N, d = cfg["N"], cfg["dim"]
        if cfg["groups"]:
            self.tokenizer = GroupedTokenizer(cfg["groups"], cfg["T"] * cfg["C"], d)
            tokens = len(cfg["groups"])
        else:
            self.patch_embed = PatchEmbed1d(cfg["C"], cfg["T"], d, cfg["padding"])
            tokens = N
        self.types = cfg["types"]
        if self.types:
            self.taxeltype_embed = nn.Parameter(torch.zeros(max(self.types) + 1, d))
        self.pos_embed = nn.Parameter(torch.zeros(1, tokens, d))
        self.blocks = nn.ModuleList([Block(d, cfg["heads"], 4.0, True) for _ in range(cfg["depth"])])
        self.norm = nn.LayerNorm(d, eps=EPS)
        self.register_buffer("xela_mean", torch.tensor(cfg["mean"]))
        self.register_buffer("xela_std", torch.tensor(cfg["std"]))

    def embed(self, x):  # x [b, t, n, c] raw -> tokens [b, tokens, d] with types and positions
        x = (x - self.xela_mean) / self.xela_std
        b = x.shape[0]
        if hasattr(self, "tokenizer"):
            e = self.tokenizer(x)
        else:
            s = x.permute(0, 2, 3, 1).reshape(b * x.shape[2], x.shape[3], x.shape[1])  # (b n) c t
            e = self.patch_embed(s)  # [(b n), 1, d]
            assert e.shape[1] == 1, "one time chunk per window"
            e = e.reshape(b, x.shape[2], -1)
        if self.types:
            e = e + self.taxeltype_embed[torch.tensor(self.types)]
        return e + self.pos_embed

    def forward(self, x, context=None):
        e = self.embed(x)
        if context is not None:
            e = torch.gather(e, 1, context[:, :, None].expand(-1, -1, e.shape[-1]))
        for blk in self.blocks:
            e = blk(e)
        return self.norm(e)


class Predictor(nn.Module):
    def __init__(self, cfg):
        super().__init__()
        d = cfg["dim"]
        self.mask_token = nn.Parameter(torch.zeros(1, 1, d))
        self.input_projection = nn.Linear(d, d)
        self.blocks = nn.ModuleList([Block(d, cfg["heads"], 4.0, False) for _ in range(cfg["predictor_depth"])])
        self.norm = nn.LayerNorm(d, eps=EPS)
        self.output_projection = nn.Linear(d, d)

    def forward(self, z, pos, target):  # z [b, K, d], pos [1, tokens, d] (the target encoder's), target [b, t]
        ctx = self.input_projection(z)
        p = pos[0][target] + self.mask_token
        x = torch.cat([ctx, p], dim=1)
        for blk in self.blocks:
            x = blk(x)
        return self.output_projection(self.norm(x)[:, z.shape[1]:])


class XelaJEPAModule(nn.Module):
    def __init__(self, cfg):
        super().__init__()
        self.context_encoder = XelaTransformer(cfg)
        self.target_encoder = XelaTransformer(cfg)
        self.predictor = Predictor(cfg)


def lr_at(s, c):  # the reference's WarmupCosineScheduler, advanced once before the first update
    k = s + 1
    if k < c["warmup"]:
        return c["start_lr"] + k / max(1, c["warmup"]) * (c["lr"] - c["start_lr"])
    progress = (k - c["warmup"]) / max(1, c["total"] - c["warmup"])
    return max(c["final_lr"], c["final_lr"] + (c["lr"] - c["final_lr"]) * 0.5 * (1 + math.cos(math.pi * progress)))


def wd_sched(k, c):  # CosineWDSchedule at its step count k
    wd = c["wd_end"] + (c["wd_start"] - c["wd_end"]) * 0.5 * (1 + math.cos(math.pi * k / c["total"]))
    return min(c["wd_end"], wd) if c["wd_end"] > c["wd_start"] else max(c["wd_end"], wd)


def wd_at(s, c):
    if c["timing"] == "ijepa":  # I-JEPA: the scheduler is stepped before each update
        return wd_sched(s + 1, c)
    return c["wd_initial"] if s == 0 else wd_sched(s, c)  # the reference: after each update


def momentum_at(s, c):
    return c["ema_start"] + s * (c["ema_end"] - c["ema_start"]) / c["total"]


def run(variant, timing, dtype, out_dir):
    torch.manual_seed(20261128)
    grouped = variant == "grouped"
    cfg = dict(N=12, C=3, T=6, dim=8, depth=2, heads=2, predictor_depth=1,
               padding=0 if grouped else 2,
               types=[] if grouped else [2, 2, 0, 0, 0, 1, 1, 0, 2, 1, 0, 0],
               groups=[[0, 1], [2, 3, 4], [5, 6], [7, 8, 9], [10, 11]] if grouped else [],
               mean=[0.5, -1.0, 2.0], std=[2.0, 0.5, 1.5])
    sched = dict(total=10, warmup=2, start_lr=1e-3, lr=2e-2, final_lr=1e-4, wd_start=0.04, wd_end=0.4,
                 wd_initial=0.05, ema_start=0.9, ema_end=1.0, betas=(0.9, 0.999), eps=1e-8, clip=None,
                 timing=timing)
    m = XelaJEPAModule(cfg).to(dtype)
    with torch.no_grad():  # non-trivial values everywhere (not the reference's init: the test is the arithmetic)
        for name, p in m.named_parameters():
            is_norm = "norm" in name.split(".")[-2] or (".direct" in name and name.split(".")[-2] == "1")
            if is_norm and name.endswith("weight"):
                p.copy_(1 + 0.2 * torch.randn_like(p))
            elif is_norm:
                p.copy_(0.1 * torch.randn_like(p))
            else:
                p.copy_(0.3 * torch.randn_like(p))
        m.target_encoder.load_state_dict(m.context_encoder.state_dict())
    B, tokens = 3, (len(cfg["groups"]) if grouped else cfg["N"])
    x = (torch.randn(B, cfg["T"], cfg["N"], cfg["C"], dtype=torch.float64) * 1.5 + 0.7).to(dtype)
    g = torch.Generator().manual_seed(7)
    K = tokens - 3 if grouped else 8
    context = torch.stack([torch.randperm(tokens, generator=g)[:K] for _ in range(B)])
    sizes = [2, 2, 1, 1] if grouped else [3, 3, 2, 2]
    targets = [torch.stack([torch.randperm(tokens, generator=g)[:t] for _ in range(B)]) for t in sizes]

    out = {"x": x, "context": context.to(torch.int64)}
    for j, t in enumerate(targets):
        out[f"target.{j}"] = t.to(torch.int64)
    for name, t in m.state_dict().items():
        out[f"init.{name}"] = t.clone()
    trainable = [(n, p) for n, p in m.named_parameters() if not n.startswith("target_encoder.")]
    decay = [p for n, p in trainable if p.dim() >= 2]
    nodecay = [p for n, p in trainable if p.dim() < 2]
    opt = torch.optim.AdamW([{"params": decay}, {"params": nodecay, "weight_decay": 0.0}], lr=sched["lr"],
                            betas=sched["betas"], eps=sched["eps"], weight_decay=sched["wd_initial"])
    clipped = []
    for s in range(3):
        lr, wd, mom = lr_at(s, sched), wd_at(s, sched), momentum_at(s, sched)
        opt.param_groups[0]["lr"] = opt.param_groups[1]["lr"] = lr
        opt.param_groups[0]["weight_decay"] = wd
        opt.zero_grad()
        z = m.context_encoder(x, context)
        with torch.no_grad():
            h = m.target_encoder(x)
        losses, preds = [], []
        for t in targets:
            p = m.predictor(z, m.target_encoder.pos_embed, t)
            y = torch.gather(h, 1, t[:, :, None].expand(-1, -1, h.shape[-1]))
            preds.append(p)
            losses.append(F.mse_loss(p, y))
        loss = torch.stack(losses).mean()
        loss.backward()
        if s == 0:
            out["step0.z"], out["step0.h"] = z.detach(), h
            for j, p in enumerate(preds):
                out[f"step0.pred.{j}"] = p.detach()
            for n, p in trainable:
                out[f"step0.grad.{n}"] = p.grad.clone()
        if s == 0:  # a threshold that clips the first update and not the last
            sched["clip"] = round(0.6 * math.sqrt(sum(float((p.grad ** 2).sum()) for _, p in trainable)), 3)
        norm = torch.nn.utils.clip_grad_norm_([p for _, p in trainable], sched["clip"])
        clipped.append(float(norm) > sched["clip"])
        opt.step()
        with torch.no_grad():
            for (n, c), (n2, tp) in zip(m.context_encoder.named_parameters(), m.target_encoder.named_parameters()):
                tp.mul_(mom).add_((1 - mom) * c)
        stats = torch.tensor([lr, wd, mom, float(loss), float(norm)], dtype=torch.float64)
        out[f"step{s}.stats"] = stats
        for name, t in m.state_dict().items():
            out[f"step{s}.{name}"] = t.clone()
        for n, p in trainable:
            st = opt.state[p]
            out[f"step{s}.opt.exp_avg.{n}"] = st["exp_avg"].clone()
            out[f"step{s}.opt.exp_avg_sq.{n}"] = st["exp_avg_sq"].clone()
    assert any(clipped) and not all(clipped), f"the fixture should clip some steps, not all: {clipped}"
    meta = {"variant": variant, "timing": timing, "torch": torch.__version__,
            "model": json.dumps({k: v for k, v in cfg.items()}),
            "schedule": json.dumps({k: v for k, v in sched.items() if k != "betas"} | {"beta1": 0.9, "beta2": 0.999}),
            "stats": "lr, wd, momentum, loss, grad_norm"}
    name = f"{variant}-{timing}-{'f64' if dtype == torch.float64 else 'f32'}.safetensors"
    write_safetensors(os.path.join(out_dir, name), out, meta)
    return name


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--out", default=os.path.join(os.path.dirname(__file__), "..", "..", "tests", "data", "reference"))
    a = ap.parse_args()
    os.makedirs(a.out, exist_ok=True)
    torch.set_num_threads(1)
    for variant, timing, dtype in [("per_taxel", "reference", torch.float64), ("per_taxel", "reference", torch.float32),
                                   ("per_taxel", "ijepa", torch.float64), ("grouped", "reference", torch.float64),
                                   ("grouped", "reference", torch.float32)]:
        print("wrote", run(variant, timing, dtype, a.out))


if __name__ == "__main__":
    main()
