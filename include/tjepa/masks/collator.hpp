#pragma once
// MaskCollator: a batch's context and target masks, as dense index tensors.
//
// Per batch (Rng(seed, batch_index)), in this order:
//   c   = max(1, ⌊N·U(context_ratio)⌋)
//   t_k = max(1, ⌊n_k·U(target_ratio)⌋) for each size slot k: one slot (n = N) for a one-part sensor,
//         one per part (n = the part's size) with per-part targets;
//   I-JEPA blocks: the target block shape, then the context block shape.
// Per sample i (its own stream Rng(seed ^ kSampleSalt, batch_index·B + i), so the result does not
// depend on the thread count):
//   targets (local: Dijkstra region; global: stratified/uniform; see local.hpp, global.hpp),
//   then the context (context.hpp) minus the union of the targets. If the context keeps fewer
//   than min_context() tokens it is redrawn, up to max_tries times; then the targets too, up to
//   max_tries times; then sample() throws a ConfigError that says why.
// Then every context is cut to the batch's smallest, K, keeping a random subset of each.
//
// Output (MaskBatch), B samples:
//   context         [B, K]     token ids, each row ascending
//   targets[j]      [B, t_j]   token ids, each row ascending; kind local/global/block, part (-1:
//                              whole sensor). Order: one-part sensors: num_local local, then
//                              num_global global targets (all of size t). Per-part targets: for
//                              each part p: num_local_per_part local, then num_global_per_part
//                              global targets of t_p = ⌊n_p·s_p⌋ tokens. I-JEPA blocks:
//                              blocks.num_targets blocks, each cut to the batch's smallest.
// Targets may overlap each other; they never overlap the context.
//
// A collator is not safe to call from several threads at once (it owns scratch buffers); it
// parallelizes over the samples itself (OpenMP, when available).
#include <algorithm>
#include <cstdint>
#include <exception>
#include <limits>
#include <optional>
#include <span>
#include <string>
#include <vector>

#ifdef _OPENMP
#include <omp.h>
#endif

#include "tjepa/core/error.hpp"
#include "tjepa/core/random.hpp"
#include "tjepa/graph/taxel_graph.hpp"
#include "tjepa/masks/config.hpp"
#include "tjepa/masks/context.hpp"
#include "tjepa/masks/workspace.hpp"
#include "tjepa/masks/domain.hpp"
#include "tjepa/masks/global.hpp"
#include "tjepa/masks/ijepa_blocks.hpp"
#include "tjepa/masks/local.hpp"

namespace tjepa {

enum class TargetKind { local, global, block };

inline const char* to_string(TargetKind k) {
  switch (k) {
    case TargetKind::local: return "local";
    case TargetKind::global: return "global";
    case TargetKind::block: return "block";
  }
  return "?";
}

struct TargetSet {
  int size = 0;                          // t: tokens per row
  TargetKind kind = TargetKind::local;
  int part = -1;                         // -1: drawn over the whole sensor
  std::vector<int> indices;              // [B, size], each row ascending

  std::span<const int> row(int b) const {
    return {indices.data() + static_cast<std::size_t>(b) * size, static_cast<std::size_t>(size)};
  }
};

struct MaskBatch {
  int B = 0;
  int K = 0;                             // context tokens per sample
  std::vector<int> context;              // [B, K], each row ascending
  std::vector<TargetSet> targets;        // [num targets], each [B, size]

  std::span<const int> context_row(int b) const {
    return {context.data() + static_cast<std::size_t>(b) * K, static_cast<std::size_t>(K)};
  }
  int num_targets() const { return static_cast<int>(targets.size()); }

  // Samples [first, first + count) as a batch of their own, into out (its buffers reused). A data
  // parallel rank draws the whole batch, whose shared sizes and context cut depend on every
  // sample, and keeps its shard: the masks of sample i do not depend on the number of ranks.
  void slice_into(MaskBatch& out, int first, int count) const {
    require<ShapeError>(first >= 0 && count > 0 && first + count <= B, "MaskBatch::slice: samples [", first, ", ",
                        first + count, ") of a batch of ", B);
    out.B = count;
    out.K = K;
    const auto rows = [](const std::vector<int>& v, int width, int b0, int n) {
      return std::span<const int>(v).subspan(static_cast<std::size_t>(b0) * width, static_cast<std::size_t>(n) * width);
    };
    const auto ctx = rows(context, K, first, count);
    out.context.assign(ctx.begin(), ctx.end());
    out.targets.resize(targets.size());
    for (std::size_t j = 0; j < targets.size(); ++j) {
      const TargetSet& src = targets[j];
      TargetSet& dst = out.targets[j];
      dst.size = src.size;
      dst.kind = src.kind;
      dst.part = src.part;
      const auto t = rows(src.indices, src.size, first, count);
      dst.indices.assign(t.begin(), t.end());
    }
  }
};

// The sizes a batch uses (drawn from Rng(seed, batch_index)).
struct MaskBatchSizes {
  int context = 0;                       // c, before the targets are removed
  std::vector<int> target;               // [num targets] t_j (block scheme: 0, sizes vary)
  BlockShape target_block{}, context_block{};
};

class MaskCollator {
 public:
  // Salt of the per-sample streams: sample i of batch b draws from Rng(seed ^ kSampleSalt, b·B + i).
  static constexpr std::uint64_t kSampleSalt = 0x6D61736B73616D70ull;  // "masksamp"

  // Throws ConfigError on a configuration that cannot work on this graph (see validate below);
  // the I-JEPA block scheme needs a grid placement of the graph's tokens.
  explicit MaskCollator(TaxelGraph graph, MaskConfig config = {},
                        std::optional<GridPlacement> grid = std::nullopt)
      : graph_(std::move(graph)), cfg_(config) {
    pieces_ = part_pieces(graph_);
    domains_.emplace_back(graph_, pieces_, -1);
    for (int p = 0; p < graph_.num_parts(); ++p) domains_.emplace_back(graph_, pieces_, p);
    if (grid) blocks_ = BlockMasker(std::move(*grid));
    validate(grid.has_value());
  }

  const TaxelGraph& graph() const { return graph_; }
  const MaskConfig& config() const { return cfg_; }
  int num_tokens() const { return graph_.num_nodes(); }
  int num_targets() const { return static_cast<int>(specs_.size()); }
  // The fewest tokens a context may keep: max(min_context_tokens, ⌈min_context_ratio·N⌉, 1), where
  // min_context_tokens -1 (the default) is min(32, ⌊⌊N·context_ratio.lo⌋/2⌋): 32 from 128 tokens
  // on, and half the smallest context draw on a small skin, which leaves room for its targets.
  int min_context() const { return min_context_; }
  bool per_part() const { return per_part_; }
  const MaskDomain& domain(int part) const { return domains_[part + 1]; }  // -1: whole sensor

  MaskBatchSizes batch_sizes(std::uint64_t seed, std::uint64_t batch_index) const {
    Rng rng(seed, batch_index);
    MaskBatchSizes s;
    const int n = num_tokens();
    s.target.assign(specs_.size(), 0);
    if (cfg_.scheme == TargetScheme::ijepa_blocks) {
      s.target_block = blocks_.sample_shape(cfg_.blocks.target_scale, cfg_.blocks.target_aspect, rng);
      s.context_block = blocks_.sample_shape(cfg_.blocks.context_scale, cfg_.blocks.context_aspect, rng);
      return s;
    }
    s.context = std::max(1, size_from_ratio(n, cfg_.context_ratio, rng));
    std::vector<int> slot_size(slot_domain_.size());
    for (std::size_t k = 0; k < slot_domain_.size(); ++k)
      slot_size[k] = std::max(1, size_from_ratio(domains_[slot_domain_[k]].size(), cfg_.target_ratio, rng));
    for (std::size_t j = 0; j < specs_.size(); ++j) s.target[j] = slot_size[specs_[j].slot];
    return s;
  }

  MaskBatch sample(int batch_size, std::uint64_t seed, std::uint64_t batch_index) const {
    MaskBatch out;
    sample_into(out, batch_size, seed, batch_index);
    return out;
  }

  // As sample(), reusing out's buffers.
  void sample_into(MaskBatch& out, int batch_size, std::uint64_t seed, std::uint64_t batch_index) const {
    require<ConfigError>(batch_size >= 1, "MaskCollator::sample: batch_size = ", batch_size,
                         ", expected >= 1");
    const int B = batch_size;
    const int n = num_tokens();
    const int T = num_targets();
    const MaskBatchSizes sizes = batch_sizes(seed, batch_index);
    const bool blocks = cfg_.scheme == TargetScheme::ijepa_blocks;

    // Rows of the scratch: contexts [B, N]; block targets [T, B, N] (their sizes vary).
    ctx_buf_.resize(static_cast<std::size_t>(B) * n);
    ctx_len_.assign(B, 0);
    errors_.assign(B, nullptr);
    out.B = B;
    out.targets.resize(T);
    for (int j = 0; j < T; ++j) {
      TargetSet& ts = out.targets[j];
      ts.kind = specs_[j].kind;
      ts.part = domains_[specs_[j].domain].part();
      ts.size = sizes.target[j];
      ts.indices.resize(static_cast<std::size_t>(B) * ts.size);
    }
    if (blocks) {
      tgt_buf_.resize(static_cast<std::size_t>(T) * B * n);
      tgt_len_.assign(static_cast<std::size_t>(T) * B, 0);
    }

    const int threads = num_threads(B);
    if (static_cast<int>(ws_.size()) < threads) ws_.resize(threads);
    for (auto& w : ws_) w.resize(n);

#ifdef _OPENMP
#pragma omp parallel for schedule(dynamic, 4) num_threads(threads)
#endif
    for (int i = 0; i < B; ++i) {
      MaskWorkspace& ws = thread_workspace();
      try {
        Rng rng(seed ^ kSampleSalt, batch_index * static_cast<std::uint64_t>(B) + i);
        if (blocks)
          sample_blocks_one(i, B, sizes, rng, ws);
        else
          sample_graph_one(i, B, sizes, rng, ws, out);
      } catch (...) {
        errors_[i] = std::current_exception();
      }
    }
    for (const auto& e : errors_)
      if (e) std::rethrow_exception(e);

    // Cut to the batch's smallest, keep a prefix of each row (rows are in random order), sort.
    const int K = *std::min_element(ctx_len_.begin(), ctx_len_.end());
    out.K = K;
    out.context.resize(static_cast<std::size_t>(B) * K);
    if (blocks)
      for (int j = 0; j < T; ++j) {
        int m = n;
        for (int i = 0; i < B; ++i) m = std::min(m, tgt_len_[static_cast<std::size_t>(j) * B + i]);
        out.targets[j].size = m;
        out.targets[j].indices.resize(static_cast<std::size_t>(B) * m);
      }
#ifdef _OPENMP
#pragma omp parallel for schedule(static) num_threads(threads)
#endif
    for (int i = 0; i < B; ++i) {
      MaskWorkspace& ws = thread_workspace();
      sorted_prefix(ctx_row(i), K, ws, out.context.data() + static_cast<std::size_t>(i) * K);
      if (blocks)
        for (int j = 0; j < T; ++j) {
          const int m = out.targets[j].size;
          sorted_prefix(tgt_row(j, i, B), m, ws, out.targets[j].indices.data() + static_cast<std::size_t>(i) * m);
        }
    }
  }

 private:
  struct TargetSpec {
    TargetKind kind;
    int domain;  // index into domains_
    int slot;    // size slot
  };

  static int size_from_ratio(int n, const RatioRange& r, Rng& rng) {
    return static_cast<int>(std::floor(n * rng.uniform(r.lo, r.hi)));
  }

  MaskWorkspace& thread_workspace() const {
#ifdef _OPENMP
    return ws_[omp_get_thread_num()];
#else
    return ws_[0];
#endif
  }

  int num_threads(int B) const {
#ifdef _OPENMP
    const int t = cfg_.num_threads > 0 ? cfg_.num_threads : omp_get_max_threads();
    return std::max(1, std::min(t, B));
#else
    (void)B;
    return 1;
#endif
  }

  // Scratch rows (the buffers are mutable scratch, so const methods hand out writable rows).
  std::span<int> ctx_row(int i) const {
    const std::size_t n = static_cast<std::size_t>(num_tokens());
    return {ctx_buf_.data() + static_cast<std::size_t>(i) * n, n};
  }
  std::span<int> tgt_row(int j, int i, int B) const {
    const std::size_t n = static_cast<std::size_t>(num_tokens());
    return {tgt_buf_.data() + (static_cast<std::size_t>(j) * B + i) * n, n};
  }

  // The first m entries of row, ascending, into dst.
  void sorted_prefix(std::span<const int> row, int m, MaskWorkspace& ws, int* dst) const {
    detail::sort_tokens(row.data(), m, ws.bits.data(), (num_tokens() + 63) / 64, dst);
  }

  [[noreturn]] void fail_context(int i, int best, int union_size, const std::string& drawn) const {
    fail<ConfigError>("MaskCollator: sample ", i, ": the context kept at most ", best, " of the ",
                      min_context_, " tokens it needs (min_context() from min_context_tokens = ",
                      cfg_.min_context_tokens, ", min_context_ratio = ", cfg_.min_context_ratio,
                      ", N = ", num_tokens(), ") after ", cfg_.max_tries, " x ", cfg_.max_tries,
                      " tries (context drawn: ", drawn, "; last union of targets: ", union_size,
                      " tokens); lower target_ratio or the number of targets, raise context_ratio, "
                      "or lower the context minimum");
  }

  void sample_graph_one(int i, int B, const MaskBatchSizes& sizes, Rng& rng, MaskWorkspace& ws,
                        MaskBatch& out) const {
    (void)B;
    const std::span<int> ctx = ctx_row(i);
    const std::span<const MaskDomain> parts(domains_.data() + 1, domains_.size() - 1);
    int best = 0, union_size = 0;
    for (int attempt = 0; attempt < cfg_.max_tries; ++attempt) {
      ws.excluded.clear();
      union_size = 0;
      for (std::size_t j = 0; j < specs_.size(); ++j) {
        TargetSet& ts = out.targets[j];
        const std::span<int> row(ts.indices.data() + static_cast<std::size_t>(i) * ts.size,
                                 static_cast<std::size_t>(ts.size));
        const MaskDomain& d = domains_[specs_[j].domain];
        if (specs_[j].kind == TargetKind::local)
          sample_local_mask(graph_, d, rng, ws, row);
        else
          sample_global_mask(d, cfg_.global_sampling, rng, ws, row);
        for (int v : row) union_size += ws.excluded.insert(v) ? 1 : 0;
      }
      for (int inner = 0; inner < cfg_.max_tries; ++inner) {
        const int kept = cfg_.context_sampling == ContextSampling::uniform
                             ? sample_uniform_context(num_tokens(), sizes.context, rng, ws, ctx)
                             : sample_local_context(graph_, parts, sizes.context, rng, ws, ctx);
        best = std::max(best, kept);
        if (kept >= min_context_) {
          ctx_len_[i] = kept;
          for (std::size_t j = 0; j < specs_.size(); ++j) {
            TargetSet& ts = out.targets[j];
            int* r = ts.indices.data() + static_cast<std::size_t>(i) * ts.size;
            std::copy(r, r + ts.size, ws.perm.data());
            detail::sort_tokens(ws.perm.data(), ts.size, ws.bits.data(), (num_tokens() + 63) / 64, r);
          }
          return;
        }
      }
    }
    fail_context(i, best, union_size, std::to_string(sizes.context) + " tokens");
  }

  void sample_blocks_one(int i, int B, const MaskBatchSizes& sizes, Rng& rng, MaskWorkspace& ws) const {
    const std::span<int> ctx = ctx_row(i);
    const int T = num_targets();
    int best = 0, union_size = 0;
    for (int attempt = 0; attempt < cfg_.max_tries; ++attempt) {
      ws.excluded.clear();
      union_size = 0;
      for (int j = 0; j < T; ++j) {
        const std::span<int> row = tgt_row(j, i, B);
        int len = 0;
        // On a sparse atlas a block can land on a gap; I-JEPA redraws such blocks.
        for (int tries = 0; tries < cfg_.max_tries && len == 0; ++tries)
          len = blocks_.sample_block(sizes.target_block, rng, nullptr, row);
        require<ConfigError>(len > 0, "MaskCollator: sample ", i, ": a ", sizes.target_block.h, " x ",
                             sizes.target_block.w, " target block held no token in ", cfg_.max_tries,
                             " places; raise blocks.target_scale");
        rng.shuffle(row.first(len));
        tgt_len_[static_cast<std::size_t>(j) * B + i] = len;
        for (int k = 0; k < len; ++k) union_size += ws.excluded.insert(row[k]) ? 1 : 0;
      }
      for (int inner = 0; inner < cfg_.max_tries; ++inner) {
        const int kept = blocks_.sample_block(sizes.context_block, rng, &ws.excluded, ctx);
        best = std::max(best, kept);
        if (kept >= min_context_) {
          rng.shuffle(ctx.first(kept));
          ctx_len_[i] = kept;
          return;
        }
      }
    }
    fail_context(i, best, union_size,
                 std::to_string(sizes.context_block.h) + " x " + std::to_string(sizes.context_block.w) + " block");
  }

  static std::string domain_name(const MaskDomain& d) {
    return d.part() < 0 ? std::string("the sensor") : "part " + std::to_string(d.part());
  }

  // Throws ConfigError unless the configuration can work on this graph.
  void validate(bool has_grid) {
    const int n = num_tokens();
    const MaskConfig& c = cfg_;
    validate_mask_config(c);
    // Automatic (-1): 32, capped at half the smallest context draw so that a small skin keeps room
    // for its targets.
    const bool ratio_ok = c.context_ratio.lo > 0 && c.context_ratio.lo < 1;  // unchecked under ijepa_blocks
    const int automatic = ratio_ok ? std::min(32, static_cast<int>(std::floor(n * c.context_ratio.lo)) / 2) : 32;
    const int tokens = c.min_context_tokens >= 0 ? c.min_context_tokens : automatic;
    min_context_ = std::max({tokens, static_cast<int>(std::ceil(c.min_context_ratio * n - 1e-9)), 1});
    require<ConfigError>(min_context_ <= n, "MaskConfig: the context minimum max(", tokens, ", ceil(",
                         c.min_context_ratio, " * ", n, ")) = ", min_context_, ", expected in [1, N = ", n, "]");

    if (c.scheme == TargetScheme::ijepa_blocks) {
      require<ConfigError>(has_grid, "MaskCollator: scheme ijepa_blocks needs a grid placement of the ",
                           n, " tokens");
      require<ShapeError>(blocks_.grid().size() == n, "MaskCollator: the grid placement has ",
                          blocks_.grid().size(), " tokens, expected ", n);
      require<ConfigError>(c.blocks.num_targets <= n,
                           "MaskConfig: blocks.num_targets = ", c.blocks.num_targets,
                           ", expected in [1, N = ", n, "]");
      for (int j = 0; j < c.blocks.num_targets; ++j) specs_.push_back({TargetKind::block, 0, 0});
      return;
    }

    per_part_ = c.part_targets == PartTargets::per_part ||
                (c.part_targets == PartTargets::automatic && graph_.num_parts() >= 2);
    const int nl = per_part_ ? c.num_local_per_part : c.num_local;
    const int ng = per_part_ ? c.num_global_per_part : c.num_global;
    const char* nl_name = per_part_ ? "num_local_per_part" : "num_local";
    const char* ng_name = per_part_ ? "num_global_per_part" : "num_global";
    require<ConfigError>(nl >= 0 && ng >= 0 && nl + ng >= 1, "MaskConfig: ", nl_name, " = ", nl, ", ",
                         ng_name, " = ", ng, ", expected >= 0 each and at least one target");
    const int slots = per_part_ ? graph_.num_parts() : 1;
    for (int k = 0; k < slots; ++k) {
      const int dom = per_part_ ? k + 1 : 0;
      slot_domain_.push_back(dom);
      for (int j = 0; j < nl; ++j) specs_.push_back({TargetKind::local, dom, k});
      for (int j = 0; j < ng; ++j) specs_.push_back({TargetKind::global, dom, k});
    }
    require<ConfigError>(num_targets() <= n, "MaskConfig: ", num_targets(),
                         " targets per sample, more than the ", n, " tokens");

    for (std::size_t k = 0; k < slot_domain_.size(); ++k) {
      const MaskDomain& d = domains_[slot_domain_[k]];
      const int tmax = std::max(1, static_cast<int>(std::floor(d.size() * c.target_ratio.hi)));
      if (nl > 0)
        require<ConfigError>(d.largest_piece() >= tmax, "MaskConfig: local targets of up to t = ", tmax,
                             " tokens, but the largest connected piece of ",
                             domain_name(d),
                             " holds ", d.largest_piece(), "; lower target_ratio.hi");
    }

    const int cmin = static_cast<int>(std::floor(n * c.context_ratio.lo));
    require<ConfigError>(cmin >= min_context_, "MaskConfig: the context can be drawn with c = floor(", n,
                         " * context_ratio.lo = ", c.context_ratio.lo, ") = ", cmin,
                         " tokens, fewer than its minimum ", min_context_,
                         "; raise context_ratio.lo or lower min_context_tokens/min_context_ratio");
    if (c.context_sampling == ContextSampling::local) {
      // The largest share each part can get (shares grow with c).
      const int cmax = static_cast<int>(std::floor(n * c.context_ratio.hi));
      long long before = 0;
      for (int p = 0; p < graph_.num_parts(); ++p) {
        const MaskDomain& d = domains_[p + 1];
        const int share = detail::local_context_share(cmax, before, before + d.size(), n);
        before += d.size();
        require<ConfigError>(share <= d.largest_piece(), "MaskConfig: a local context gives part ", p,
                             " up to ", share, " tokens, but its largest connected piece holds ",
                             d.largest_piece(), "; lower context_ratio.hi or use the uniform context");
      }
    }
  }

  TaxelGraph graph_;
  MaskConfig cfg_;
  GraphPieces pieces_;
  std::vector<MaskDomain> domains_;  // [0] whole sensor, [1 + p] part p
  std::vector<TargetSpec> specs_;
  std::vector<int> slot_domain_;     // size slot -> domain
  bool per_part_ = false;
  BlockMasker blocks_;
  int min_context_ = 0;

  // Scratch, reused across calls.
  mutable std::vector<MaskWorkspace> ws_;
  mutable std::vector<int> ctx_buf_, ctx_len_;  // [B, N], [B]
  mutable std::vector<int> tgt_buf_, tgt_len_;  // [T, B, N], [T, B] (block scheme)
  mutable std::vector<std::exception_ptr> errors_;
};

// The mask sizes the first `batches` batches of a run draw (MaskCollator::batch_sizes with the
// mask stream's seed): the context c before the targets are removed, and every target t_j. What a
// run predicts is easy to misjudge on a small skin: parts of 12 tokens and target ratios of 0.15
// make every target one token. The block scheme's sizes vary per sample: targets are not counted.
struct MaskSizeSummary {
  int batches = 0;
  int context_min = 0, context_max = 0;
  double context_mean = 0;
  int target_min = 0, target_max = 0;  // 0, 0: the block scheme
  double target_mean = 0;
};

inline MaskSizeSummary summarize_mask_sizes(const MaskCollator& c, std::uint64_t mask_seed, int batches = 256) {
  require<ConfigError>(batches > 0, "summarize_mask_sizes: batches = ", batches, ", expected > 0");
  MaskSizeSummary s;
  s.batches = batches;
  s.context_min = s.target_min = std::numeric_limits<int>::max();
  long long context_sum = 0, target_sum = 0, targets = 0;
  for (int b = 0; b < batches; ++b) {
    const MaskBatchSizes z = c.batch_sizes(mask_seed, static_cast<std::uint64_t>(b));
    s.context_min = std::min(s.context_min, z.context), s.context_max = std::max(s.context_max, z.context);
    context_sum += z.context;
    for (int t : z.target) {
      if (t <= 0) continue;
      s.target_min = std::min(s.target_min, t), s.target_max = std::max(s.target_max, t);
      target_sum += t, ++targets;
    }
  }
  s.context_mean = static_cast<double>(context_sum) / batches;
  if (targets == 0) s.target_min = s.target_max = 0;
  else s.target_mean = static_cast<double>(target_sum) / static_cast<double>(targets);
  return s;
}

}  // namespace tjepa
