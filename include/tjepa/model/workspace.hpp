#pragma once
// Workspace: the caller-owned scratch of every module's forward and backward. Buffers grow on
// demand and never shrink, so once a shape has been seen, running it again allocates nothing.
// Activations kept for backward are not here but in each module's cache (EncoderCache, ...).
// One Workspace serves one call at a time; modules called one after the other may share it.
#include <cstddef>
#include <vector>

#include "tjepa/core/aligned.hpp"
#include "tjepa/core/detail/parallel.hpp"
#include "tjepa/kernels/attention.hpp"
#include "tjepa/kernels/linear.hpp"
#include "tjepa/model/stage_clock.hpp"

namespace tjepa {

template <class T>
struct Workspace {
  // Forward scratch (M = rows = B·L).
  AlignedVector<T> x;       // [M, d] running activation of the inference path
  AlignedVector<T> stream;  // [M, d] residual stream of a stack that keeps only some rows
  AlignedVector<T> ln;      // [M, d] LayerNorm output
  AlignedVector<T> qkv;     // [M, 3d]; the probe's attention weights [M, H] (its backward: their gradient)
  AlignedVector<T> att;     // [M, d] attention output before proj
  AlignedVector<T> hidden;  // [M, hidden] MLP activation (training)
  AlignedVector<T> mlp;     // the row-tiled inference MLP: packed weights + [tile, hidden] per thread
  AlignedVector<T> branch;  // [M, d] a residual branch under drop-path; the probe's pooled tokens [B, H, d]
  AlignedVector<T> scales;  // [depth, 2, B] drop-path scales of the inference path
  AlignedVector<T> rows;    // [rows, ·] gathered rows (predictor targets, tokenizer groups); the probe's query
  AlignedVector<T> rows2;   // [rows, ·] second gathered buffer; the probe's folded keys, then its norm2 output
  std::vector<int> index;   // [M] row indices (the encoder's token types)
  AlignedVector<T> registers;  // [B·(R + K), d] the encoder's output (or its gradient) with its register rows
  // Backward scratch.
  AlignedVector<T> dx;       // [M, d] gradient flowing down the residual stream
  AlignedVector<T> dbranch;  // [M, d]; the probe's inference copy of its tokens with padded rows zeroed
  AlignedVector<T> dln;      // [M, d]
  AlignedVector<T> dqkv;     // [M, 3d]
  AlignedVector<T> dhidden;  // [M, hidden]
  AlignedVector<T> hidden2;  // [M, hidden] recomputed activation
  AlignedVector<T> drows;    // [rows, ·]; the probe's ∂pooled [B, H, d]
  AlignedVector<T> dkept;    // [B·Lk, d] gradient of the rows a stack keeps; the probe's ∂u per sample [B, H, d]
  // How the forward products of the tokenizer, the encoder (qkv, proj, MLP) and the predictor's
  // blocks read their weights:
  // - frozen_weights: inference on weights that do not change between calls (a frozen encoder in
  //   a control loop): each weight is packed once, into `packed`, instead of on every call. Clear
  //   `packed` when the values change (its entries are keyed by address).
  // - precision: Precision::bf16 runs those products with bf16 operands and fp32 accumulation
  //   (AVX512-BF16; a build without it computes fp32). Attention, norms, activations between the
  //   products, backward passes and the parameters stay fp32.
  bool frozen_weights = false;
  Precision precision = Precision::fp32;
  kernels::PackedWeights<T> packed;
  // The cache the modules pass to their products; nullptr: fp32, packed per call.
  kernels::PackedWeights<T>* weights() {
    if (!frozen_weights && precision == Precision::fp32) return nullptr;
    packed.keep = frozen_weights;
    packed.precision = precision;
    return &packed;
  }
  // Times the stages of inference calls when set (StageClock); nullptr: off.
  StageClock* clock = nullptr;
  void mark(const char* stage) {
    if (clock) clock->mark(stage);
  }
  // One attention workspace per OpenMP thread.
  std::vector<kernels::AttentionWorkspace<T>> attention;

  // Every thread's workspace, each reserved for `shape` here, before the parallel loop: which
  // thread runs which (dynamically scheduled) task varies from call to call, so a workspace
  // left to grow on its thread's first task could allocate in any later call.
  kernels::AttentionWorkspace<T>* attention_per_thread(const kernels::AttentionShape& shape) {
    const auto n = static_cast<std::size_t>(detail::max_threads());
    if (attention.size() < n) attention.resize(n);
    for (auto& a : attention) a.reserve(shape);
    return attention.data();
  }
};

}  // namespace tjepa
