#pragma once
// JepaModel: the three parameter sets of Tactile-JEPA and the modules that read them.
//
//   context    tokenizer + encoder (position table, blocks, final norm): trained
//   target     the same layout, the EMA copy of `context` (REFERENCE §5): never gets gradients
//   predictor  the predictor: trained
// Checkpoint prefixes are the reference module's attribute names: "context_encoder.",
// "target_encoder.", "predictor." (tensor names inside follow the reference PyTorch model).
#include <algorithm>
#include <cmath>
#include <cstdint>
#include <span>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "tjepa/core/error.hpp"
#include "tjepa/core/json.hpp"
#include "tjepa/core/random.hpp"
#include "tjepa/model/encoder.hpp"
#include "tjepa/model/init.hpp"
#include "tjepa/model/predictor.hpp"
#include "tjepa/model/prefixed_params.hpp"
#include "tjepa/model/tokenizer.hpp"

namespace tjepa {

struct JepaConfig {
  // Tokenizer input per token: m·τ values (one token per taxel), or with group_size set, the
  // m·τ values of each taxel of a group (DECO-50: groups of 4 and 5 taxels).
  int in_dim = 30;
  // m: values per taxel and frame; in_dim = m·τ. The per-taxel tokenizer's weight is [d, m, τ].
  int axes = 1;
  std::vector<int> group_size;  // [N tokens] taxels per token; empty: one token per taxel
  EncoderConfig encoder;        // encoder.num_tokens = N
  PredictorConfig predictor;    // in_dim = encoder.dim; dim = encoder.dim (position rows are shared)
  // Std of the tokenizer's initial bias (the reference: 0). With a zero bias, LayerNorm(W·x) does
  // not see the scale of x, so an idle taxel's noise becomes a token as loud as a contact; a bias
  // well above W·noise maps idle taxels to one "no contact" token and lets a token's direction
  // carry the contact's amplitude. Init only: checkpoints are unaffected.
  double tokenizer_bias_std = 0.0;

  // The reference (REFERENCE §4): ViT-Tiny encoder, 4-block predictor of width 192.
  static JepaConfig reference(int num_tokens, int in_dim, int axes = 1) {
    JepaConfig c;
    c.in_dim = in_dim;
    c.axes = axes;
    c.encoder.num_tokens = num_tokens;
    return c;
  }

  void validate() const {
    auto check_width = [](const char* part, int dim, int depth, int heads, double mlp_ratio) {
      require<ConfigError>(dim > 0 && depth > 0 && heads > 0 && dim % heads == 0 && mlp_ratio > 0 &&
                               std::isfinite(mlp_ratio),
                           "JepaConfig: ", part, " dim = ", dim, ", depth = ", depth, ", heads = ", heads,
                           ", mlp_ratio = ", mlp_ratio, ", expected positive, with heads dividing dim");
    };
    require<ConfigError>(encoder.num_tokens > 0, "JepaConfig: encoder.num_tokens = ", encoder.num_tokens,
                         ", expected > 0");
    check_width("encoder", encoder.dim, encoder.depth, encoder.heads, encoder.mlp_ratio);
    check_width("predictor", predictor.dim, predictor.depth, predictor.heads, predictor.mlp_ratio);
    require<ConfigError>(in_dim > 0, "JepaConfig: in_dim = ", in_dim, ", expected > 0");
    require<ConfigError>(tokenizer_bias_std >= 0 && std::isfinite(tokenizer_bias_std),
                         "JepaConfig: tokenizer_bias_std = ", tokenizer_bias_std, ", expected >= 0");
    require<ConfigError>(axes > 0 && in_dim % axes == 0, "JepaConfig: axes = ", axes,
                         ", expected > 0 and dividing in_dim = ", in_dim, " (in_dim = m·τ)");
    require<ConfigError>(group_size.empty() || static_cast<int>(group_size.size()) == encoder.num_tokens,
                         "JepaConfig: group_size has ", group_size.size(), " entries, expected encoder.num_tokens = ",
                         encoder.num_tokens, " (or none)");
    require<ConfigError>(predictor.in_dim == encoder.dim, "JepaConfig: predictor.in_dim = ", predictor.in_dim,
                         ", expected encoder.dim = ", encoder.dim);
    require<ConfigError>(predictor.dim == encoder.dim, "JepaConfig: predictor.dim = ", predictor.dim,
                         ", expected encoder.dim = ", encoder.dim,
                         " (the predictor adds the encoder's position rows in its own width)");
  }

  // The inverse of to_json; a missing key or a wrong type throws E naming `where` and the key,
  // and the result is validated.
  template <class E = ConfigError>
  static JepaConfig from_json(const nlohmann::json& j, const std::string& where) {
    JepaConfig c;
    json_read<E>(j, "in_dim", c.in_dim, where);
    json_read<E>(j, "axes", c.axes, where);
    json_read<E>(j, "group_size", c.group_size, where);
    json_read<E>(j, "tokenizer_bias_std", c.tokenizer_bias_std, where);
    const auto e = json_get<nlohmann::json, E>(j, "encoder", where), p = json_get<nlohmann::json, E>(j, "predictor", where);
    const std::string we = where + ": encoder", wp = where + ": predictor";
    json_read<E>(e, "num_tokens", c.encoder.num_tokens, we);
    json_read<E>(e, "dim", c.encoder.dim, we);
    json_read<E>(e, "depth", c.encoder.depth, we);
    json_read<E>(e, "heads", c.encoder.heads, we);
    json_read<E>(e, "mlp_ratio", c.encoder.mlp_ratio, we);
    json_read<E>(e, "bias", c.encoder.bias, we);
    json_read<E>(e, "eps", c.encoder.eps, we);
    json_read<E>(p, "in_dim", c.predictor.in_dim, wp);
    json_read<E>(p, "dim", c.predictor.dim, wp);
    json_read<E>(p, "depth", c.predictor.depth, wp);
    json_read<E>(p, "heads", c.predictor.heads, wp);
    json_read<E>(p, "mlp_ratio", c.predictor.mlp_ratio, wp);
    json_read<E>(p, "bias", c.predictor.bias, wp);
    json_read<E>(p, "eps", c.predictor.eps, wp);
    try {
      c.validate();
    } catch (const Error& err) {
      fail<E>(where, ": ", err.what());
    }
    return c;
  }

  nlohmann::json to_json() const {
    const auto& e = encoder;
    const auto& p = predictor;
    return {{"in_dim", in_dim},
            {"axes", axes},
            {"group_size", group_size},
            {"tokenizer_bias_std", tokenizer_bias_std},
            {"encoder",
             {{"num_tokens", e.num_tokens}, {"dim", e.dim}, {"depth", e.depth}, {"heads", e.heads},
              {"mlp_ratio", e.mlp_ratio}, {"bias", e.bias}, {"eps", e.eps}}},
            {"predictor",
             {{"in_dim", p.in_dim}, {"dim", p.dim}, {"depth", p.depth}, {"heads", p.heads},
              {"mlp_ratio", p.mlp_ratio}, {"bias", p.bias}, {"eps", p.eps}}}};
  }
};

template <class T>
class JepaModel {
 public:
  JepaConfig config;
  ParamSet<T> context, target, predictor_params;
  Tokenizer tokenizer;
  Encoder encoder;
  Predictor predictor;

  // Builds the modules, initializes context and predictor as REFERENCE §4 (seeded), and copies
  // the context encoder into the target encoder.
  JepaModel(const JepaConfig& c, std::uint64_t seed) : config(c) {
    c.validate();
    const int N = c.encoder.num_tokens, d = c.encoder.dim;
    tokenizer = c.group_size.empty()
                    ? Tokenizer::per_taxel(context, N, c.axes, c.in_dim / c.axes, d, c.encoder.eps)
                    : Tokenizer::grouped(context, c.group_size, c.in_dim, d, c.encoder.eps);
    encoder = Encoder(context, c.encoder);
    predictor = Predictor(predictor_params, c.predictor, "");
    context.allocate();
    predictor_params.allocate();
    init_params(context, seed);
    if (c.tokenizer_bias_std > 0) {
      Rng r(seed, 0x746f6b62696173ull);  // "tokbias"
      for (const auto& m : tokenizer.maps) {
        T* b = context.value(m.proj.bias);
        for (int i = 0; i < m.proj.out; ++i) b[i] = static_cast<T>(c.tokenizer_bias_std * r.normal());
      }
    }
    init_params(predictor_params, seed ^ 0x7072656469637472ull);  // "predictr": an unrelated stream
    target = context;
  }

  // Overwrites the position table, e_i of the context and of the target encoder, with rows
  // [N, d] (row-major), e.g. graph_positions(graph, d, k, scale, seed). Init only: call it before
  // training; the rows then train as the reference's table does.
  void set_positions(std::span<const double> rows) {
    const std::size_t n = static_cast<std::size_t>(num_tokens()) * dim();
    require<ShapeError>(rows.size() == n, "JepaModel::set_positions: ", rows.size(), " values, expected N·d = ",
                        num_tokens(), "·", dim());
    for (std::size_t i = 0; i < n; ++i)
      require<DataError>(std::isfinite(rows[i]), "JepaModel::set_positions: value ", i, " is ", rows[i]);
    for (ParamSet<T>* ps : {&context, &target}) std::copy(rows.begin(), rows.end(), ps->value(encoder.pos_embed()));
  }

  int num_tokens() const { return config.encoder.num_tokens; }
  int dim() const { return config.encoder.dim; }
  // Values per token row of the tokenizer's input x [B, N, width].
  int token_width() const { return tokenizer.width; }

  // What AdamW and gradient clipping see.
  std::vector<PrefixedParams<T>> trainable() { return {{"context_encoder.", &context}, {"predictor.", &predictor_params}}; }
  // Everything a checkpoint holds.
  std::vector<PrefixedParams<T>> parts() {
    return {{"context_encoder.", &context}, {"target_encoder.", &target}, {"predictor.", &predictor_params}};
  }
};

}  // namespace tjepa
