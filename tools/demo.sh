#!/usr/bin/env bash
# The main job: builds the `tjepa` command (preset "release") and runs `tjepa demo`.
# Extra arguments go to `tjepa demo`.
set -euo pipefail
cd "$(dirname "$0")/.."
source tools/deps.sh
tjepa_ensure_packages "${TJEPA_BUILD_PACKAGES[@]}"
cmake --preset release -DTJEPA_BUILD_APPS=ON -DTJEPA_BUILD_TESTS=OFF -DTJEPA_BUILD_BENCHMARKS=OFF >/dev/null
cmake --build --preset release --target tjepa_cli -j "$(nproc)"
exec build/release/apps/tjepa/tjepa demo "$@"
