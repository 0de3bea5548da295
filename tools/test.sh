#!/usr/bin/env bash
# Builds and runs tjepa's whole test suite (preset "ci": -O2, -march=native, warnings are errors,
# MPI on for the data-parallel tests, which mpirun runs as root too).
# Extra arguments go to ctest, e.g. `tools/test.sh -L graph`.
set -euo pipefail
cd "$(dirname "$0")/.."
source tools/deps.sh
tjepa_ensure_packages "${TJEPA_TEST_PACKAGES[@]}"
cmake --preset ci >/dev/null
cmake --build --preset ci -j "$(nproc)"
ctest --preset ci "$@"
