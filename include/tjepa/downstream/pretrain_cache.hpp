#pragma once
// Pre-trained encoders kept on disk between runs of the downstream protocol (grasp_eval.hpp), so
// that heads, read-outs and tables can be run again without pre-training again.
//
// An entry is keyed by everything its weights are a function of: the row (Tactile-JEPA, a mask
// variant, MAE), the pre-training seed, the whole pre-training config, the pre-training data (a
// fingerprint of the recordings after drift tracking and of the preprocessor's statistics), the
// thread count (sums may split by thread) and the library version. It does not see the code: a
// changed training step under the same version string reuses stale weights; clear the directory
// after changing the library.
//
// File: <dir>/<row>-seed<s>-<hash of the key>.safetensors, a training checkpoint without optimizer
// state (io/checkpoint.hpp): the encoder's tensors as "encoder.<name>", the key as its config and
// the pre-training's record (losses, time) as the metadata entry "pretraining". Loading checks
// that the file's key is the key asked for (a different one is an error that names the file);
// writing is atomic.
#include <cctype>
#include <cstdint>
#include <filesystem>
#include <optional>
#include <string>

#include <nlohmann/json.hpp>

#include "tjepa/core/atomic_write.hpp"
#include "tjepa/core/detail/parallel.hpp"
#include "tjepa/core/error.hpp"
#include "tjepa/core/param_set.hpp"
#include "tjepa/data/window_source.hpp"
#include "tjepa/io/checkpoint.hpp"
#include "tjepa/train/data_parallel.hpp"
#include "tjepa/version.hpp"

namespace tjepa {

// What pre-training reads of a window source: every recording's values and the preprocessor's
// statistics (FNV-1a).
inline std::uint64_t window_source_fingerprint(const WindowSource& source) {
  std::uint64_t h = fingerprint_seed;
  for (const Recording& r : source.recordings()) h = fingerprint(r.values(), h);
  if (const auto& p = source.preprocessor())
    for (const std::vector<float>* v : {&p->baseline(), &p->mean(), &p->std()})
      h = fingerprint(std::span<const float>(*v), h);
  return h;
}

class PretrainCache {
 public:
  PretrainCache() = default;  // off: nothing is read or written
  // data: what identifies the pre-training data (e.g. seed, frame counts and
  // window_source_fingerprint), part of every key.
  PretrainCache(std::filesystem::path dir, nlohmann::json data) : dir_(std::move(dir)), data_(std::move(data)) {}

  bool enabled() const { return !dir_.empty(); }
  const std::filesystem::path& dir() const { return dir_; }

  // The key of one pre-trained encoder: row name, seed, its config (with anything particular to
  // the row, e.g. MAE's mask ratio) and the cache's data.
  nlohmann::json key(const std::string& row, std::uint64_t seed, const nlohmann::json& config) const {
    return {{"format", "tjepa.pretrain_cache.v1"}, {"tjepa_version", version_string}, {"row", row},
            {"seed", seed}, {"config", config}, {"data", data_}, {"threads", max_threads()}};
  }

  std::filesystem::path path(const nlohmann::json& key) const {
    std::string slug;
    for (const char ch : key.at("row").get<std::string>()) {
      const auto u = static_cast<unsigned char>(ch);
      if (std::isalnum(u)) slug += static_cast<char>(std::tolower(u));
      else if (!slug.empty() && slug.back() != '-') slug += '-';
    }
    while (!slug.empty() && slug.back() == '-') slug.pop_back();
    return dir_ / (slug + "-seed" + std::to_string(key.at("seed").get<std::uint64_t>()) + "-" +
                   detail::short_hash(key.dump()) + ".safetensors");
  }

  // Loads the encoder of `key` into params and returns its pre-training record; nullopt when the
  // cache is off or holds no such file. Throws FileError for a file that does not load (corrupt,
  // truncated, other shapes) or holds another key.
  template <class T>
  std::optional<nlohmann::json> load(const nlohmann::json& key, ParamSet<T>& params) const {
    if (!enabled()) return std::nullopt;
    const std::filesystem::path p = path(key);
    if (!std::filesystem::exists(p)) return std::nullopt;
    {  // the key and the record first: params change only when all of the file is as expected
      const SafetensorsFile f = load_safetensors(p);
      const auto config = f.metadata.find("config"), record = f.metadata.find("pretraining");
      require<FileError>(config != f.metadata.end() && nlohmann::json::parse(config->second, nullptr, false) == key,
                         p.string(), ": the cached encoder's key is not the one asked for (an edited file or a hash ",
                         "collision); delete the file");
      require<FileError>(record != f.metadata.end() &&
                             nlohmann::json::parse(record->second, nullptr, false).is_object(),
                         p.string(), ": metadata 'pretraining' is missing or not a JSON object");
    }
    const CheckpointState s = load_checkpoint<T>(p, {PrefixedParams<T>{"encoder.", &params}}, nullptr);
    return nlohmann::json::parse(s.metadata.at("pretraining"));
  }

  // Writes params under key with its pre-training record (atomically; creates the directory).
  template <class T>
  void save(const nlohmann::json& key, ParamSet<T>& params, const nlohmann::json& record) const {
    if (!enabled()) return;
    std::filesystem::create_directories(dir_);
    CheckpointState s;
    s.config = key;
    s.metadata["pretraining"] = record.dump();
    save_checkpoint<T>(path(key), {PrefixedParams<T>{"encoder.", &params}}, nullptr, s);
  }

 private:
  std::filesystem::path dir_;
  nlohmann::json data_;
};

}  // namespace tjepa
