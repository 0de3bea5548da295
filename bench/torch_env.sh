# Sourced by bench/compare.sh and bench/scale.sh before they run PyTorch: the OpenBLAS kernels
# Debian's PyTorch runs on. OpenBLAS 0.3.21 (bookworm) reads the CPU model to pick its kernels and
# takes a model it does not know for the oldest it does: on the Xeon of family 6 model 207 it ran
# Prescott's SSE3 kernels (21 GFLOP/s in the JEPA step where its AVX-512 ones reach 75). When it
# falls back to Prescott on a CPU with AVX-512 or AVX2, OPENBLAS_CORETYPE names the kernels the
# flags allow (SkylakeX, Haswell), so that PyTorch is measured at its best; the core it runs on is
# written to $1 for the results.
torch_openblas_core() {
  local detected chosen=""
  detected=$(OPENBLAS_VERBOSE=2 /usr/bin/python3 -c 'import torch; torch.ones(64, 64) @ torch.ones(64, 64)' 2>&1 |
    sed -n 's/^Core: //p' | head -1)
  if [ "$detected" = Prescott ]; then
    if grep -qw avx512f /proc/cpuinfo; then
      chosen=SkylakeX
    elif grep -qw avx2 /proc/cpuinfo; then
      chosen=Haswell
    fi
  fi
  if [ -n "$chosen" ]; then
    export OPENBLAS_CORETYPE=$chosen
    echo "$chosen (OPENBLAS_CORETYPE; OpenBLAS detected ${detected})" >"$1"
  else
    echo "${detected:-unknown} (detected)" >"$1"
  fi
  echo "PyTorch's OpenBLAS kernels: $(cat "$1")" >&2
}
