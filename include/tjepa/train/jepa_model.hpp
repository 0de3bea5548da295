#pragma once
// JepaModel: the three parameter sets of Tactile-JEPA and the modules that read them.
//
//   context    tokenizer + encoder (position table, blocks, final norm): trained
//   target     the same layout, the EMA copy of `context` (paper, Sec. III-B): never gets gradients
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
#include "tjepa/core/prefixed_params.hpp"
#include "tjepa/model/tokenizer.hpp"

namespace tjepa {

namespace detail {
// A transformer's width check, shared by the encoder and predictor parts of the configs.
inline void check_width(const char* who, const char* part, int dim, int depth, int heads, double mlp_ratio) {
  require<ConfigError>(dim > 0 && depth > 0 && heads > 0 && dim % heads == 0 && mlp_ratio > 0 && std::isfinite(mlp_ratio),
                       who, ": ", part, " dim = ", dim, ", depth = ", depth, ", heads = ", heads,
                       ", mlp_ratio = ", mlp_ratio, ", expected positive, with heads dividing dim");
}
}  // namespace detail

// The context encoder's side of a model config: the tokenizer and the encoder. JepaConfig and
// MaeConfig (baselines/mae.hpp) both extend it, so both build the same `context_encoder.` tensors.
struct ContextEncoderConfig {
  // Tokenizer input per token: m·τ values (one token per taxel), or with group_size set, the
  // m·τ values of each taxel of a group (DECO-50: groups of 4 and 5 taxels).
  int in_dim = 30;
  // m: values per taxel and frame; in_dim = m·τ. The per-taxel tokenizer's weight is [d, m, τ].
  int axes = 1;
  std::vector<int> group_size;  // [N tokens] taxels per token; empty: one token per taxel
  EncoderConfig encoder;        // encoder.num_tokens = N
  // Std of the tokenizer's initial bias (the reference: 0). With a zero bias, LayerNorm(W·x) does
  // not see the scale of x, so an idle taxel's noise becomes a token as loud as a contact; a bias
  // well above W·noise maps idle taxels to one "no contact" token and lets a token's direction
  // carry the contact's amplitude. Init only: checkpoints are unaffected.
  double tokenizer_bias_std = 0.0;
  // The per-taxel tokenizer's temporal zero padding (Tokenizer::per_taxel): 0, or the 2 of the
  // reference's checkpoints that predate its `_temporal_patch_version` marker.
  int temporal_padding = 0;

  // A config C (deriving from this one) at its defaults, with the reference's ViT-Tiny encoder
  // for num_tokens tokens of in_dim = m·τ values, m = axes.
  template <class C>
  static C reference_for(int num_tokens, int in_dim, int axes) {
    C c;
    c.in_dim = in_dim;
    c.axes = axes;
    c.encoder.num_tokens = num_tokens;
    return c;
  }

  // `who` names the config in the messages ("JepaConfig", "MaeConfig").
  void validate_encoder(const char* who) const {
    require<ConfigError>(encoder.num_tokens > 0, who, ": encoder.num_tokens = ", encoder.num_tokens,
                         ", expected > 0");
    detail::check_width(who, "encoder", encoder.dim, encoder.depth, encoder.heads, encoder.mlp_ratio);
    require<ConfigError>(in_dim > 0, who, ": in_dim = ", in_dim, ", expected > 0");
    require<ConfigError>(tokenizer_bias_std >= 0 && std::isfinite(tokenizer_bias_std), who,
                         ": tokenizer_bias_std = ", tokenizer_bias_std, ", expected >= 0");
    require<ConfigError>(axes > 0 && in_dim % axes == 0, who, ": axes = ", axes,
                         ", expected > 0 and dividing in_dim = ", in_dim, " (in_dim = m·τ)");
    require<ConfigError>(group_size.empty() || static_cast<int>(group_size.size()) == encoder.num_tokens, who,
                         ": group_size has ", group_size.size(), " entries, expected encoder.num_tokens = ",
                         encoder.num_tokens, " (or none)");
    require<ConfigError>(temporal_padding == 0 || (group_size.empty() && 2 * temporal_padding < in_dim / axes), who,
                         ": temporal_padding = ", temporal_padding,
                         ", expected 0, or with the per-taxel tokenizer 2·padding < τ = ", in_dim / axes);
    require<ConfigError>(static_cast<int>(encoder.token_type.size()) == (encoder.token_types > 0 ? encoder.num_tokens : 0),
                         who, ": encoder.token_type has ", encoder.token_type.size(), " entries for ",
                         encoder.token_types, " types, expected num_tokens = ", encoder.num_tokens,
                         " with types, none without");
    for (std::size_t i = 0; i < encoder.token_type.size(); ++i)
      require<ConfigError>(encoder.token_type[i] >= 0 && encoder.token_type[i] < encoder.token_types, who,
                           ": encoder.token_type[", i, "] = ", encoder.token_type[i], ", expected in [0, ",
                           encoder.token_types, ")");
  }

  // Reads the keys encoder_json writes into this config; a missing key or a wrong type throws E
  // naming `where` and the key.
  template <class E>
  void read_encoder_json(const nlohmann::json& j, const std::string& where) {
    json_read<E>(j, "in_dim", in_dim, where);
    json_read<E>(j, "axes", axes, where);
    json_read<E>(j, "group_size", group_size, where);
    json_read<E>(j, "tokenizer_bias_std", tokenizer_bias_std, where);
    const auto e = json_get<nlohmann::json, E>(j, "encoder", where);
    const std::string we = where + ": encoder";
    json_read<E>(e, "num_tokens", encoder.num_tokens, we);
    json_read<E>(e, "dim", encoder.dim, we);
    json_read<E>(e, "depth", encoder.depth, we);
    json_read<E>(e, "heads", encoder.heads, we);
    json_read<E>(e, "mlp_ratio", encoder.mlp_ratio, we);
    json_read<E>(e, "bias", encoder.bias, we);
    json_read<E>(e, "eps", encoder.eps, we);
    // Written only when set (files from before them lack them).
    if (j.contains("temporal_padding")) json_read<E>(j, "temporal_padding", temporal_padding, where);
    if (e.contains("token_types")) json_read<E>(e, "token_types", encoder.token_types, we);
    if (e.contains("token_type")) json_read<E>(e, "token_type", encoder.token_type, we);
  }

  nlohmann::json encoder_json() const {
    const auto& e = encoder;
    nlohmann::json j = {{"in_dim", in_dim},
                        {"axes", axes},
                        {"group_size", group_size},
                        {"tokenizer_bias_std", tokenizer_bias_std},
                        {"encoder",
                         {{"num_tokens", e.num_tokens}, {"dim", e.dim}, {"depth", e.depth}, {"heads", e.heads},
                          {"mlp_ratio", e.mlp_ratio}, {"bias", e.bias}, {"eps", e.eps}}}};
    if (temporal_padding != 0) j["temporal_padding"] = temporal_padding;
    if (e.token_types > 0) {
      j["encoder"]["token_types"] = e.token_types;
      j["encoder"]["token_type"] = e.token_type;
    }
    return j;
  }
};

// A PredictorConfig as JSON (out_dim only when set, so JEPA configs read as before).
inline nlohmann::json to_json(const PredictorConfig& p) {
  nlohmann::json j = {{"in_dim", p.in_dim}, {"dim", p.dim},         {"depth", p.depth}, {"heads", p.heads},
                      {"mlp_ratio", p.mlp_ratio}, {"bias", p.bias}, {"eps", p.eps}};
  if (p.out_dim != 0) j["out_dim"] = p.out_dim;
  return j;
}

// The inverse of to_json(PredictorConfig) (out_dim optional).
template <class E>
PredictorConfig predictor_from_json(const nlohmann::json& p, const std::string& where) {
  PredictorConfig c;
  json_read<E>(p, "in_dim", c.in_dim, where);
  json_read<E>(p, "dim", c.dim, where);
  json_read<E>(p, "depth", c.depth, where);
  json_read<E>(p, "heads", c.heads, where);
  json_read<E>(p, "mlp_ratio", c.mlp_ratio, where);
  json_read<E>(p, "bias", c.bias, where);
  json_read<E>(p, "eps", c.eps, where);
  if (p.contains("out_dim")) json_read<E>(p, "out_dim", c.out_dim, where);
  return c;
}

// Validates c, rethrowing a failure as E prefixed with `where` (a config read from a file).
template <class E, class C>
void validate_as(const C& c, const std::string& where) {
  try {
    c.validate();
  } catch (const Error& err) {
    fail<E>(where, ": ", err.what());
  }
}

struct JepaConfig : ContextEncoderConfig {
  PredictorConfig predictor;    // in_dim = encoder.dim; dim = encoder.dim (position rows are shared)

  // The paper's model (Sec. IV-D, architecture details): ViT-Tiny encoder, 4-block predictor of
  // width 192.
  static JepaConfig reference(int num_tokens, int in_dim, int axes = 1) {
    return reference_for<JepaConfig>(num_tokens, in_dim, axes);
  }

  void validate() const {
    validate_encoder("JepaConfig");
    detail::check_width("JepaConfig", "predictor", predictor.dim, predictor.depth, predictor.heads, predictor.mlp_ratio);
    require<ConfigError>(predictor.in_dim == encoder.dim, "JepaConfig: predictor.in_dim = ", predictor.in_dim,
                         ", expected encoder.dim = ", encoder.dim);
    require<ConfigError>(predictor.dim == encoder.dim, "JepaConfig: predictor.dim = ", predictor.dim,
                         ", expected encoder.dim = ", encoder.dim,
                         " (the predictor adds the encoder's position rows in its own width)");
    require<ConfigError>(predictor.out_dim == 0 || predictor.out_dim == encoder.dim, "JepaConfig: predictor.out_dim = ",
                         predictor.out_dim, ", expected 0 or encoder.dim = ", encoder.dim,
                         " (the predictor predicts embeddings)");
  }

  // The inverse of to_json; a missing key or a wrong type throws E naming `where` and the key,
  // and the result is validated.
  template <class E = ConfigError>
  static JepaConfig from_json(const nlohmann::json& j, const std::string& where) {
    JepaConfig c;
    c.read_encoder_json<E>(j, where);
    c.predictor = predictor_from_json<E>(json_get<nlohmann::json, E>(j, "predictor", where), where + ": predictor");
    validate_as<E>(c, where);
    return c;
  }

  nlohmann::json to_json() const {
    nlohmann::json j = encoder_json();
    j["predictor"] = tjepa::to_json(predictor);
    return j;
  }
};

// Registers the context encoder's tensors on ps, in the order and with the names of JepaModel's
// `context`: the tokenizer (patch_embed.* or tokenizer.*), then pos_embed, blocks.*, norm.*.
template <class T>
void add_context_encoder(ParamSet<T>& ps, const ContextEncoderConfig& c, Tokenizer& tokenizer, Encoder& encoder) {
  const int N = c.encoder.num_tokens, d = c.encoder.dim;
  tokenizer = c.group_size.empty()
                  ? Tokenizer::per_taxel(ps, N, c.axes, c.in_dim / c.axes, d, c.encoder.eps, "patch_embed.", c.temporal_padding)
                  : Tokenizer::grouped(ps, c.group_size, c.in_dim, d, c.encoder.eps);
  encoder = Encoder(ps, c.encoder);
}

// Initializes an allocated context encoder as the reference implementation does (init_params,
// model/init.hpp; seeded), then the tokenizer's bias with c.tokenizer_bias_std: the same seed
// gives JepaModel and MaeModel the same encoder.
template <class T>
void init_context_encoder(ParamSet<T>& ps, const Tokenizer& tokenizer, const ContextEncoderConfig& c,
                          std::uint64_t seed) {
  init_params(ps, seed);
  if (c.tokenizer_bias_std > 0) {
    Rng r(seed, 0x746f6b62696173ull);  // "tokbias"
    for (const auto& m : tokenizer.maps) {
      T* b = ps.value(m.proj.bias);
      for (int i = 0; i < m.proj.out; ++i) b[i] = static_cast<T>(c.tokenizer_bias_std * r.normal());
    }
  }
}

namespace detail {
// set_positions' argument check: rows [N, d] row-major, all finite.
inline void check_position_rows(std::span<const double> rows, int N, int d, const char* who) {
  const std::size_t n = static_cast<std::size_t>(N) * d;
  require<ShapeError>(rows.size() == n, who, ": ", rows.size(), " values, expected N·d = ", N, "·", d);
  for (std::size_t i = 0; i < n; ++i) require<DataError>(std::isfinite(rows[i]), who, ": value ", i, " is ", rows[i]);
}
}  // namespace detail

template <class T>
class JepaModel {
 public:
  JepaConfig config;
  ParamSet<T> context, target, predictor_params;
  Tokenizer tokenizer;
  Encoder encoder;
  Predictor predictor;

  // Builds the modules, initializes context and predictor as the reference implementation does
  // (init_params, model/init.hpp; seeded), and copies the context encoder into the target encoder.
  JepaModel(const JepaConfig& c, std::uint64_t seed) : config(c) {
    c.validate();
    add_context_encoder(context, c, tokenizer, encoder);
    predictor = Predictor(predictor_params, c.predictor, "");
    context.allocate();
    predictor_params.allocate();
    init_context_encoder(context, tokenizer, c, seed);
    init_params(predictor_params, seed ^ 0x7072656469637472ull);  // "predictr": an unrelated stream
    target = context;
  }

  // Overwrites the position table, e_i of the context and of the target encoder, with rows
  // [N, d] (row-major), e.g. graph_positions(graph, d, k, scale, seed). Init only: call it before
  // training; the rows then train as the reference's table does.
  void set_positions(std::span<const double> rows) {
    detail::check_position_rows(rows, num_tokens(), dim(), "JepaModel::set_positions");
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
