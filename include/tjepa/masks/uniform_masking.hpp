#pragma once
// UniformMasking: MAE's random masking (He et al. 2022) of N tokens, as a MaskBatch.
//
//   visible = K = N − ⌊N·mask_ratio⌋ uniform random tokens of the N (no graph: MAE's masking)
//   masked  = the other N − K tokens
// per sample i of batch b from its own stream Rng(seed ^ kSampleSalt, b·B + i), so a batch is
// the same on any thread count and for any order of calls. Every sample keeps the same K, so the
// batch is dense without cutting.
//
// Output (MaskBatch, the type the JEPA step reads): context [B, K] = the visible tokens, and one
// target [B, N − K] (kind global: uniform over the sensor) = the masked tokens, each row
// ascending. Together they partition [0, N) in every sample.
//
// Not safe to call from several threads at once (it owns its scratch buffers).
#include <cmath>
#include <cstdint>
#include <span>
#include <vector>

#include "tjepa/core/error.hpp"
#include "tjepa/core/random.hpp"
#include "tjepa/masks/collator.hpp"
#include "tjepa/masks/context.hpp"
#include "tjepa/masks/workspace.hpp"

namespace tjepa {

class UniformMasking {
 public:
  // Salt of the per-sample streams (unrelated to MaskCollator's).
  static constexpr std::uint64_t kSampleSalt = 0x6d61656d61736b73ull;  // "maemasks"

  UniformMasking(int num_tokens, double mask_ratio) : n_(num_tokens), ratio_(mask_ratio) {
    require<ConfigError>(num_tokens >= 2, "UniformMasking: num_tokens = ", num_tokens,
                         ", expected >= 2 (one visible and one masked token)");
    require<ConfigError>(mask_ratio > 0.0 && mask_ratio < 1.0, "UniformMasking: mask_ratio = ", mask_ratio,
                         ", expected in (0, 1)");
    masked_ = static_cast<int>(std::floor(num_tokens * mask_ratio));
    require<ConfigError>(masked_ >= 1 && masked_ < num_tokens, "UniformMasking: mask_ratio ", mask_ratio, " of ",
                         num_tokens, " tokens masks ", masked_, ", expected 1..", num_tokens - 1);
    ws_.resize(num_tokens);
  }

  int num_tokens() const { return n_; }
  double mask_ratio() const { return ratio_; }
  int num_visible() const { return n_ - masked_; }
  int num_masked() const { return masked_; }

  MaskBatch sample(int batch_size, std::uint64_t seed, std::uint64_t batch_index) const {
    MaskBatch out;
    sample_into(out, batch_size, seed, batch_index);
    return out;
  }

  // As sample(), reusing out's buffers.
  void sample_into(MaskBatch& out, int batch_size, std::uint64_t seed, std::uint64_t batch_index) const {
    require<ConfigError>(batch_size >= 1, "UniformMasking::sample: batch_size = ", batch_size, ", expected >= 1");
    const int B = batch_size, K = num_visible(), M = masked_;
    out.B = B;
    out.K = K;
    out.context.resize(static_cast<std::size_t>(B) * K);
    out.targets.resize(1);
    TargetSet& masked = out.targets[0];
    masked.size = M;
    masked.kind = TargetKind::global;
    masked.part = -1;
    masked.indices.resize(static_cast<std::size_t>(B) * M);
    const int words = (n_ + 63) / 64;
    draw_.resize(static_cast<std::size_t>(K));
    for (int i = 0; i < B; ++i) {
      Rng rng(seed ^ kSampleSalt, batch_index * static_cast<std::uint64_t>(B) + static_cast<std::uint64_t>(i));
      ws_.excluded.clear();  // nothing excluded: K plain uniform draws
      sample_uniform_context(n_, K, rng, ws_, draw_);
      int* visible = out.context.data() + static_cast<std::size_t>(i) * K;
      detail::sort_tokens(draw_.data(), K, ws_.bits.data(), words, visible);
      // The masked row: the ascending complement of the visible row.
      int* row = masked.indices.data() + static_cast<std::size_t>(i) * M;
      for (int v = 0, j = 0; v < n_; ++v) {
        if (j < K && visible[j] == v)
          ++j;
        else
          *row++ = v;
      }
    }
  }

 private:
  int n_ = 0, masked_ = 0;
  double ratio_ = 0;
  mutable MaskWorkspace ws_;
  mutable std::vector<int> draw_;  // [K] the visible tokens in draw order
};

}  // namespace tjepa
