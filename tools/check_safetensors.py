#!/usr/bin/env python3
"""Reads a safetensors file written by tjepa (or anyone) with numpy only, and checks it.

    check_safetensors.py FILE                    print every tensor (name, dtype, shape) and the metadata
    check_safetensors.py FILE --expect LIST      also check names and shapes against LIST:
                                                 a JSON object {"name": [d0, d1, ...]}, or a text file
                                                 with one "name d0,d1,..." per line ("name" alone: a scalar)
    --prefix P       compare only tensors whose names start with P (e.g. "target_encoder.")
    --allow-extra    tensors in the file but not in LIST are not an error

Besides names and shapes it checks the layout (data offsets tile the data exactly, sizes match the
shapes), decodes every tensor with numpy and reports non-finite floats. Exit status 0 when all
checks pass, 1 otherwise. Not part of the C++ test suite's dependencies.
"""
import argparse
import json
import struct
import sys

import numpy as np

DTYPES = {
    "BOOL": np.bool_, "U8": np.uint8, "I8": np.int8, "U16": "<u2", "I16": "<i2", "F16": "<f2",
    "U32": "<u4", "I32": "<i4", "F32": "<f4", "U64": "<u8", "I64": "<i8", "F64": "<f8",
    "BF16": "<u2",  # numpy has no bfloat16: kept as raw 16-bit words
}


def read(path):
    with open(path, "rb") as f:
        blob = f.read()
    if len(blob) < 8:
        raise ValueError(f"{path}: truncated ({len(blob)} bytes)")
    (n,) = struct.unpack("<Q", blob[:8])
    if n > len(blob) - 8:
        raise ValueError(f"{path}: header length {n} exceeds the file")
    header = json.loads(blob[8:8 + n].decode("utf-8"))
    data = memoryview(blob)[8 + n:]
    metadata = header.pop("__metadata__", {})
    tensors, spans = {}, []
    for name, e in header.items():
        dtype = np.dtype(DTYPES[e["dtype"]])
        shape = tuple(e["shape"])
        begin, end = e["data_offsets"]
        count = int(np.prod(shape, dtype=np.int64)) if shape else 1
        if end - begin != count * dtype.itemsize:
            raise ValueError(f"{path}: tensor {name!r}: {end - begin} bytes for {e['dtype']} {list(shape)}")
        spans.append((begin, end, name))
        tensors[name] = (e["dtype"], np.frombuffer(data[begin:end], dtype=dtype).reshape(shape))
    pos = 0
    for begin, end, name in sorted(spans):
        if begin != pos:
            raise ValueError(f"{path}: tensor {name!r} starts at {begin}, expected {pos} (overlap or hole)")
        pos = end
    if pos != len(data):
        raise ValueError(f"{path}: tensors cover {pos} data bytes, the file holds {len(data)}")
    return metadata, tensors


def read_expected(path):
    with open(path) as f:
        text = f.read()
    try:
        return {k: tuple(v) for k, v in json.loads(text).items()}
    except json.JSONDecodeError:
        out = {}
        for line in text.splitlines():
            parts = line.split()
            if not parts or parts[0].startswith("#"):
                continue
            out[parts[0]] = tuple(int(d) for d in parts[1].split(",")) if len(parts) > 1 else ()
        return out


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("file")
    ap.add_argument("--expect")
    ap.add_argument("--prefix", default="")
    ap.add_argument("--allow-extra", action="store_true")
    args = ap.parse_args()
    try:
        metadata, tensors = read(args.file)
    except (ValueError, KeyError, UnicodeDecodeError, json.JSONDecodeError) as e:
        print(f"error: {e}", file=sys.stderr)
        return 1
    ok = True
    for key, value in sorted(metadata.items()):
        print(f"metadata {key} = {value if len(value) < 100 else value[:97] + '...'}")
    for name, (dtype, array) in tensors.items():
        print(f"{name} {dtype} {list(array.shape)}")
        if array.dtype.kind == "f" and not np.all(np.isfinite(array)):
            print(f"error: tensor {name!r} holds non-finite values", file=sys.stderr)
            ok = False
    if args.expect:
        expected = read_expected(args.expect)
        have = {k: v[1].shape for k, v in tensors.items() if k.startswith(args.prefix)}
        want = {k: v for k, v in expected.items() if k.startswith(args.prefix)}
        for name in sorted(set(want) - set(have)):
            print(f"error: missing tensor {name!r}", file=sys.stderr)
            ok = False
        if not args.allow_extra:
            for name in sorted(set(have) - set(want)):
                print(f"error: unexpected tensor {name!r}", file=sys.stderr)
                ok = False
        for name in sorted(set(have) & set(want)):
            if tuple(have[name]) != tuple(want[name]):
                print(f"error: tensor {name!r} has shape {list(have[name])}, expected {list(want[name])}",
                      file=sys.stderr)
                ok = False
        print(f"checked {len(want)} expected tensors: {'ok' if ok else 'MISMATCH'}")
    return 0 if ok else 1


if __name__ == "__main__":
    sys.exit(main())
