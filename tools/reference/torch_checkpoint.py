#!/usr/bin/python3
"""The PyTorch side of `tjepa convert` (needs Debian's python3-torch; tjepa itself reads safetensors).

  torch_checkpoint.py to-safetensors last.ckpt ref.safetensors [--config .hydra/config.yaml]
      The reference code's checkpoint (Lightning Fabric: its "model" entry is XelaJEPAModule's state
      dict; a plain state dict works too) as a safetensors state dict. With --config, the encoder's
      keys of the run's Hydra config (in_dim, in_chans, sequence_length, time_chunk_size,
      temporal_patch_padding, num_heads, ...) go into the metadata, where `tjepa convert` reads them.
  torch_checkpoint.py to-torch ref.safetensors out.ckpt
      Back: {"model": state dict, "global_step": n} for the reference code's loaders
      (checkpoint["model"], as its downstream sl_module reads it)."""
import argparse
import json
import os
import pickle
import sys

try:
    import torch
except ModuleNotFoundError:
    sys.exit(f"torch_checkpoint.py: this python ({sys.executable}) has no module 'torch'. It needs PyTorch: "
             "install Debian's python3-torch (apt-get install python3-torch) and run the script with "
             "/usr/bin/python3 tools/reference/torch_checkpoint.py ...")

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from safetensors_io import read_safetensors, write_safetensors  # noqa: E402


class _Stub:
    def __init__(self, *a, **k):
        pass

    def __setstate__(self, state):
        self.__dict__["state"] = state


class _Unpickler(pickle.Unpickler):
    """Loads checkpoints that pickled tactile_ssl objects (schedulers) without tactile_ssl installed."""

    def find_class(self, module, name):
        try:
            return super().find_class(module, name)
        except (ImportError, AttributeError):
            return _Stub


class _StubPickle:
    Unpickler = _Unpickler
    load = pickle.load


def _encoder_config(node):
    """The first mapping whose _target_ names a tactile_ssl encoder (xela_*), searched depth first."""
    if isinstance(node, dict):
        t = str(node.get("_target_", ""))
        if "tactile_ssl.model.xela" in t or "tactile_ssl.model.signal" in t:
            return node
        for v in node.values():
            r = _encoder_config(v)
            if r is not None:
                return r
    elif isinstance(node, list):
        for v in node:
            r = _encoder_config(v)
            if r is not None:
                return r
    return None


def to_safetensors(src, dst, config):
    try:
        ckpt = torch.load(src, map_location="cpu", weights_only=False)
    except (ModuleNotFoundError, AttributeError):
        ckpt = torch.load(src, map_location="cpu", pickle_module=_StubPickle)
    state = ckpt.get("model", ckpt.get("state_dict", ckpt)) if isinstance(ckpt, dict) else ckpt
    if hasattr(state, "state_dict"):
        state = state.state_dict()
    out = {}
    for k, v in state.items():
        if not torch.is_tensor(v):
            continue
        for p in ("_forward_module.", "module.", "model."):
            if k.startswith(p):
                k = k[len(p):]
        out[k] = v
    meta = {"format": "tactile_ssl.state_dict", "source": os.path.basename(src)}
    if isinstance(ckpt, dict) and "global_step" in ckpt:
        meta["global_step"] = str(int(ckpt["global_step"]))
    if config:
        import yaml
        with open(config) as f:
            enc = _encoder_config(yaml.safe_load(f))
        if enc is None:
            sys.exit(f"{config}: no encoder node (_target_: tactile_ssl.model.xela_*) found")
        keys = ("in_dim", "in_chans", "sequence_length", "time_chunk_size", "temporal_patch_padding", "num_heads",
                "depth", "embed_dim", "num_register_tokens", "use_taxel_type_embedding", "_target_")
        meta["reference.config"] = json.dumps({k: enc[k] for k in keys if k in enc and not isinstance(enc[k], dict)})
    write_safetensors(dst, out, meta)
    print(f"wrote {dst}: {len(out)} tensors")


def to_torch(src, dst):
    tensors, meta = read_safetensors(src)
    ckpt = {"model": tensors, "checkpoint_format_version": 2, "global_step": int(meta.get("global_step", 0))}
    tmp = dst + ".tmp"
    torch.save(ckpt, tmp)
    os.replace(tmp, dst)
    print(f"wrote {dst}: {len(tensors)} tensors under 'model'")


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    sub = ap.add_subparsers(dest="cmd", required=True)
    a = sub.add_parser("to-safetensors")
    a.add_argument("src")
    a.add_argument("dst")
    a.add_argument("--config", help="the run's Hydra config.yaml")
    b = sub.add_parser("to-torch")
    b.add_argument("src")
    b.add_argument("dst")
    args = ap.parse_args()
    if args.cmd == "to-safetensors":
        to_safetensors(args.src, args.dst, args.config)
    else:
        to_torch(args.src, args.dst)


if __name__ == "__main__":
    main()
