# Sourced by bench/compare.sh and bench/scale.sh before they run PyTorch: the OpenBLAS kernels
# Debian's PyTorch runs on. OpenBLAS 0.3.21 (bookworm) reads the CPU model to pick its kernels and
# takes a model it does not know for an older one: on the Xeon of family 6 model 207 it ran
# Prescott's SSE3 kernels (21 GFLOP/s in the JEPA step where its AVX-512 ones reach 75), on AMD
# Zen 5 (family 26) Haswell's AVX2 ones (the step at 1 thread: 3244 ms, SkylakeX's 1793 ms). When
# it picks kernels narrower than the CPU's flags allow, OPENBLAS_CORETYPE names the widest
# (SkylakeX for AVX-512, Haswell for AVX2), so that PyTorch is measured at its best; the core it
# runs on is written to $1 for the results.
torch_openblas_core() {
  local detected chosen=""
  detected=$(OPENBLAS_VERBOSE=2 /usr/bin/python3 -c 'import torch; torch.ones(64, 64) @ torch.ones(64, 64)' 2>&1 |
    sed -n 's/^Core: //p' | head -1)
  case "$detected" in
    SkylakeX | Cooperlake | SapphireRapids) ;;  # AVX-512 kernels already
    *)
      if grep -qw avx512f /proc/cpuinfo; then
        chosen=SkylakeX
      elif [ "$detected" != Haswell ] && [ "$detected" != Zen ] && grep -qw avx2 /proc/cpuinfo; then
        chosen=Haswell
      fi
      ;;
  esac
  if [ -n "$chosen" ]; then
    export OPENBLAS_CORETYPE=$chosen
    echo "$chosen (OPENBLAS_CORETYPE; OpenBLAS detected ${detected})" >"$1"
  else
    echo "${detected:-unknown} (detected)" >"$1"
  fi
  echo "PyTorch's OpenBLAS kernels: $(cat "$1")" >&2
}
