#pragma once
// Embeddings of windows by a frozen encoder: what probes train on and what `tjepa embed` writes.
//
//   out[s] = encoder(θ, tokenizer(θ, window ids[s]))        out [S, N, d], all N tokens
//
// Inference only (no cache, no drop-path); the workspace is reused, so after the first batch the
// loop allocates nothing but the output.
#include <algorithm>
#include <cstdint>
#include <functional>
#include <span>

#include "tjepa/core/error.hpp"
#include "tjepa/data/window_source.hpp"
#include "tjepa/model/encoder.hpp"
#include "tjepa/model/tokenizer.hpp"

namespace tjepa {

// progress(done, total) after every batch.
inline AlignedVector<float> embed_windows(const ParamSet<float>& ps, const Tokenizer& tokenizer, const Encoder& encoder,
                                          const WindowSource& src, std::span<const std::int64_t> ids, int batch = 32,
                                          const std::function<void(std::int64_t, std::int64_t)>& progress = {}) {
  require<ConfigError>(batch > 0, "embed_windows: batch = ", batch, ", expected > 0");
  require<ShapeError>(tokenizer.num_tokens == src.taxels() && tokenizer.width == src.length() * src.axes(),
                      "embed_windows: the tokenizer takes ", tokenizer.num_tokens, " tokens of ", tokenizer.width,
                      " values, the windows have ", src.taxels(), " taxels of ", src.length(), " frames x ", src.axes(),
                      " axes");
  const int N = encoder.num_tokens(), d = encoder.dim();
  const std::size_t per = static_cast<std::size_t>(N) * d;
  AlignedVector<float> out(ids.size() * per);
  AlignedVector<float> rows, tokens;
  Workspace<float> ws;
  WindowBatch wb;
  const auto S = static_cast<std::int64_t>(ids.size());
  for (std::int64_t s0 = 0; s0 < S; s0 += batch) {
    const int B = static_cast<int>(std::min<std::int64_t>(batch, S - s0));
    src.gather(ids.subspan(static_cast<std::size_t>(s0), static_cast<std::size_t>(B)), wb);
    float* tok = detail::grow(tokens, static_cast<std::size_t>(B) * per);
    windows_to_tokens(wb, rows);
    tokenizer.forward(ps, rows.data(), B, tok, ws);
    encoder.forward(ps, {tok, B}, out.data() + static_cast<std::size_t>(s0) * per, ws,
                    EncoderOptions{.register_rows = false});
    if (progress) progress(s0 + B, S);
  }
  return out;
}

}  // namespace tjepa
