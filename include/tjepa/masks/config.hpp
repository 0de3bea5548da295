#pragma once
// MaskConfig: every range and count of the mask sampler, with the Sparsh-skin defaults (the paper's
// Sec. IV-D, "Mask sampling", and the reference implementation: E-Kovtun/tactile,
// tactile_ssl/utils/jepa_masking.py). N is the number of tokens of the graph the masks are drawn
// over.
#include <array>
#include <string>
#include <string_view>
#include <utility>

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
constexpr auto json_names(GlobalSampling) {
  return std::array{std::pair<std::string_view, GlobalSampling>{"stratified", GlobalSampling::stratified},
                    std::pair<std::string_view, GlobalSampling>{"uniform", GlobalSampling::uniform}};
}

// How the context picks its c tokens (before the union of targets is removed).
enum class ContextSampling {
  uniform,  // c uniform random tokens (default)
  local,    // a connected Dijkstra region of c tokens; on a sensor in several parts, one region
            // per part, c split in proportion to the parts' sizes (the paper's † ablation)
};
constexpr auto json_names(ContextSampling) {
  return std::array{std::pair<std::string_view, ContextSampling>{"uniform", ContextSampling::uniform},
                    std::pair<std::string_view, ContextSampling>{"local", ContextSampling::local}};
}

// What the targets are.
enum class TargetScheme {
  graph,         // local + global targets over the taxel graph (default)
  ijepa_blocks,  // I-JEPA rectangular blocks on a grid placement, context a block too ("4I-JEPA")
};
constexpr auto json_names(TargetScheme) {
  return std::array{std::pair<std::string_view, TargetScheme>{"graph", TargetScheme::graph},
                    std::pair<std::string_view, TargetScheme>{"ijepa_blocks", TargetScheme::ijepa_blocks}};
}

// Whether a sensor in several parts gets per-part targets.
enum class PartTargets {
  automatic,  // per part when the graph has >= 2 parts (default)
  per_part,   // per part always (a one-part graph then behaves like `whole`, with its own counts)
  whole,      // targets over the whole sensor even when it has several parts
};
constexpr auto json_names(PartTargets) {
  return std::array{std::pair<std::string_view, PartTargets>{"automatic", PartTargets::automatic},
                    std::pair<std::string_view, PartTargets>{"per_part", PartTargets::per_part},
                    std::pair<std::string_view, PartTargets>{"whole", PartTargets::whole}};
}

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

// Throws ConfigError unless c is a possible configuration on some graph (MaskCollator then checks
// it against its graph): counts, tries and threads in range, and the ranges of the scheme in use.
inline void validate_mask_config(const MaskConfig& c) {
  require<ConfigError>(c.max_tries >= 1, "MaskConfig: max_tries = ", c.max_tries, ", expected >= 1");
  require<ConfigError>(c.num_threads >= 0, "MaskConfig: num_threads = ", c.num_threads,
                       ", expected >= 0 (0: OpenMP's default)");
  require<ConfigError>(c.min_context_tokens >= -1, "MaskConfig: min_context_tokens = ", c.min_context_tokens,
                       ", expected >= 0 (or -1: automatic)");
  require<ConfigError>(c.min_context_ratio >= 0.0 && c.min_context_ratio < 1.0, "MaskConfig: min_context_ratio = ",
                       c.min_context_ratio, ", expected in [0, 1)");
  require<ConfigError>(c.num_local >= 0 && c.num_global >= 0 && c.num_local_per_part >= 0 &&
                           c.num_global_per_part >= 0,
                       "MaskConfig: target counts ", c.num_local, ", ", c.num_global, ", ", c.num_local_per_part,
                       ", ", c.num_global_per_part, " (local, global, local per part, global per part), expected >= 0");
  if (c.scheme == TargetScheme::ijepa_blocks) {
    detail::check_ratio_range(c.blocks.target_scale, "blocks.target_scale", true);
    detail::check_ratio_range(c.blocks.context_scale, "blocks.context_scale", true);
    detail::check_positive_range(c.blocks.target_aspect, "blocks.target_aspect");
    detail::check_positive_range(c.blocks.context_aspect, "blocks.context_aspect");
    require<ConfigError>(c.blocks.num_targets >= 1, "MaskConfig: blocks.num_targets = ", c.blocks.num_targets,
                         ", expected >= 1");
  } else {
    detail::check_ratio_range(c.context_ratio, "context_ratio");
    detail::check_ratio_range(c.target_ratio, "target_ratio");
  }
}

}  // namespace tjepa
