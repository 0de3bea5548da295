#!/usr/bin/env bash
# The dist test: data-parallel pre-training against one process (tests/dist/CMakeLists.txt).
#   check.sh <tjepa_dist_check> <mpirun> <work dir>
# 1. 20 steps with 1 rank and with 2 ranks, the same global batch of 8: the loss curves agree
#    within TOL (relative). The masks and the drop-path noise of each sample are identical; the
#    only difference is where the gradient's sum over samples is split (one GEMM over 8 samples,
#    or two over 4 then MPI_Allreduce), which changes float rounding.
# 2. 2 ranks stop after step 10 (checkpoint by rank 0), 1 rank resumes to step 20; and the reverse.
#    Both curves agree with the uninterrupted 1-rank curve within TOL.
# 3. Rank 1 throws after step 3: mpirun fails, stderr names the rank and the error, and the
#    checkpoint rank 0 wrote is whole (a resume from it runs).
set -euo pipefail
bin=$1 mpirun=$2 work=$3
TOL=${TJEPA_DIST_TOL:-1e-6}
rm -rf "$work"
mkdir -p "$work"
export OMPI_ALLOW_RUN_AS_ROOT=1 OMPI_ALLOW_RUN_AS_ROOT_CONFIRM=1 OMP_NUM_THREADS=1
run() {
  local np=$1
  shift
  "$mpirun" --oversubscribe --bind-to none -np "$np" -x OMP_NUM_THREADS "$bin" "$@"
}
# compare A B [part]: B's steps are A's (all of them unless "part"), losses within TOL relative;
# prints the largest difference.
compare() {
  awk -v tol="$TOL" -v a="$1" -v b="$2" -v part="${3:-}" '
    NR == FNR { loss[$1] = $2; n++; next }
    { m++; if (!($1 in loss)) { print "step " $1 " of " b " is not in " a; bad = 1; next }
      d = loss[$1] - $2; if (d < 0) d = -d; r = d / (loss[$1] < 0 ? -loss[$1] : loss[$1]);
      if (r > worst) worst = r }
    END { if (m == 0 || (part == "" && n != m)) { print a " has " n " steps, " b " has " m; bad = 1 }
          printf "%s vs %s: %d steps, largest relative loss difference %.3g (tolerance %s)\n", a, b, m, worst, tol;
          exit (bad || worst > tol) }' "$work/$1" "$work/$2"
}

echo "== 1, 2 and 3 ranks, 20 steps of a global batch of 8 (3 ranks: uneven shards of 2, 3, 3)"
run 1 --curve "$work/one.txt" --steps 20
run 2 --curve "$work/two.txt" --steps 20
compare one.txt two.txt
run 3 --curve "$work/three.txt" --steps 20
compare one.txt three.txt

echo "== 2 ranks to step 10, then 1 rank resumes"
run 2 --curve "$work/two_one.txt" --steps 20 --stop-after 10 --checkpoint "$work/two.safetensors"
run 1 --curve "$work/two_one.txt" --steps 20 --resume "$work/two.safetensors"
compare one.txt two_one.txt

echo "== 1 rank to step 10, then 2 ranks resume"
run 1 --curve "$work/one_two.txt" --steps 20 --stop-after 10 --checkpoint "$work/one.safetensors"
run 2 --curve "$work/one_two.txt" --steps 20 --resume "$work/one.safetensors"
compare one.txt one_two.txt

echo "== rank 1 fails after step 3"
if run 2 --curve "$work/fail.txt" --steps 20 --checkpoint "$work/fail.safetensors" --fail-rank 1 --fail-at 3 \
    >"$work/fail.out" 2>"$work/fail.err"; then
  echo "mpirun succeeded although rank 1 failed"; exit 1
fi
grep -q "tjepa: error on rank 1 of 2: tjepa_dist_check: the planned failure at step 3" "$work/fail.err" || {
  echo "stderr does not name the failing rank and its error:"; cat "$work/fail.err"; exit 1; }
# The checkpoint is whole: a resume from it continues the uninterrupted curve, and its next write
# removes any temporary file the abort left behind.
run 1 --curve "$work/after_fail.txt" --steps 20 --resume "$work/fail.safetensors" --stop-after 6 \
  --checkpoint "$work/fail.safetensors"
compare one.txt after_fail.txt part
if ls -A "$work" | grep -q "tjepa-tmp"; then echo "a temporary file was left:"; ls -A "$work"; exit 1; fi
echo "the failing rank brought both down; the checkpoint left behind resumes"
echo "dist: all checks passed"
