#pragma once
// A pre-trained model restored from a Trainer checkpoint (any program's: a user's Trainer,
// `tjepa pretrain`, `tjepa demo`), with the data statistics it was trained on.
//
//   TrainedModel m = load_trained_model("runs/x/checkpoint.safetensors");
//   m.track(recording);                                     // drift tracking, if the run used it
//   WindowSource src(recording, WindowSpec{m.config.data.tau}, {}, m.pre);
//   embed_windows(m.model->target, m.model->tokenizer, m.model->encoder, src, ids);
//
// data_state() writes the statistics a Trainer stores with its checkpoints (Trainer::extras).
#include <algorithm>
#include <cstdint>
#include <filesystem>
#include <memory>
#include <optional>
#include <span>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "tjepa/core/error.hpp"
#include "tjepa/core/files.hpp"
#include "tjepa/core/json.hpp"
#include "tjepa/data/drift_tracker.hpp"
#include "tjepa/data/named_tensor.hpp"
#include "tjepa/data/preprocessor.hpp"
#include "tjepa/io/checkpoint.hpp"
#include "tjepa/train/config.hpp"
#include "tjepa/train/jepa_model.hpp"

namespace tjepa {

namespace detail {
// The weights of a JepaModel of config c (context and target tokenizers, encoders' blocks and
// positions, the predictor's blocks and linear maps), leaving out biases and LayerNorms: a lower
// bound of the parameter count, computed in double.
inline double jepa_weight_count(const JepaConfig& c) {
  const auto& e = c.encoder;
  const auto& p = c.predictor;
  const double d = e.dim, pd = p.dim, he = e.mlp_ratio * d, hp = p.mlp_ratio * pd;
  // Tokenizer: one map of in_dim·d per taxel token, or per distinct group size n one of n·in_dim·d.
  double tokenizer = static_cast<double>(c.in_dim) * d;
  if (!c.group_size.empty()) {
    tokenizer = 0;
    std::vector<int> sizes(c.group_size.begin(), c.group_size.end());
    std::sort(sizes.begin(), sizes.end());
    sizes.erase(std::unique(sizes.begin(), sizes.end()), sizes.end());
    for (const int n : sizes) tokenizer += static_cast<double>(std::max(n, 1)) * c.in_dim * d;
  }
  const double encoder =
      static_cast<double>(e.depth) * (4 * d * d + 2 * d * he) + static_cast<double>(e.num_tokens) * d + tokenizer;
  const double predictor = static_cast<double>(p.depth) * (4 * pd * pd + 2 * pd * hp) +
                           static_cast<double>(p.in_dim + p.output_width()) * pd;
  return 2 * encoder + predictor;
}
}  // namespace detail

// The data statistics of a run, as a checkpoint stores them: the preprocessor's, and the drift
// tracker's when the run tracked drift.
inline CheckpointState data_state(const Preprocessor& pre, const DriftTracker* drift = nullptr) {
  CheckpointState s;
  for (const NamedTensor& t : pre.state()) s.normalization.emplace(t.name, Tensor::from(t.values, t.shape));
  if (drift)
    for (const NamedTensor& t : drift->state()) s.normalization.emplace(t.name, Tensor::from(t.values, t.shape));
  return s;
}

struct TrainedModel {
  TrainConfig config;
  std::unique_ptr<JepaModel<float>> model;
  Preprocessor pre;                   // not ready() when the run stored no statistics
  std::optional<DriftTracker> drift;  // when the run tracked drift: apply it to new recordings first
  std::int64_t step = 0;
  // Converted from the reference code's checkpoint (`tjepa convert`; its "reference.source"):
  // such a model expects recordings whose baselines are already subtracted, as the reference's
  // dataset does before its model. Empty for a tjepa run.
  std::string converted_from;

  // The run's drift tracking over a new recording (from the fitted rest readings); no-op without.
  void track(Recording& rec) {
    if (!drift) return;
    drift->reset();
    drift->apply(rec);
  }
};

// Reads a checkpoint written by a Trainer. Malformed metadata (a missing key, a wrong type, a
// value no run could have) throws FileError naming the file and the key; nothing else escapes.
inline TrainedModel load_trained_model(const std::filesystem::path& path) {
  require_input_file(path, "checkpoint");
  const SafetensorsFile file = load_safetensors(path);
  const auto it = file.metadata.find("config");
  require<FileError>(it != file.metadata.end(), path.string(), ": no 'config' metadata; not a tjepa checkpoint");
  const std::string where = path.string() + ": metadata 'config'";
  const nlohmann::json meta = json_parse<FileError>(it->second, where);
  require<FileError>(meta.is_object(), where, ": expected a JSON object");
  const std::string objective = checkpoint_objective(meta);
  require<FileError>(objective == "jepa", path.string(), " is a checkpoint of a '", objective,
                     "' run; load_trained_model reads Tactile-JEPA runs ('jepa')");
  TrainedModel m;
  try {
    m.config.update(checkpoint_legacy_defaults(), "checkpoint_legacy_defaults");  // keys the file may predate
    m.config.update(json_get<nlohmann::json, FileError>(meta, "train", where), where + ".train");
    m.config.validate();
  } catch (const FileError&) {
    throw;
  } catch (const Error& e) {
    fail<FileError>(e.what());
  }
  const JepaConfig mc =
      JepaConfig::from_json<FileError>(json_get<nlohmann::json, FileError>(meta, "model", where), where + ".model");
  // The model is allocated before its tensors are read: metadata that describes a larger model
  // than the file holds values for is refused first (no multi-GB allocation from a 1 KB file).
  double held = 0;
  for (const std::string& name : file.names()) held += static_cast<double>(file.at(name).numel());
  const double needed = detail::jepa_weight_count(mc);
  require<FileError>(needed <= held, where, ".model: describes a model of about ", needed,
                     " weights, the file holds ", held, " values");
  m.model = std::make_unique<JepaModel<float>>(mc, 0);
  const auto parts = m.model->parts();
  const CheckpointState st =
      load_checkpoint(path, std::span<const PrefixedParams<float>>(parts), static_cast<AdamW<float>*>(nullptr));
  std::vector<NamedTensor> state;
  for (const auto& [name, t] : st.normalization) {
    NamedTensor nt{name, t.shape, std::vector<float>(t.numel())};
    t.copy_to(std::span<float>(nt.values));
    state.push_back(std::move(nt));
  }
  try {
    const bool has_pre = std::any_of(state.begin(), state.end(),
                                     [](const NamedTensor& t) { return t.name == "preprocess.config"; });
    if (has_pre) m.pre = Preprocessor::from_state(state);
    if (DriftTracker::in_state(state)) m.drift = DriftTracker::from_state(state);
  } catch (const FileError&) {
    throw;
  } catch (const Error& e) {
    fail<FileError>(path.string(), ": data statistics: ", e.what());
  }
  m.step = st.step;
  if (const auto src = file.metadata.find("reference.source"); src != file.metadata.end()) m.converted_from = src->second;
  return m;
}

}  // namespace tjepa
