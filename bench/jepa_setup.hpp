#pragma once
// The whole JEPA step's setup that bench/train.cpp (Google Benchmark) and bench/scale.cpp (the
// per-phase profile) share: the paper's model (ViT-Tiny encoder d = 192, 12 blocks, 3 heads;
// predictor 4 blocks) on one of two skins, a batch of random windows, and the FLOPs of one step
// with the library's own masks (MaskCollator, seed 3, batch 0):
//   allegro  Allegro/Xela skin, N = 368 tokens of m·τ = 30 values (K 163, targets 4 × 53)
//   deco     DECO-50, two Inspire hands: 2124 taxels in 528 groups of 4 and 5 (deco50_grouping),
//            τ = 3, m = 1, the grouped tokenizer (K 326, targets 38, 38, 39, 39)
// bench/compare_torch.py times the same step in plain PyTorch with these sizes (its --jepa-*
// defaults); keep both in step when the masks change.
//
// FLOP convention (GEMMs and attention products only): a block on L tokens costs per token
// 24 d² (qkv 6d², proj 2d², fc1 8d², fc2 8d²) + 4 L d (QKᵀ and PV) forward; forward + backward
// = 3× forward. Target encoder: forward on N tokens; context encoder: 3× on K tokens; predictor:
// 3× on K + t tokens for each target. Tokenizer, norms and the optimizer are not counted.
#include <cstddef>
#include <string>
#include <string_view>
#include <vector>

#include <tjepa/tjepa.hpp>

namespace tjepa_bench {

struct JepaSetup {
  tjepa::TaxelGraph graph;  // one node per token
  tjepa::JepaConfig config;
  std::vector<float> x;     // [B, N, token width]
  int B = 8;
};

inline JepaSetup jepa_setup(std::string_view skin, int B = 8) {
  JepaSetup s;
  s.B = B;
  tjepa::Rng rng(2);
  if (skin == "allegro") {
    const auto hand = tjepa::layouts::allegro_xela();
    const int N = hand.graph.num_nodes();
    s.graph = hand.graph;
    s.config = tjepa::JepaConfig::reference(N, 30, 3);
    s.x.resize(static_cast<std::size_t>(B) * N * 30);
    for (auto& v : s.x) v = static_cast<float>(rng.normal());
    return s;
  }
  tjepa::require<tjepa::ConfigError>(skin == "deco", "jepa_setup: skin '", std::string(skin),
                                     "', expected allegro or deco");
  const int tau = 3, axes = 1;
  const tjepa::Skin hands = tjepa::layouts::inspire_hands();
  const tjepa::Grouping grouping = tjepa::layouts::deco50_grouping(hands);
  const int taxels = grouping.num_taxels, G = grouping.num_groups();
  // Windows [B, 2124, τ, m] gathered into the grouped tokenizer's rows [B, 528, 5·τ·m].
  std::vector<float> windows(static_cast<std::size_t>(B) * taxels * tau * axes);
  for (auto& v : windows) v = static_cast<float>(rng.normal());
  s.x.resize(static_cast<std::size_t>(B) * G * grouping.max_size * tau * axes);
  tjepa::gather_groups(windows.data(), B, taxels, tau, axes, grouping.members.data(), G, grouping.max_size, s.x.data());
  s.graph = grouping.graph;
  s.config = tjepa::JepaConfig::reference(G, tau * axes, axes);
  s.config.group_size = grouping.sizes;
  return s;
}

// One benchmark run of a setup: its collator's masks (seed 3, batch 0), the model (seed 1), AdamW,
// the reference schedule, and the step in `precision`, drop-path 0 (every branch computed, as
// PyTorch's timm-style step computes every branch and masks it: the same work).
struct JepaRun {
  tjepa::MaskCollator collator;
  int N;
  tjepa::MaskBatch masks;
  tjepa::JepaModel<float> model;
  tjepa::AdamW<float> opt;
  tjepa::TrainingSchedule schedule;
  tjepa::JepaStep<float> step;
  JepaRun(const JepaSetup& s, tjepa::Precision precision)
      : collator(s.graph),
        N(collator.num_tokens()),
        masks(collator.sample(s.B, 3, 0)),
        model(s.config, 1),
        opt(model.trainable()),
        schedule(tjepa::TrainingSchedule::reference(500, 100, 30)),
        step(model, step_config(precision)) {}

 private:
  static tjepa::JepaStepConfig step_config(tjepa::Precision precision) {
    tjepa::JepaStepConfig c;
    c.precision = precision;
    return c;
  }
};

inline double block_flops(double tokens, double L, double d) { return tokens * (24 * d * d + 4 * L * d); }

// FLOPs of one step of `config` on masks (the convention above).
inline double jepa_step_flops(const tjepa::JepaConfig& config, const tjepa::MaskBatch& masks, int N) {
  const double d = config.encoder.dim, K = masks.K, B = masks.B;
  double flops = block_flops(B * N, N, d) * config.encoder.depth;  // target encoder, forward only
  flops += 3 * block_flops(B * K, K, d) * config.encoder.depth;    // context encoder
  for (const auto& t : masks.targets)
    flops += 3 * block_flops(B * (K + t.size), K + t.size, d) * config.predictor.depth;
  return flops;
}

// "N 368, K 163, targets 53,53,53,53"
inline std::string masks_label(const tjepa::MaskBatch& masks, int N) {
  std::string targets;
  for (const auto& t : masks.targets) {
    if (!targets.empty()) targets += ',';
    targets += std::to_string(t.size);
  }
  return "N " + std::to_string(N) + ", K " + std::to_string(masks.K) + ", targets " + targets;
}

}  // namespace tjepa_bench
