#pragma once
// MaskConfig: every range and count of the mask sampler, with the Sparsh-skin defaults (the paper's
// Sec. IV-D, "Mask sampling", and the reference implementation: E-Kovtun/tactile,
// tactile_ssl/utils/jepa_masking.py). N is the number of tokens of the graph the masks are drawn
// over.
#include <string>

#include "tjepa/core/error.hpp"

namespace tjepa {

// A ratio range [lo, hi): a size is ⌊n·U(lo, hi)⌋ for a domain of n tokens.
struct RatioRange {
  double lo = 0.0;
  double hi = 0.0;
  friend bool operator==(const RatioRange&, const RatioRange&) = default;
};

// How global targets pick their tokens.
enum class GlobalSampling {
  stratified,  // one random token from each group of the domain, then uniform up to t (default)
  uniform,     // t tokens uniform over the domain (the paper's plain reading)
};

// How the context picks its c tokens (before the union of targets is removed).
enum class ContextSampling {
  uniform,  // c uniform random tokens (default)
  local,    // a connected Dijkstra region of c tokens; on a sensor in several parts, one region
            // per part, c split in proportion to the parts' sizes (the paper's † ablation)
};

// What the targets are.
enum class TargetScheme {
  graph,         // local + global targets over the taxel graph (default)
  ijepa_blocks,  // I-JEPA rectangular blocks on a grid placement, context a block too ("4I-JEPA")
};

// Whether a sensor in several parts gets per-part targets.
enum class PartTargets {
  automatic,  // per part when the graph has >= 2 parts (default)
  per_part,   // per part always (a one-part graph then behaves like `whole`, with its own counts)
  whole,      // targets over the whole sensor even when it has several parts
};

// I-JEPA's multi-block ranges (facebookresearch/ijepa, src/masks/multiblock.py defaults and the
// ViT configs): target blocks of scale U(0.15, 0.2) and aspect ratio U(0.75, 1.5), one context
// block of scale U(0.85, 1.0), aspect ratio 1. Scales are fractions of the N tokens (on a full grid
// that is I-JEPA's fraction of the H·W cells).
struct BlockMaskConfig {
  RatioRange target_scale{0.15, 0.2};
  RatioRange target_aspect{0.75, 1.5};
  RatioRange context_scale{0.85, 1.0};
  RatioRange context_aspect{1.0, 1.0};
  int num_targets = 4;
  friend bool operator==(const BlockMaskConfig&, const BlockMaskConfig&) = default;
};

struct MaskConfig {
  RatioRange context_ratio{0.5, 0.9};   // c = ⌊N·U(lo, hi)⌋ per batch
  RatioRange target_ratio{0.10, 0.18};  // t = ⌊n·U(lo, hi)⌋ per batch (n = N, or the part's size)
  // One-part sensors (and PartTargets::whole): targets per sample.
  int num_local = 2;
  int num_global = 2;
  // Multi-part sensors: targets per part per sample, of ⌊n_part·s⌋ tokens, s drawn per part.
  int num_local_per_part = 1;
  int num_global_per_part = 1;
  PartTargets part_targets = PartTargets::automatic;
  GlobalSampling global_sampling = GlobalSampling::stratified;
  ContextSampling context_sampling = ContextSampling::uniform;
  TargetScheme scheme = TargetScheme::graph;
  BlockMaskConfig blocks{};
  // The context keeps at least max(min_context_tokens, ⌈min_context_ratio·N⌉) tokens; -1: 32, or
  // half the smallest context ⌊⌊N·context_ratio.lo⌋/2⌋ when that is less (MaskCollator::min_context).
  int min_context_tokens = -1;
  double min_context_ratio = 0.15;
  // Resampling: targets and then the context are redrawn up to max_tries times each.
  int max_tries = 32;
  // Threads over the samples of a batch (OpenMP); 0: OpenMP's default. Results never depend on it.
  int num_threads = 0;
};

namespace detail {
inline void check_ratio_range(const RatioRange& r, const char* name, bool allow_one = false) {
  const bool lo_ok = r.lo > 0.0 && (allow_one ? r.lo <= 1.0 : r.lo < 1.0);
  const bool hi_ok = r.hi > 0.0 && (allow_one ? r.hi <= 1.0 : r.hi < 1.0);
  require<ConfigError>(lo_ok && hi_ok && r.lo <= r.hi, "MaskConfig: ", name, " = [", r.lo, ", ",
                       r.hi, "], expected 0 < lo <= hi ", allow_one ? "<= 1" : "< 1");
}
inline void check_positive_range(const RatioRange& r, const char* name) {
  require<ConfigError>(r.lo > 0.0 && r.lo <= r.hi && r.hi < 1e6, "MaskConfig: ", name, " = [",
                       r.lo, ", ", r.hi, "], expected 0 < lo <= hi");
}
}  // namespace detail

}  // namespace tjepa
