#!/usr/bin/env bash
# Regenerates the PyTorch fixture of the `reference` tests (tests/data/reference/*.safetensors)
# with Debian's python3-torch. The output is deterministic: a rerun gives the same bytes.
set -euo pipefail
cd "$(dirname "$0")/../.."
/usr/bin/python3 -c "import torch" 2>/dev/null || { echo "regen.sh needs python3-torch (apt-get install python3-torch)" >&2; exit 1; }
/usr/bin/python3 tools/reference/fixture.py --out tests/data/reference
