#pragma once
// Data-parallel pre-training over MPI. Include this header only in targets that link MPI (CMake:
// find_package(MPI) and MPI::MPI_CXX; tjepa's own targets with -DTJEPA_USE_MPI=ON); the rest of
// the library never needs it.
//
//   int main(int argc, char** argv) {
//     tjepa::dist::MpiSession mpi(&argc, &argv);
//     return mpi.run_or_abort([&] {
//       ...
//       JepaTrainer<float> trainer(model, source, graph, cfg);
//       trainer.parallel = tjepa::dist::mpi_data_parallel<float>(mpi.comm());
//       if (mpi.rank() == 0) trainer.log = &std::cout;  // Trainer writes checkpoints on rank 0 only
//       trainer.run();
//       return 0;
//     });
//   }
//
// Each rank runs the same program on the same data description and gathers only its shard of
// each global batch (train/data_parallel.hpp). The gradients of the two trainable parameter sets
// (context encoder, predictor; each contiguous in its ParamSet) are summed with one
// MPI_Allreduce each, before clipping; every rank then applies the same AdamW and EMA update.
// Placement: one rank per node or per socket, OpenMP threads inside it, e.g.
//   OMP_NUM_THREADS=32 mpirun -np 16 --map-by ppr:1:socket --bind-to socket tjepa pretrain ...
// On one machine: mpirun -np 2 --bind-to core -x OMP_NUM_THREADS=1 (2 ranks x 1 thread).
#include <mpi.h>

#include <algorithm>
#include <climits>
#include <cstdint>
#include <cstdio>
#include <exception>
#include <span>
#include <type_traits>

#include "tjepa/core/error.hpp"
#include "tjepa/train/data_parallel.hpp"

namespace tjepa::dist {

namespace detail {
template <class T>
MPI_Datatype mpi_type() {
  static_assert(std::is_same_v<T, float> || std::is_same_v<T, double>, "MPI sums of float or double only");
  return std::is_same_v<T, float> ? MPI_FLOAT : MPI_DOUBLE;
}

inline void check(int rc, const char* what) {
  if (rc == MPI_SUCCESS) return;
  char msg[MPI_MAX_ERROR_STRING];
  int len = 0;
  MPI_Error_string(rc, msg, &len);
  fail<Error>("MPI: ", what, " failed: ", std::string(msg, static_cast<std::size_t>(len)));
}

// In-place sum over comm, in chunks of at most INT_MAX values (MPI counts are int).
template <class T>
void allreduce_sum(std::span<T> v, MPI_Comm comm) {
  for (std::size_t i = 0; i < v.size(); i += INT_MAX) {
    const int n = static_cast<int>(std::min<std::size_t>(INT_MAX, v.size() - i));
    check(MPI_Allreduce(MPI_IN_PLACE, v.data() + i, n, mpi_type<T>(), MPI_SUM, comm), "MPI_Allreduce");
  }
}
}  // namespace detail

// MPI for the lifetime of the object: initialized (threads: MPI_THREAD_FUNNELED, OpenMP threads
// make no MPI calls) unless the program already did, finalized if this object initialized it.
class MpiSession {
 public:
  MpiSession(int* argc, char*** argv, MPI_Comm comm = MPI_COMM_WORLD) : comm_(comm) {
    int ready = 0;
    MPI_Initialized(&ready);
    if (!ready) {
      int provided = 0;
      detail::check(MPI_Init_thread(argc, argv, MPI_THREAD_FUNNELED, &provided), "MPI_Init_thread");
      owner_ = true;
      require<ConfigError>(provided >= MPI_THREAD_FUNNELED, "MPI: this MPI library provides thread level ",
                           provided, ", tjepa needs MPI_THREAD_FUNNELED (OpenMP threads beside the main thread)");
    }
    // Errors come back as codes (and then as tjepa::Error, which run_or_abort reports with the
    // rank) instead of MPI's default abort without a word.
    MPI_Comm_set_errhandler(comm_, MPI_ERRORS_RETURN);
    MPI_Comm_rank(comm_, &rank_);
    MPI_Comm_size(comm_, &size_);
  }
  MpiSession(const MpiSession&) = delete;
  MpiSession& operator=(const MpiSession&) = delete;
  ~MpiSession() {
    int done = 0;
    MPI_Finalized(&done);
    if (owner_ && !done) MPI_Finalize();
  }

  int rank() const { return rank_; }
  int size() const { return size_; }
  MPI_Comm comm() const { return comm_; }

  // Runs f() and returns its result. An exception on this rank (a NaN, a bad file, a failed write)
  // prints "tjepa: error on rank r of R: <message>" on stderr and aborts every rank with
  // MPI_Abort, so that no rank waits forever in a collective. Files are written atomically, so
  // nothing is left half-written.
  template <class F>
  int run_or_abort(F&& f) const {
    try {
      return f();
    } catch (const std::exception& e) {
      std::fflush(stdout);
      std::fprintf(stderr, "tjepa: error on rank %d of %d: %s\n", rank_, size_, e.what());
      std::fflush(stderr);
      MPI_Abort(comm_, 1);
    }
    return 1;
  }

 private:
  MPI_Comm comm_;
  int rank_ = 0, size_ = 1;
  bool owner_ = false;
};

// A DataParallel over comm: this process's rank and size, sums by MPI_Allreduce, and a check of
// the parameters' fingerprint every check_every steps (the MPI standard only advises that a
// reduction give every rank the same result; Open MPI's do for a given count and rank count).
template <class T>
DataParallel<T> mpi_data_parallel(MPI_Comm comm = MPI_COMM_WORLD) {
  DataParallel<T> dp;
  MPI_Comm_rank(comm, &dp.rank);
  MPI_Comm_size(comm, &dp.ranks);
  dp.sum = [comm](std::span<T> v) { detail::allreduce_sum(v, comm); };
  dp.sum_stats = [comm](std::span<double> v) { detail::allreduce_sum(v, comm); };
  dp.agree = [comm](std::uint64_t h) {
    std::uint64_t lo = h, hi = h;
    detail::check(MPI_Allreduce(MPI_IN_PLACE, &lo, 1, MPI_UINT64_T, MPI_MIN, comm), "MPI_Allreduce");
    detail::check(MPI_Allreduce(MPI_IN_PLACE, &hi, 1, MPI_UINT64_T, MPI_MAX, comm), "MPI_Allreduce");
    return lo == hi;
  };
  return dp;
}

}  // namespace tjepa::dist
