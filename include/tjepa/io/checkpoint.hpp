#pragma once
// Training checkpoints and the encoder-only export, as safetensors files a PyTorch user can load.
//
// Tensor names in a training checkpoint (T the model's scalar type):
//   <prefix><name>               every model part, e.g. "context_encoder.blocks.0.attn.qkv.weight",
//                                "target_encoder.pos_embed", "predictor.mask_token" (the prefixes
//                                of the reference module's state dict)
//   opt.exp_avg.<full name>      AdamW first moment of each trainable tensor
//   opt.exp_avg_sq.<full name>   AdamW second moment
//   rng.<key>                    U64 [4]: the xoshiro256** state of each named generator
//   normalization.<key>          data normalization statistics (any dtype)
// Metadata (strings): format = "tjepa.checkpoint.v1", step (optimizer steps done), opt.step,
// config (JSON), and any caller entries.
//
// The encoder-only export (format "tjepa.encoder.v1") holds one encoder's tensors under their
// plain state-dict names (prefix ""), the normalization statistics and the config: in PyTorch,
// encoder.load_state_dict({k: v for k, v in load_file(f).items() if not k.startswith("normalization.")}).
//
// Loading checks everything before it changes anything: every expected tensor is present with
// the same dtype and shape, and the file holds no tensor nobody expects.
#include <charconv>
#include <cstdint>
#include <filesystem>
#include <map>
#include <set>
#include <span>
#include <string>
#include <string_view>
#include <system_error>

#include <nlohmann/json.hpp>

#include "tjepa/core/error.hpp"
#include "tjepa/core/random.hpp"
#include "tjepa/io/safetensors.hpp"
#include "tjepa/core/param_set.hpp"
#include "tjepa/core/prefixed_params.hpp"
#include "tjepa/optim/adamw.hpp"
#include "tjepa/version.hpp"

namespace tjepa {

inline constexpr std::string_view checkpoint_format = "tjepa.checkpoint.v1";
inline constexpr std::string_view encoder_export_format = "tjepa.encoder.v1";

// The version of a checkpoint's config metadata: 1 (no "version" key) is a JEPA run's
// {"train", "model"}; 2 adds "version" and "objective"; 3 adds the run keys of
// checkpoint_legacy_defaults; 4 adds wd_initial; 5 adds the mask sampler's other settings
// (local_targets_per_part ... mask_max_tries), which every earlier file ran at these defaults.
inline constexpr int checkpoint_metadata_version = 5;

// The run ("train") keys added after the first checkpoints, with the values that give the
// behaviour of a file written without them: a checkpoint that lacks one is read with this value
// (and resumes only a run that has it).
inline const nlohmann::json& checkpoint_legacy_defaults() {
  static const nlohmann::json j = {{"layout_edges", ""},     {"layout_columns", ""}, {"bridges", "connect"},
                                   {"taxel_order", ""},      {"weight_decay_timing", "ijepa"},
                                   {"wd_initial", -1.0},
                                   {"local_targets_per_part", 1},
                                   {"global_targets_per_part", 1},
                                   {"part_targets", "automatic"},
                                   {"global_sampling", "stratified"},
                                   {"context_sampling", "uniform"},
                                   {"mask_scheme", "graph"},
                                   {"block_target_scale", {0.15, 0.2}},
                                   {"block_target_aspect", {0.75, 1.5}},
                                   {"block_context_scale", {0.85, 1.0}},
                                   {"block_context_aspect", {1.0, 1.0}},
                                   {"block_targets", 4},
                                   {"min_context_ratio", 0.15},
                                   {"mask_max_tries", 32}};
  return j;
}

// The objective a checkpoint's config metadata names ("jepa" for version 1).
inline std::string checkpoint_objective(const nlohmann::json& config) {
  if (!config.is_object() || !config.contains("objective")) return "jepa";
  return config["objective"].is_string() ? config["objective"].get<std::string>() : std::string("(not a string)");
}

// Everything in a checkpoint that is not a model tensor or an optimizer moment.
struct CheckpointState {
  std::int64_t step = 0;                           // optimizer steps done
  std::map<std::string, Rng::State> rng;           // named generators (masks, data order, ...)
  nlohmann::json config = nlohmann::json::object();
  std::map<std::string, Tensor> normalization;     // e.g. "mean", "std": shapes are the caller's
  std::map<std::string, std::string> metadata;     // free-form extras
};

// Adds each tensor of `params` as <prefix><name> with its PyTorch shape.
template <class T>
void add_params(SafetensorsFile& file, std::string_view prefix, const ParamSet<T>& params) {
  for (std::size_t i = 0; i < params.count(); ++i) {
    const auto& info = params.infos()[i];
    file.add(std::string(prefix) + info.name, params.value_span(params.id(i)), info.shape);
  }
}

namespace detail {
template <class T>
const Tensor& expect_tensor(const SafetensorsFile& file, const std::string& name,
                            const std::vector<std::int64_t>& shape) {
  if (!file.contains(name)) fail<FileError>(file.source(), ": missing tensor '", name, "'");
  const Tensor& t = file.at(name);
  if (t.dtype != dtype_of<T>)
    fail<FileError>(file.source(), ": tensor '", name, "' has dtype ", dtype_name(t.dtype), ", expected ",
                    dtype_name(dtype_of<T>));
  if (t.shape != shape)
    fail<FileError>(file.source(), ": tensor '", name, "' has shape ", shape_string(t.shape), ", expected ",
                    shape_string(shape));
  return t;
}

// Checks (and with copy = true then loads) every tensor of `params` from <prefix><name>; records
// the names it used.
template <class T>
void read_params(const SafetensorsFile& file, std::string_view prefix, ParamSet<T>& params, bool copy,
                 std::set<std::string>& used) {
  for (std::size_t i = 0; i < params.count(); ++i) {
    const auto& info = params.infos()[i];
    const std::string name = std::string(prefix) + info.name;
    const Tensor& t = expect_tensor<T>(file, name, info.shape);
    if (copy) t.copy_to(params.value_span(params.id(i)));
    used.insert(name);
  }
}

// Calls f(part index, tensor info, full name) for every tensor the optimizer holds moments of.
template <class T, class F>
void for_each_moment(const AdamW<T>& optimizer, F&& f) {
  const auto& parts = optimizer.parts();
  for (std::size_t k = 0; k < parts.size(); ++k)
    for (const ParamInfo& info : parts[k].params->infos()) f(k, info, parts[k].prefix + info.name);
}

inline std::int64_t metadata_int(const SafetensorsFile& file, const std::string& key) {
  auto it = file.metadata.find(key);
  if (it == file.metadata.end()) fail<FileError>(file.source(), ": metadata has no '", key, "'");
  std::int64_t v = 0;
  const auto& s = it->second;
  auto [end, ec] = std::from_chars(s.data(), s.data() + s.size(), v);
  if (ec != std::errc() || end != s.data() + s.size() || v < 0)
    fail<FileError>(file.source(), ": metadata '", key, "' = '", s, "', expected an integer >= 0");
  return v;
}

inline void expect_format(const SafetensorsFile& file, std::string_view format) {
  auto it = file.metadata.find("format");
  if (it == file.metadata.end() || it->second != format)
    fail<FileError>(file.source(), ": metadata 'format' is '", it == file.metadata.end() ? "" : it->second,
                    "', expected '", format, "'");
}

inline void reject_unused(const SafetensorsFile& file, const std::set<std::string>& used) {
  for (const auto& name : file.names())
    if (!used.contains(name)) fail<FileError>(file.source(), ": unexpected tensor '", name, "'");
}

template <class T>
SafetensorsFile make_file(std::span<const PrefixedParams<T>> models, const CheckpointState& state,
                          std::string_view format) {
  check_prefixed_params<T>(models, "checkpoint");
  SafetensorsFile file;
  for (const auto& part : models) add_params(file, part.prefix, *part.params);
  for (const auto& [key, t] : state.normalization) file.add("normalization." + key, t);
  file.metadata = state.metadata;
  file.metadata["format"] = std::string(format);
  file.metadata["tjepa_version"] = version_string;
  file.metadata["config"] = state.config.dump();
  return file;
}

// Reads config and normalization statistics and marks them used.
inline CheckpointState read_state(const SafetensorsFile& file, std::set<std::string>& used) {
  CheckpointState state;
  for (const auto& [k, v] : file.metadata)
    if (k != "format" && k != "tjepa_version" && k != "config" && k != "step" && k != "opt.step")
      state.metadata.emplace(k, v);
  auto it = file.metadata.find("config");
  if (it != file.metadata.end()) {
    try {
      state.config = nlohmann::json::parse(it->second);
    } catch (const nlohmann::json::exception& e) {
      fail<FileError>(file.source(), ": metadata 'config' is not valid JSON: ", e.what());
    }
  }
  for (const auto& name : file.names())
    if (name.starts_with("normalization.")) {
      state.normalization.emplace(name.substr(14), file.at(name));
      used.insert(name);
    }
  return state;
}
}  // namespace detail

// Writes a training checkpoint atomically. `models` lists every model part (trainable or not);
// the optimizer's parts must be among them (same ParamSet objects).
template <class T>
void save_checkpoint(const std::filesystem::path& path, std::span<const PrefixedParams<T>> models,
                     const AdamW<T>* optimizer, const CheckpointState& state) {
  SafetensorsFile file = detail::make_file(models, state, checkpoint_format);
  for (const auto& [key, s] : state.rng)
    file.add("rng." + key, std::span<const std::uint64_t>(s), {4});
  file.metadata["step"] = std::to_string(state.step);
  if (optimizer) {
    file.metadata["opt.step"] = std::to_string(optimizer->steps());
    detail::for_each_moment(*optimizer, [&](std::size_t k, const ParamInfo& info, const std::string& full) {
      require<ConfigError>(file.contains(full), "save_checkpoint: optimizer parameter '", full,
                           "' is not among the model parts");
      file.add("opt.exp_avg." + full, optimizer->exp_avg(k).subspan(info.offset, info.size), info.shape);
      file.add("opt.exp_avg_sq." + full, optimizer->exp_avg_sq(k).subspan(info.offset, info.size), info.shape);
    });
  }
  save_safetensors(path, file);
}

template <class T>
void save_checkpoint(const std::filesystem::path& path, std::initializer_list<PrefixedParams<T>> models,
                     const AdamW<T>* optimizer, const CheckpointState& state) {
  save_checkpoint(path, std::span<const PrefixedParams<T>>(models.begin(), models.size()), optimizer, state);
}

// Loads a training checkpoint into the given model parts and optimizer (may be null: then the
// file's optimizer tensors are ignored), and returns the rest. Nothing is changed unless the
// whole file matches.
template <class T>
CheckpointState load_checkpoint(const std::filesystem::path& path, std::span<const PrefixedParams<T>> models,
                                AdamW<T>* optimizer) {
  check_prefixed_params<T>(models, "load_checkpoint");
  const SafetensorsFile file = load_safetensors(path);
  detail::expect_format(file, checkpoint_format);
  std::set<std::string> used;
  CheckpointState state = detail::read_state(file, used);
  state.step = detail::metadata_int(file, "step");
  for (const auto& name : file.names())
    if (name.starts_with("rng.")) {
      const Tensor& t = detail::expect_tensor<std::uint64_t>(file, name, {4});
      Rng::State s{};
      t.copy_to(std::span<std::uint64_t>(s));
      if (s[0] == 0 && s[1] == 0 && s[2] == 0 && s[3] == 0)
        fail<FileError>(file.source(), ": tensor '", name, "' is an all-zero generator state");
      state.rng.emplace(name.substr(4), s);
      used.insert(name);
    }
  // Two passes: check everything, then copy.
  for (int pass = 0; pass < 2; ++pass) {
    const bool copy = pass == 1;
    for (const auto& part : models) detail::read_params(file, part.prefix, *part.params, copy, used);
    if (optimizer) {
      detail::for_each_moment(*optimizer, [&](std::size_t k, const ParamInfo& info, const std::string& full) {
        const Tensor& m = detail::expect_tensor<T>(file, "opt.exp_avg." + full, info.shape);
        const Tensor& v = detail::expect_tensor<T>(file, "opt.exp_avg_sq." + full, info.shape);
        if (copy) {
          m.copy_to(optimizer->exp_avg(k).subspan(info.offset, info.size));
          v.copy_to(optimizer->exp_avg_sq(k).subspan(info.offset, info.size));
        }
        used.insert("opt.exp_avg." + full);
        used.insert("opt.exp_avg_sq." + full);
      });
      if (copy) optimizer->set_steps(detail::metadata_int(file, "opt.step"));
      else (void)detail::metadata_int(file, "opt.step");
    } else {
      for (const auto& name : file.names())
        if (name.starts_with("opt.")) used.insert(name);
    }
    if (!copy) detail::reject_unused(file, used);
  }
  return state;
}

template <class T>
CheckpointState load_checkpoint(const std::filesystem::path& path, std::initializer_list<PrefixedParams<T>> models,
                                AdamW<T>* optimizer) {
  return load_checkpoint(path, std::span<const PrefixedParams<T>>(models.begin(), models.size()), optimizer);
}

// Writes one encoder for inference: its parts (normally with prefix "", e.g. tokenizer, position
// table and blocks of the target encoder), the config and the normalization statistics.
template <class T>
void export_encoder(const std::filesystem::path& path, std::span<const PrefixedParams<T>> encoder,
                    const CheckpointState& state) {
  save_safetensors(path, detail::make_file(encoder, state, encoder_export_format));
}

// Loads an export written by export_encoder into `encoder`; returns config and statistics.
template <class T>
CheckpointState load_encoder(const std::filesystem::path& path, std::span<const PrefixedParams<T>> encoder) {
  check_prefixed_params<T>(encoder, "load_encoder");
  const SafetensorsFile file = load_safetensors(path);
  detail::expect_format(file, encoder_export_format);
  std::set<std::string> used;
  CheckpointState state = detail::read_state(file, used);
  for (const auto& part : encoder) detail::read_params(file, part.prefix, *part.params, false, used);
  detail::reject_unused(file, used);
  for (const auto& part : encoder) detail::read_params(file, part.prefix, *part.params, true, used);
  return state;
}

}  // namespace tjepa
