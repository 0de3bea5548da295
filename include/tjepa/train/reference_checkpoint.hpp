#pragma once
// The reference implementation's checkpoints (E-Kovtun/tactile, tactile_ssl: XelaJEPAModule, the
// `model` entry of its Lightning Fabric checkpoints, as a safetensors state dict) in and out of a
// JepaModel.
//
//   const SafetensorsFile f = load_safetensors("ref.safetensors");   // torch_checkpoint.py wrote it
//   ReferenceFacts facts;
//   JepaConfig c = reference_model_config(f, opt, &facts);           // shapes, names, options
//   JepaModel<float> m(c, 0);
//   load_reference_state(f, m, opt);                                 // context, target, predictor
//   SafetensorsFile back = reference_state(m, facts, opt);            // the same tensors, bit for bit
//
// Names: the reference's state dict has the prefixes context_encoder., target_encoder. and
// predictor., and inside them tjepa's names (model/encoder.hpp, predictor.hpp, tokenizer.hpp) but
// for the per-taxel tokenizer's LayerNorm, patch_embed.layer_norm (patch_embed.norm is read too).
// What tjepa's model holds elsewhere or not at all:
//   pos_embed              rows in the reference's token order; tjepa's token j is the reference's
//                          token order[j] (the layout's recording columns), so rows are permuted
//   taxeltype_embed        [types, d]: added per token type (EncoderConfig::token_type, by default
//                          the Xela hand's: 4x4, 4x6, curved pads); all zeros = unused
//   xela_mean, xela_std    the in-model input normalization: ReferenceFacts, which the caller puts
//                          in the data preprocessing (Preprocessor::with_statistics)
//   _temporal_patch_version  int8 marker: absent or 0 = the Conv1d's temporal padding 2, >= 1 = 0
// Refused by name: any other tensor (register tokens, an encoder mask token, LayerScale, a
// class token), biases in some but not all of an encoder's linear maps, predictor biases, a
// predictor width other than the encoder's, several time chunks per window, tensors that differ
// between the two encoders in shape.
#include <algorithm>
#include <cmath>
#include <cstdint>
#include <map>
#include <set>
#include <span>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "tjepa/core/error.hpp"
#include "tjepa/core/json.hpp"
#include "tjepa/io/checkpoint.hpp"
#include "tjepa/io/safetensors.hpp"
#include "tjepa/sensors/allegro_xela.hpp"
#include "tjepa/train/jepa_model.hpp"
#include "tjepa/train/trained_model.hpp"

namespace tjepa {

// What a reference file holds beyond tjepa's model; reference_state writes it back.
struct ReferenceFacts {
  std::string patch_norm = "layer_norm";  // patch_embed.<patch_norm>.{weight,bias}
  int version_marker = 1;                 // _temporal_patch_version; -1: absent
  int unused_type_rows = 0;               // rows of an all-zero taxeltype_embed (not used by the model)
  std::vector<float> mean, std;           // xela_mean, xela_std (empty: absent)
  bool buffers_f64 = false;               // those buffers as float64 (a model moved to double)

  nlohmann::json to_json() const {
    return {{"patch_norm", patch_norm}, {"version_marker", version_marker}, {"unused_type_rows", unused_type_rows},
            {"mean", mean}, {"std", std}, {"buffers_f64", buffers_f64}};
  }
  static ReferenceFacts from_json(const nlohmann::json& j, const std::string& where) {
    ReferenceFacts f;
    json_read<FileError>(j, "patch_norm", f.patch_norm, where);
    json_read<FileError>(j, "version_marker", f.version_marker, where);
    json_read<FileError>(j, "unused_type_rows", f.unused_type_rows, where);
    json_read<FileError>(j, "mean", f.mean, where);
    json_read<FileError>(j, "std", f.std, where);
    json_read<FileError>(j, "buffers_f64", f.buffers_f64, where);
    require<FileError>(f.patch_norm == "layer_norm" || f.patch_norm == "norm", where, ": patch_norm '", f.patch_norm,
                       "', expected 'layer_norm' or 'norm'");
    require<FileError>(f.mean.size() == f.std.size(), where, ": ", f.mean.size(), " means and ", f.std.size(), " stds");
    return f;
  }
};

struct ReferenceOptions {
  int heads = 0;              // 0: by width, as the reference's factories (96, 192: 3; 384: 6; 768: 12)
  int temporal_padding = -1;  // -1: from _temporal_patch_version
  int axes = 0;               // grouped tokenizer only: values per taxel and frame (0: 1)
  std::vector<int> order;        // [tokens] tjepa token j = reference token order[j]; empty: the same order
  std::vector<int> token_types;  // [tokens] reference order; empty: the Xela hand's when the file uses types
  std::vector<int> group_size;   // grouped tokenizer: members of each token, reference order
};

namespace detail {
inline const Tensor& reference_tensor(const SafetensorsFile& f, const std::string& name) {
  require<FileError>(f.contains(name), f.source(), ": no tensor '", name, "' (not a Tactile-JEPA reference state dict?)");
  return f.at(name);
}

inline int count_blocks(const SafetensorsFile& f, const std::string& prefix) {
  int n = 0;
  while (f.contains(prefix + "blocks." + std::to_string(n) + ".norm1.weight")) ++n;
  return n;
}

inline bool all_zero(const Tensor& t) {
  return std::all_of(t.data.begin(), t.data.end(), [](std::byte b) { return b == std::byte{0}; });
}

// The tjepa name of a reference encoder tensor ("" for those tjepa keeps elsewhere).
inline std::string tjepa_encoder_name(const std::string& ref, const std::string& patch_norm) {
  const std::string p = "patch_embed." + patch_norm + ".";
  if (ref.starts_with(p)) return "patch_embed.norm." + ref.substr(p.size());
  return ref;
}
inline std::string reference_encoder_name(const std::string& name, const std::string& patch_norm) {
  if (name.starts_with("patch_embed.norm.")) return "patch_embed." + patch_norm + "." + name.substr(17);
  return name;
}

// The permutation order as checked: a permutation of [0, n).
inline std::vector<int> reference_order(const ReferenceOptions& opt, int n, const std::string& where) {
  if (opt.order.empty()) {
    std::vector<int> id(static_cast<std::size_t>(n));
    for (int i = 0; i < n; ++i) id[static_cast<std::size_t>(i)] = i;
    return id;
  }
  require<ConfigError>(static_cast<int>(opt.order.size()) == n, where, ": a token order of ", opt.order.size(),
                       " entries, the model has ", n, " tokens");
  std::vector<char> seen(static_cast<std::size_t>(n), 0);
  for (std::size_t j = 0; j < opt.order.size(); ++j) {
    const int c = opt.order[j];
    require<ConfigError>(c >= 0 && c < n && !seen[static_cast<std::size_t>(c)], where, ": order[", j, "] = ", c,
                         ", expected a permutation of 0..", n - 1);
    seen[static_cast<std::size_t>(c)] = 1;
  }
  return opt.order;
}
}  // namespace detail

// The JepaConfig of a reference state dict, from its tensor shapes and opt; facts (may be null)
// receives what the model does not hold. Throws FileError naming the file and the tensor for
// anything tjepa cannot represent, ConfigError for options that do not fit the file.
inline JepaConfig reference_model_config(const SafetensorsFile& f, const ReferenceOptions& opt,
                                         ReferenceFacts* facts = nullptr) {
  const std::string& src = f.source();
  const std::string ce = "context_encoder.", te = "target_encoder.", pr = "predictor.";
  ReferenceFacts fx;
  const Tensor& pos = detail::reference_tensor(f, ce + "pos_embed");
  require<FileError>(pos.shape.size() == 3 && pos.shape[0] == 1 && pos.shape[1] > 0 && pos.shape[2] > 0 &&
                         pos.shape[1] < (1 << 24) && pos.shape[2] < (1 << 16),
                     src, ": context_encoder.pos_embed has shape ", detail::shape_string(pos.shape),
                     ", expected [1, tokens, d]");
  const int P = static_cast<int>(pos.shape[1]), d = static_cast<int>(pos.shape[2]);
  JepaConfig c;
  c.encoder.num_tokens = P;
  c.encoder.dim = d;
  c.encoder.eps = 1e-6;
  c.predictor.eps = 1e-6;
  const bool grouped = !f.contains(ce + "patch_embed.proj.weight");
  if (!grouped) {
    const Tensor& w = f.at(ce + "patch_embed.proj.weight");
    require<FileError>(w.shape.size() == 3 && w.shape[0] == d && w.shape[1] > 0 && w.shape[2] > 0 &&
                           w.shape[1] * w.shape[2] < (1 << 24),
                       src, ": context_encoder.patch_embed.proj.weight has shape ",
                       detail::shape_string(w.shape), ", expected [d = ", d, ", channels, chunk]");
    c.axes = static_cast<int>(w.shape[1]);
    c.in_dim = static_cast<int>(w.shape[1] * w.shape[2]);
    fx.patch_norm = f.contains(ce + "patch_embed.layer_norm.weight") ? "layer_norm" : "norm";
    fx.version_marker = -1;
    if (f.contains(ce + "_temporal_patch_version")) {
      const Tensor& v = f.at(ce + "_temporal_patch_version");
      require<FileError>(v.dtype == Dtype::I8 && v.numel() == 1, src,
                         ": _temporal_patch_version is not one int8 value");
      fx.version_marker = static_cast<int>(static_cast<std::int8_t>(v.data[0]));
    }
    c.temporal_padding = opt.temporal_padding >= 0 ? opt.temporal_padding : fx.version_marker >= 1 ? 0 : 2;
  } else {
    require<ConfigError>(static_cast<int>(opt.group_size.size()) == P, src,
                         ": a grouped tokenizer (tokenizer.direct*): give the members of each of its ", P,
                         " tokens (ReferenceOptions::group_size)");
    for (int n : opt.group_size)
      require<ConfigError>(n > 0, src, ": group sizes must be > 0, got ", n);
    const int n0 = opt.group_size.front();
    const Tensor& w = detail::reference_tensor(f, ce + "tokenizer.direct" + std::to_string(n0) + ".0.weight");
    require<FileError>(w.shape.size() == 2 && w.shape[1] > 0 && w.shape[1] % n0 == 0 && w.shape[1] < (1 << 24), src,
                       ": tokenizer.direct", n0,
                       ".0.weight has shape ", detail::shape_string(w.shape), ", expected [d, ", n0, "·k]");
    c.in_dim = static_cast<int>(w.shape[1]) / n0;
    c.axes = opt.axes > 0 ? opt.axes : 1;
    const auto ord = detail::reference_order(opt, P, src);
    for (int j = 0; j < P; ++j) c.group_size.push_back(opt.group_size[static_cast<std::size_t>(ord[static_cast<std::size_t>(j)])]);
  }
  if (f.contains(ce + "xela_mean") || f.contains(ce + "xela_std")) {
    const Tensor& m = detail::reference_tensor(f, ce + "xela_mean");
    const Tensor& s = detail::reference_tensor(f, ce + "xela_std");
    require<FileError>(m.dtype == s.dtype && (m.dtype == Dtype::F32 || m.dtype == Dtype::F64) && m.numel() == s.numel(),
                       src, ": xela_mean / xela_std are not two float vectors of one dtype and size");
    fx.buffers_f64 = m.dtype == Dtype::F64;
    if (fx.buffers_f64) {
      const auto mv = m.to_vector<double>(), sv = s.to_vector<double>();
      fx.mean.assign(mv.begin(), mv.end());
      fx.std.assign(sv.begin(), sv.end());
      for (std::size_t i = 0; i < mv.size(); ++i)
        require<FileError>(double(fx.mean[i]) == mv[i] && double(fx.std[i]) == sv[i], src,
                           ": float64 xela_mean / xela_std not exact in float32");
    } else {
      fx.mean = m.to_vector<float>();
      fx.std = s.to_vector<float>();
    }
    for (float v : fx.std) require<FileError>(v > 0 && std::isfinite(v), src, ": xela_std holds ", v, ", expected > 0");
  }
  // Encoder blocks: depth, MLP width, biases (all or none).
  c.encoder.depth = detail::count_blocks(f, ce);
  require<FileError>(c.encoder.depth > 0, src, ": context_encoder has no blocks.0");
  const auto matrix = [&](const std::string& name, int cols) -> const Tensor& {
    const Tensor& t = detail::reference_tensor(f, name);
    require<FileError>(t.shape.size() == 2 && t.shape[0] > 0 && t.shape[0] < (1 << 24) && t.shape[1] == cols, src,
                       ": tensor '", name, "' has shape ", detail::shape_string(t.shape), ", expected [rows, ", cols, "]");
    return t;
  };
  c.encoder.mlp_ratio = static_cast<double>(matrix(ce + "blocks.0.mlp.fc1.weight", d).shape[0]) / d;
  const bool qb = f.contains(ce + "blocks.0.attn.qkv.bias"), pb = f.contains(ce + "blocks.0.attn.proj.bias"),
             fb = f.contains(ce + "blocks.0.mlp.fc1.bias");
  require<FileError>(qb == pb && pb == fb, src, ": context_encoder blocks with qkv_bias ", qb, ", proj_bias ", pb,
                     ", ffn_bias ", fb, "; tjepa's encoder has all three or none");
  c.encoder.bias = qb;
  int heads = opt.heads;
  if (heads == 0) {
    static const std::map<int, int> factory{{96, 3}, {192, 3}, {384, 6}, {768, 12}};
    const auto it = factory.find(d);
    require<ConfigError>(it != factory.end(), src, ": width ", d,
                         " is none of the reference's model sizes (96, 192, 384, 768): give the number of heads");
    heads = it->second;
  }
  c.encoder.heads = heads;
  // Token types.
  if (f.contains(ce + "taxeltype_embed")) {
    const Tensor& t = f.at(ce + "taxeltype_embed");
    require<FileError>(t.shape.size() == 2 && t.shape[1] == d, src, ": taxeltype_embed has shape ",
                       detail::shape_string(t.shape), ", expected [types, ", d, "]");
    const int rows = static_cast<int>(t.shape[0]);
    if (detail::all_zero(t) && detail::all_zero(detail::reference_tensor(f, te + "taxeltype_embed"))) {
      fx.unused_type_rows = rows;
    } else {
      std::vector<int> types = opt.token_types;
      if (types.empty()) {
        require<ConfigError>(P == layouts::allegro::kTaxels, src, ": taxeltype_embed is in use and the model has ",
                             P, " tokens, not the Xela hand's 368: give the type of each token");
        types = layouts::allegro::reference_taxel_types();
      }
      require<ConfigError>(static_cast<int>(types.size()) == P, src, ": ", types.size(), " token types for ", P, " tokens");
      const auto ord = detail::reference_order(opt, P, src);
      c.encoder.token_types = rows;
      for (int j = 0; j < P; ++j) c.encoder.token_type.push_back(types[static_cast<std::size_t>(ord[static_cast<std::size_t>(j)])]);
    }
  }
  // Predictor.
  c.predictor.in_dim = d;
  c.predictor.depth = detail::count_blocks(f, pr);
  require<FileError>(c.predictor.depth > 0, src, ": predictor has no blocks.0");
  c.predictor.dim = static_cast<int>(matrix(pr + "input_projection.weight", d).shape[0]);
  require<FileError>(c.predictor.dim == d, src, ": predictor width ", c.predictor.dim,
                     ", tjepa's predictor has the encoder's width ", d);
  c.predictor.heads = heads;
  c.predictor.mlp_ratio = static_cast<double>(matrix(pr + "blocks.0.mlp.fc1.weight", d).shape[0]) / d;
  for (const char* b : {"attn.qkv.bias", "attn.proj.bias", "mlp.fc1.bias", "mlp.fc2.bias"})
    require<FileError>(!f.contains(pr + "blocks.0." + b), src, ": predictor.blocks.0.", b,
                       ": tjepa's predictor blocks have no biases (the reference's default)");
  // Time chunks: the file's own config, when the conversion step recorded it.
  if (const auto it = f.metadata.find("reference.config"); it != f.metadata.end()) {
    const nlohmann::json rc = json_parse<FileError>(it->second, src + ": metadata 'reference.config'");
    if (rc.contains("sequence_length") && rc.contains("time_chunk_size") && !grouped)
      require<FileError>(rc["sequence_length"] == rc["time_chunk_size"], src, ": sequence_length ",
                         rc["sequence_length"].dump(), " over time chunks of ", rc["time_chunk_size"].dump(),
                         ": several tokens per taxel, tjepa has one token per taxel and window");
  }
  try {
    c.validate();
  } catch (const Error& e) {
    fail<FileError>(src, ": ", e.what());
  }
  // A model no larger than the file: metadata-sized allocations from a small file are refused.
  double held = 0;
  for (const std::string& name : f.names()) held += static_cast<double>(f.at(name).numel());
  require<FileError>(detail::jepa_weight_count(c) <= held, src, ": the tensors' shapes describe a model of about ",
                     detail::jepa_weight_count(c), " weights, the file holds ", held, " values");
  // Every tensor must be one tjepa reads (or a fact above).
  ParamSet<float> ctx, pred;
  Tokenizer tok;
  Encoder enc;
  add_context_encoder(ctx, c, tok, enc);
  Predictor p(pred, c.predictor, "");
  std::set<std::string> known;
  for (const auto& info : ctx.infos())
    for (const std::string& part : {ce, te}) known.insert(part + detail::reference_encoder_name(info.name, fx.patch_norm));
  for (const auto& info : pred.infos()) known.insert(pr + info.name);
  for (const std::string& part : {ce, te}) {
    for (const char* extra : {"xela_mean", "xela_std", "_temporal_patch_version"}) known.insert(part + extra);
    if (fx.unused_type_rows > 0) known.insert(part + "taxeltype_embed");
  }
  for (const std::string& name : f.names())
    require<FileError>(known.contains(name), src, ": tensor '", name, "' has no counterpart in tjepa's model",
                       name.find("register") != std::string::npos ? " (register tokens)"
                       : name.find("ls1") != std::string::npos || name.find("ls2") != std::string::npos
                           ? " (LayerScale)"
                           : "");
  if (facts) *facts = fx;
  return c;
}

// Loads a reference state dict into m (built from reference_model_config(f, opt)). Checks every
// tensor's dtype (T's) and shape before it changes anything.
template <class T>
void load_reference_state(const SafetensorsFile& f, JepaModel<T>& m, const ReferenceOptions& opt) {
  ReferenceFacts fx;
  (void)reference_model_config(f, opt, &fx);
  const int P = m.num_tokens(), d = m.dim();
  const auto ord = detail::reference_order(opt, P, f.source());
  for (int pass = 0; pass < 2; ++pass) {
    const bool copy = pass == 1;
    for (auto [prefix, ps] : std::vector<std::pair<std::string, ParamSet<T>*>>{
             {"context_encoder.", &m.context}, {"target_encoder.", &m.target}, {"predictor.", &m.predictor_params}}) {
      const bool encoder = prefix != "predictor.";
      for (std::size_t i = 0; i < ps->count(); ++i) {
        const ParamInfo& info = ps->infos()[i];
        const std::string name = prefix + (encoder ? detail::reference_encoder_name(info.name, fx.patch_norm) : info.name);
        const Tensor& t = detail::expect_tensor<T>(f, name, info.shape);
        if (!copy) continue;
        std::span<T> out = ps->value_span(ps->id(i));
        if (encoder && info.name == "pos_embed") {
          const std::vector<T> rows = t.to_vector<T>();
          for (int j = 0; j < P; ++j)
            std::copy_n(rows.begin() + std::ptrdiff_t(ord[std::size_t(j)]) * d, d, out.begin() + std::ptrdiff_t(j) * d);
        } else {
          t.copy_to(out);
        }
      }
    }
  }
}

// m as a reference state dict: the inverse of load_reference_state, with facts (the reference
// file's, for a bitwise round trip; ReferenceFacts{} with mean/std for a model trained here).
// The temporal padding must be one the reference knows (0 or 2).
template <class T>
SafetensorsFile reference_state(const JepaModel<T>& m, const ReferenceFacts& facts, const ReferenceOptions& opt) {
  const int P = m.num_tokens(), d = m.dim();
  const auto ord = detail::reference_order(opt, P, "reference_state");
  require<ConfigError>(m.config.temporal_padding == 0 || m.config.temporal_padding == 2, "reference_state: temporal padding ",
                       m.config.temporal_padding, ": the reference's PatchEmbed1d has 0 or 2");
  require<ConfigError>(facts.version_marker < 0 || (facts.version_marker >= 1) == (m.config.temporal_padding == 0),
                       "reference_state: _temporal_patch_version ", facts.version_marker, " with temporal padding ",
                       m.config.temporal_padding);
  SafetensorsFile f;
  for (auto [prefix, ps] : std::vector<std::pair<std::string, const ParamSet<T>*>>{
           {"context_encoder.", &m.context}, {"target_encoder.", &m.target}, {"predictor.", &m.predictor_params}}) {
    const bool encoder = prefix != "predictor.";
    for (std::size_t i = 0; i < ps->count(); ++i) {
      const ParamInfo& info = ps->infos()[i];
      const std::string name = prefix + (encoder ? detail::reference_encoder_name(info.name, facts.patch_norm) : info.name);
      std::span<const T> v = ps->value_span(ps->id(i));
      if (encoder && info.name == "pos_embed") {
        std::vector<T> rows(v.size());
        for (int j = 0; j < P; ++j)
          std::copy_n(v.begin() + std::ptrdiff_t(j) * d, d, rows.begin() + std::ptrdiff_t(ord[std::size_t(j)]) * d);
        f.add(name, std::span<const T>(rows), info.shape);
      } else {
        f.add(name, v, info.shape);
      }
    }
    if (!encoder) continue;
    if (facts.unused_type_rows > 0 && m.config.encoder.token_types == 0) {
      const std::vector<T> zeros(static_cast<std::size_t>(facts.unused_type_rows) * d, T(0));
      f.add(prefix + "taxeltype_embed", std::span<const T>(zeros), {facts.unused_type_rows, d});
    }
    if (!facts.mean.empty()) {
      const std::vector<std::int64_t> shape{static_cast<std::int64_t>(facts.mean.size())};
      if (facts.buffers_f64) {
        f.add(prefix + "xela_mean", Tensor::from(std::vector<double>(facts.mean.begin(), facts.mean.end()), shape));
        f.add(prefix + "xela_std", Tensor::from(std::vector<double>(facts.std.begin(), facts.std.end()), shape));
      } else {
        f.add(prefix + "xela_mean", std::span<const float>(facts.mean), shape);
        f.add(prefix + "xela_std", std::span<const float>(facts.std), shape);
      }
    }
    if (facts.version_marker >= 0 && m.config.group_size.empty()) {
      const std::int8_t v = static_cast<std::int8_t>(facts.version_marker);
      f.add(prefix + "_temporal_patch_version", std::span<const std::int8_t>(&v, 1), {});
    }
  }
  return f;
}

}  // namespace tjepa
