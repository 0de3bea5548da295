#!/usr/bin/env bash
# Time and peak memory of parse_safetensors on the costliest headers within the 4 MiB limit: many
# empty tensors, and many __metadata__ keys (the largest DOM per header byte). Run from the
# repository root after tools/test.sh (it uses the fuzz replay program of the ci build).
set -euo pipefail
dir=$(mktemp -d)
python3 - "$dir" <<'PY'
import struct, sys
limit = 4 << 20
d = sys.argv[1]
def write(name, body):
    h = body.encode()
    open(f"{d}/{name}.safetensors", "wb").write(struct.pack("<Q", len(h)) + h)
parts, size, i = [], 2, 0
while True:
    e = '"t%d":{"dtype":"F32","shape":[0],"data_offsets":[0,0]}' % i
    if size + len(e) + 1 > limit - 64: break
    parts.append(e); size += len(e) + 1; i += 1
write("tensors", "{" + ",".join(parts) + "}")
parts, size, i = [], 16, 0
while size < limit - 64:
    e = '"%x":""' % i; parts.append(e); size += len(e) + 1; i += 1
write("metadata", '{"__metadata__":{' + ",".join(parts) + "}}")
PY
for f in tensors metadata; do
  /usr/bin/time -f "$f: %e s, %M KB peak RSS" build/ci/tests/fuzz/tjepa_fuzz_replay safetensors "$dir/$f.safetensors" 2>&1 | tail -1
done
/usr/bin/time -f "a small file: %M KB peak RSS" build/ci/tests/fuzz/tjepa_fuzz_replay safetensors tests/fuzz/corpus/safetensors 2>&1 | tail -1
rm -rf "$dir"
