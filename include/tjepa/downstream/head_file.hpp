#pragma once
// A trained head as one safetensors file, with what it needs to run: save_head / load_probe_head /
// load_sequence_head. Format "tjepa.head.v1":
//   tensors   the head's parameters under their PyTorch names ("probe.*" for ProbeHead, the
//             sequence head's names for SequenceModel)
//             scaler.mean, scaler.std  F64 [R]: regression outputs are z · std + mean
//             center.shift             [N, d], only for a head trained on centred token
//                                      embeddings (center_token_embeddings): added to every window's
//                                      embeddings before the head
//   metadata  format, tjepa_version, and "head" (JSON): kind ("probe" | "sequence"), the module's
//             config (dim, heads, mlp_ratio, eps, pooling {kind, tokens, components}; head_hidden,
//             regression, classes for a probe; length, outputs for a sequence head), and the
//             HeadInfo: task, class_names [C], output_names [R], tau, stride, encoder (the
//             fingerprint of the encoder and data statistics it was trained on, encoder_fingerprint),
//             encoder_file (where that encoder was read from; informational).
// Loading checks the whole file before it builds anything: every tensor present with its dtype and
// shape, nothing extra, names and counts that agree. Given the encoder's fingerprint, a head trained
// on another encoder is refused, naming both.
#include <cmath>
#include <cstdint>
#include <filesystem>
#include <set>
#include <span>
#include <string>
#include <string_view>
#include <vector>

#include <nlohmann/json.hpp>

#include "tjepa/core/error.hpp"
#include "tjepa/core/files.hpp"
#include "tjepa/core/hash.hpp"
#include "tjepa/core/json.hpp"
#include "tjepa/core/param_set.hpp"
#include "tjepa/data/named_tensor.hpp"
#include "tjepa/downstream/probe_head.hpp"
#include "tjepa/downstream/sequence_head.hpp"
#include "tjepa/io/checkpoint.hpp"
#include "tjepa/io/safetensors.hpp"
#include "tjepa/train/trained_model.hpp"
#include "tjepa/version.hpp"

namespace tjepa {

inline constexpr std::string_view head_format = "tjepa.head.v1";

// The fingerprint of an encoder as a head sees it: its parameters (names, shapes, values) and the
// data statistics its windows are made with (Preprocessor / DriftTracker state), as 16 hex digits.
// Two encoders with one fingerprint give the same embeddings of the same recording.
template <class T>
std::string encoder_fingerprint(const ParamSet<T>& params, std::span<const NamedTensor> data_state = {}) {
  std::uint64_t h = fingerprint_seed;
  auto add_string = [&](std::string_view s) { h = fingerprint(std::span<const char>(s.data(), s.size() + 0), h); };
  for (std::size_t i = 0; i < params.count(); ++i) {
    const ParamInfo& info = params.infos()[i];
    add_string(info.name);
    h = fingerprint(std::span<const std::int64_t>(info.shape), h);
    h = fingerprint(params.value_span(params.id(i)), h);
  }
  for (const NamedTensor& t : data_state) {
    add_string(t.name);
    h = fingerprint(std::span<const std::int64_t>(t.shape), h);
    h = fingerprint(std::span<const float>(t.values), h);
  }
  return hex_digits(h);
}

// The fingerprint of a trained model's encoder (its target or its context parameters) with the
// data statistics the model makes its windows with: the preprocessor's, and the drift tracker's
// fitted state (not its running rest readings, "drift.rest", which follow whatever it tracked
// last; every recording and stream starts from the fitted ones).
inline std::string encoder_fingerprint(const TrainedModel& m, const ParamSet<float>& encoder) {
  std::vector<NamedTensor> statistics = m.pre.state();
  if (m.drift)
    for (NamedTensor& t : m.drift->state())
      if (t.name != "drift.rest") statistics.push_back(std::move(t));
  return encoder_fingerprint(encoder, statistics);
}

// What a saved head needs beyond its weights to run, and to be refused where it does not apply.
struct HeadInfo {
  std::string task;                       // "classification", "regression", "force", ... (free text)
  std::vector<std::string> class_names;   // [C] the classes' names, in logit order
  std::vector<std::string> output_names;  // [R] the regression outputs' names
  int tau = 0;                            // frames per window
  int stride = 0;                         // frames between the windows it was trained on
  std::string encoder;                    // encoder_fingerprint of the encoder it reads
  std::string encoder_file;               // where that encoder came from (informational)
  std::vector<float> center_shift;        // [N·d]: added to the embeddings first (empty: none)
};

template <class T>
struct LoadedProbeHead {
  ProbeHead<T> head;
  HeadInfo info;
};

template <class T>
struct LoadedSequenceHead {
  SequenceModel<T> head;
  HeadInfo info;
};

namespace detail {
inline nlohmann::json pooling_json(const PoolingConfig& p) {
  return {{"kind", to_string(p.kind)}, {"tokens", p.tokens}, {"components", p.components}};
}

inline void info_to_json(const HeadInfo& info, int regression, int classes, nlohmann::json& j) {
  require<ConfigError>(static_cast<int>(info.class_names.size()) == classes, "save_head: ", info.class_names.size(),
                       " class names for ", classes, " classes");
  require<ConfigError>(info.output_names.empty() || static_cast<int>(info.output_names.size()) == regression,
                       "save_head: ", info.output_names.size(), " output names for ", regression, " regression outputs");
  require<ConfigError>(info.tau > 0 && info.stride > 0, "save_head: tau ", info.tau, ", stride ", info.stride,
                       ", expected > 0 (the windows the head was trained on)");
  require<ConfigError>(info.encoder.size() == 16, "save_head: encoder fingerprint '", info.encoder,
                       "', expected 16 hex digits (encoder_fingerprint)");
  std::vector<std::string> outputs = info.output_names;
  for (int a = static_cast<int>(outputs.size()); a < regression; ++a) outputs.push_back("output_" + std::to_string(a));
  j["task"] = info.task;
  j["class_names"] = info.class_names;
  j["output_names"] = outputs;
  j["tau"] = info.tau;
  j["stride"] = info.stride;
  j["encoder"] = info.encoder;
  j["encoder_file"] = info.encoder_file;
}

template <class T>
SafetensorsFile head_file(const ParamSet<T>& params, const ColumnScaler& scaler, const HeadInfo& info, int tokens,
                          int dim, nlohmann::json j) {
  SafetensorsFile file;
  add_params(file, "", params);
  file.add("scaler.mean", std::span<const double>(scaler.mean), {static_cast<std::int64_t>(scaler.mean.size())});
  file.add("scaler.std", std::span<const double>(scaler.std), {static_cast<std::int64_t>(scaler.std.size())});
  if (!info.center_shift.empty()) {
    require<ShapeError>(info.center_shift.size() == static_cast<std::size_t>(tokens) * dim, "save_head: center shift of ",
                        info.center_shift.size(), " values, expected N·d = ", tokens, "·", dim);
    file.add("center.shift", std::span<const float>(info.center_shift), {tokens, dim});
  }
  file.metadata["format"] = std::string(head_format);
  file.metadata["tjepa_version"] = version_string;
  file.metadata["head"] = j.dump();
  return file;
}

// The file's "head" JSON, its kind checked.
inline nlohmann::json head_json(const SafetensorsFile& file, std::string_view kind) {
  expect_format(file, head_format);
  const auto it = file.metadata.find("head");
  require<FileError>(it != file.metadata.end(), file.source(), ": metadata has no 'head'");
  const std::string where = file.source() + ": metadata 'head'";
  nlohmann::json j = json_parse<FileError>(it->second, where);
  require<FileError>(j.is_object(), where, ": expected a JSON object");
  const auto k = json_get<std::string, FileError>(j, "kind", where);
  require<FileError>(k == kind, file.source(), " holds a '", k, "' head, expected a '", kind, "' head");
  return j;
}

inline PoolingConfig pooling_of(const nlohmann::json& j, const std::string& where) {
  const nlohmann::json p = json_get<nlohmann::json, FileError>(j, "pooling", where);
  PoolingConfig c;
  const auto kind = json_get<std::string, FileError>(p, "kind", where + ".pooling");
  require<FileError>(kind == "attentive" || kind == "taxel", where, ".pooling.kind '", kind,
                     "', expected attentive or taxel");
  c.kind = parse_pooling(kind);
  c.tokens = json_get<int, FileError>(p, "tokens", where + ".pooling");
  c.components = json_get<int, FileError>(p, "components", where + ".pooling");
  require<FileError>(c.kind == PoolingKind::attentive ||
                         (c.tokens > 0 && c.tokens <= 1 << 20 && c.components > 0 && c.components <= 1 << 10),
                     where, ".pooling: tokens ", c.tokens, ", components ", c.components,
                     ", expected > 0 for the taxel pooling");
  return c;
}

// A head file read, its "head" JSON of the expected kind.
struct OpenedHead {
  SafetensorsFile file;
  nlohmann::json json;
  std::string where;
};
inline OpenedHead open_head(const std::filesystem::path& path, std::string_view kind) {
  require_input_file(path, "head file");
  OpenedHead h{load_safetensors(path), {}, {}};
  h.json = head_json(h.file, kind);
  h.where = h.file.source() + ": metadata 'head'";
  return h;
}

// The token count N of the file's centring shift [N, d] (0: none, or a shape info_of refuses).
inline int shift_tokens(const SafetensorsFile& file) {
  if (!file.contains("center.shift") || file.at("center.shift").shape.size() != 2) return 0;
  const std::int64_t n = file.at("center.shift").shape[0];
  return n > 0 && n <= 1 << 20 ? static_cast<int>(n) : 0;
}

// Reads the HeadInfo and the scaler (R values) and checks the encoder (expected "": any).
inline HeadInfo info_of(const SafetensorsFile& file, const nlohmann::json& j, int regression, int classes, int tokens,
                        int dim, ColumnScaler& scaler, std::set<std::string>& used, std::string_view expected_encoder,
                        std::string_view encoder_name) {
  const std::string where = file.source() + ": metadata 'head'";
  HeadInfo info;
  info.task = json_get<std::string, FileError>(j, "task", where);
  info.class_names = json_get<std::vector<std::string>, FileError>(j, "class_names", where);
  info.output_names = json_get<std::vector<std::string>, FileError>(j, "output_names", where);
  info.tau = json_get<int, FileError>(j, "tau", where);
  info.stride = json_get<int, FileError>(j, "stride", where);
  info.encoder = json_get<std::string, FileError>(j, "encoder", where);
  info.encoder_file = json_get<std::string, FileError>(j, "encoder_file", where);
  require<FileError>(static_cast<int>(info.class_names.size()) == classes, where, ": ", info.class_names.size(),
                     " class names for ", classes, " classes");
  require<FileError>(static_cast<int>(info.output_names.size()) == regression, where, ": ", info.output_names.size(),
                     " output names for ", regression, " regression outputs");
  require<FileError>(info.tau > 0 && info.stride > 0, where, ": tau ", info.tau, ", stride ", info.stride,
                     ", expected > 0");
  if (!expected_encoder.empty() && info.encoder != expected_encoder)
    fail<ConfigError>(file.source(), " was trained on encoder ", info.encoder,
                      info.encoder_file.empty() ? std::string() : " (" + info.encoder_file + ")", ", not on ",
                      encoder_name.empty() ? std::string("this encoder") : std::string(encoder_name), " (",
                      expected_encoder, "): a head reads only the embeddings it was trained on");
  const std::vector<std::int64_t> shape{regression};
  const Tensor& mean = expect_tensor<double>(file, "scaler.mean", shape);
  const Tensor& sd = expect_tensor<double>(file, "scaler.std", shape);
  scaler.mean.assign(static_cast<std::size_t>(regression), 0.0);
  scaler.std.assign(static_cast<std::size_t>(regression), 1.0);
  mean.copy_to(std::span<double>(scaler.mean));
  sd.copy_to(std::span<double>(scaler.std));
  for (int a = 0; a < regression; ++a)
    require<FileError>(std::isfinite(scaler.mean[static_cast<std::size_t>(a)]) &&
                           std::isfinite(scaler.std[static_cast<std::size_t>(a)]) && scaler.std[static_cast<std::size_t>(a)] > 0,
                       file.source(), ": scaler of output ", a, " is mean ", scaler.mean[static_cast<std::size_t>(a)],
                       ", std ", scaler.std[static_cast<std::size_t>(a)], ", expected finite with std > 0");
  used.insert("scaler.mean");
  used.insert("scaler.std");
  if (file.contains("center.shift")) {
    const Tensor& t = expect_tensor<float>(file, "center.shift", {tokens, dim});
    info.center_shift.resize(t.numel());
    t.copy_to(std::span<float>(info.center_shift));
    used.insert("center.shift");
  }
  return info;
}

// Checks, then copies, the parameters; refuses tensors nobody reads and non-finite values.
template <class T>
void read_head_params(const SafetensorsFile& file, ParamSet<T>& params, std::set<std::string>& used) {
  read_params(file, "", params, false, used);
  reject_unused(file, used);
  read_params(file, "", params, true, used);
  for (std::size_t i = 0; i < params.count(); ++i)
    for (T v : params.value_span(params.id(i)))
      require<FileError>(std::isfinite(static_cast<double>(v)), file.source(), ": tensor '", params.infos()[i].name,
                         "' holds a non-finite value");
}
}  // namespace detail

// Writes a probe head (atomically).
template <class T>
void save_head(const std::filesystem::path& path, const ProbeHead<T>& head, const HeadInfo& info) {
  const ProbeConfig& c = head.probe.config;
  nlohmann::json j = {{"kind", "probe"},         {"dim", c.dim},           {"heads", c.heads},
                      {"mlp_ratio", c.mlp_ratio}, {"eps", c.eps},           {"head_hidden", c.head_hidden},
                      {"regression", head.regression}, {"classes", head.classes}, {"pooling", detail::pooling_json(c.pooling)}};
  detail::info_to_json(info, head.regression, head.classes, j);
  require<ConfigError>(info.center_shift.empty() || c.pooling.tokens > 0 || c.pooling.kind == PoolingKind::attentive,
                       "save_head: center shift without a token count");
  const int tokens = info.center_shift.empty() ? 0 : static_cast<int>(info.center_shift.size() / static_cast<std::size_t>(c.dim));
  save_safetensors(path, detail::head_file(head.params, head.scaler, info, tokens, c.dim, std::move(j)));
}

// Writes a sequence head (atomically).
template <class T>
void save_head(const std::filesystem::path& path, const SequenceModel<T>& model, const HeadInfo& info) {
  const SequenceHeadConfig& c = model.head.config;
  nlohmann::json j = {{"kind", "sequence"}, {"dim", c.dim},     {"heads", c.heads},
                      {"length", c.length}, {"outputs", c.outputs}, {"mlp_ratio", c.mlp_ratio},
                      {"eps", c.eps},       {"pooling", detail::pooling_json(c.pooling)}};
  detail::info_to_json(info, c.outputs, 0, j);
  const int tokens = info.center_shift.empty() ? 0 : static_cast<int>(info.center_shift.size() / static_cast<std::size_t>(c.dim));
  save_safetensors(path, detail::head_file(model.params, model.scaler, info, tokens, c.dim, std::move(j)));
}

// Reads a probe head written by save_head. expected_encoder: the fingerprint of the encoder it will
// read (encoder_fingerprint; "": not checked), encoder_name what to call that encoder in the error.
template <class T>
LoadedProbeHead<T> load_probe_head(const std::filesystem::path& path, std::string_view expected_encoder = "",
                                   std::string_view encoder_name = "") {
  const detail::OpenedHead h = detail::open_head(path, "probe");
  const SafetensorsFile& file = h.file;
  const nlohmann::json& j = h.json;
  const std::string& where = h.where;
  ProbeConfig c;
  c.dim = json_get<int, FileError>(j, "dim", where);
  c.heads = json_get<int, FileError>(j, "heads", where);
  c.mlp_ratio = json_get<double, FileError>(j, "mlp_ratio", where);
  c.eps = json_get<double, FileError>(j, "eps", where);
  c.head_hidden = json_get<int, FileError>(j, "head_hidden", where);
  c.pooling = detail::pooling_of(j, where);
  const int R = json_get<int, FileError>(j, "regression", where), C = json_get<int, FileError>(j, "classes", where);
  require<FileError>(c.dim > 0 && c.heads > 0 && c.dim % c.heads == 0 && c.head_hidden > 0 && c.mlp_ratio > 0 &&
                         c.eps > 0 && c.dim <= 1 << 16 && c.head_hidden <= 1 << 16 && c.mlp_ratio <= 64,
                     where, ": dim ", c.dim, ", heads ", c.heads, ", head_hidden ", c.head_hidden, ", mlp_ratio ",
                     c.mlp_ratio, ", eps ", c.eps, ", expected positive sizes with heads dividing dim");
  require<FileError>(R >= 0 && (C == 0 || C > 1) && R + C > 0 && R + C <= 1 << 16, where, ": regression ", R,
                     ", classes ", C, ", expected R >= 0, C = 0 or C >= 2, and R + C > 0");
  c.out_dim = R + C;
  std::set<std::string> used;
  ColumnScaler scaler;
  const int tokens = detail::shift_tokens(file);
  HeadInfo info = detail::info_of(file, j, R, C, tokens, c.dim, scaler, used, expected_encoder,
                                  encoder_name);
  LoadedProbeHead<T> out{ProbeHead<T>(c, R, C), std::move(info)};
  detail::read_head_params(file, out.head.params, used);
  out.head.scaler = std::move(scaler);
  return out;
}

// Reads a sequence head written by save_head (expected_encoder as for load_probe_head).
template <class T>
LoadedSequenceHead<T> load_sequence_head(const std::filesystem::path& path, std::string_view expected_encoder = "",
                                         std::string_view encoder_name = "") {
  const detail::OpenedHead h = detail::open_head(path, "sequence");
  const SafetensorsFile& file = h.file;
  const nlohmann::json& j = h.json;
  const std::string& where = h.where;
  SequenceHeadConfig c;
  c.dim = json_get<int, FileError>(j, "dim", where);
  c.heads = json_get<int, FileError>(j, "heads", where);
  c.length = json_get<int, FileError>(j, "length", where);
  c.outputs = json_get<int, FileError>(j, "outputs", where);
  c.mlp_ratio = json_get<double, FileError>(j, "mlp_ratio", where);
  c.eps = json_get<double, FileError>(j, "eps", where);
  c.pooling = detail::pooling_of(j, where);
  require<FileError>(c.dim > 0 && c.heads > 0 && c.dim % c.heads == 0 && c.length > 0 && c.outputs > 0 &&
                         c.mlp_ratio > 0 && c.eps > 0 && c.dim <= 1 << 16 && c.length <= 1 << 16 &&
                         c.outputs <= 1 << 16 && c.mlp_ratio <= 64,
                     where, ": dim ", c.dim, ", heads ", c.heads, ", length ", c.length, ", outputs ", c.outputs,
                     ", expected positive sizes with heads dividing dim");
  std::set<std::string> used;
  ColumnScaler scaler;
  const int tokens = detail::shift_tokens(file);
  HeadInfo info =
      detail::info_of(file, j, c.outputs, 0, tokens, c.dim, scaler, used, expected_encoder, encoder_name);
  LoadedSequenceHead<T> out{SequenceModel<T>(c, 0), std::move(info)};
  detail::read_head_params(file, out.head.params, used);
  out.head.scaler = std::move(scaler);
  return out;
}

}  // namespace tjepa
