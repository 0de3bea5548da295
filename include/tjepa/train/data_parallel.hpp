#pragma once
// DataParallel: how one training step's global batch is shared among processes (ranks).
//
//   rank r of R takes the samples [first, first + count) of the global batch of B,
//     first = ⌊r·B / R⌋, count = ⌊(r+1)·B / R⌋ − first;
//   masks and drop-path noise are drawn per global sample index (MaskBatch::slice_into,
//   DropPath::first_sample), so sample i gets the same masks and noise whatever R is;
//   after backward, each rank scales its gradients (of the mean over its shard) by count / B and
//   `sum` adds them over the ranks: every rank then holds the gradient of the global batch's mean
//   loss and applies the same clipping, AdamW and EMA update (JepaStep::all_reduce).
//
// The one-process default (ranks = 1) changes nothing. dist/mpi.hpp builds one over
// MPI_Allreduce; any transport that sums in place, with the same result on every rank, fits.
#include <cstddef>
#include <cstdint>
#include <functional>
#include <span>

#include "tjepa/core/error.hpp"
#include "tjepa/core/hash.hpp"  // fingerprint: the Trainer checks that ranks agree

namespace tjepa {

struct Shard {
  int first = 0, count = 0;
};

template <class T>
struct DataParallel {
  int rank = 0, ranks = 1;
  // Sums values over all ranks, in place; every rank must get the same result.
  std::function<void(std::span<T>)> sum;
  std::function<void(std::span<double>)> sum_stats;
  // True when every rank passes the same value. The Trainer passes a hash of all parameters
  // every check_every steps and stops with NumericError if the ranks have drifted apart (a
  // transport whose sums differ between ranks). Empty or check_every 0: no check.
  std::function<bool(std::uint64_t)> agree;
  std::int64_t check_every = 100;

  bool active() const { return ranks > 1; }

  // This rank's samples of a global batch of B.
  Shard shard(int B) const {
    require<ConfigError>(ranks >= 1 && rank >= 0 && rank < ranks, "DataParallel: rank ", rank, " of ", ranks);
    require<ConfigError>(B >= ranks, "DataParallel: a global batch of ", B, " cannot give each of ", ranks,
                         " ranks a sample");
    const auto at = [&](int r) { return static_cast<int>(static_cast<long long>(r) * B / ranks); };
    return {at(rank), at(rank + 1) - at(rank)};
  }
};

}  // namespace tjepa
