#pragma once
// Pre-trained encoders kept on disk between runs of the downstream protocol (grasp_eval.hpp), so
// that heads, read-outs and tables can be run again without pre-training again.
//
// An entry is keyed by everything its weights are a function of: the row (Tactile-JEPA, a mask
// variant, MAE), the pre-training seed, the whole pre-training config, the pre-training data (the
// caller's description, e.g. a fingerprint of the windows), the thread count (sums may split by
// thread), the build (compiler and SIMD instruction set: they change the arithmetic) and the
// library version. It does not see the source code: a changed training step under the same
// version string reuses stale weights; clear the directory after changing the library.
//
// File: <dir>/<row>-seed<s>-<hash of the key>.safetensors, a training checkpoint without optimizer
// state (io/checkpoint.hpp): the encoder's tensors as "encoder.<name>", the key as its config and
// the pre-training's log entry (losses, time) as the metadata entry "pretraining". Loading checks
// the file's key against the key asked for and changes the parameters only when all of the file
// is as expected; writing is atomic. Errors are FileError and name the file or the directory.
#include <cctype>
#include <cstdint>
#include <filesystem>
#include <optional>
#include <string>
#include <system_error>

#include <nlohmann/json.hpp>

#include "tjepa/core/detail/parallel.hpp"
#include "tjepa/core/threads.hpp"
#include "tjepa/core/detail/vendor.hpp"
#include "tjepa/core/error.hpp"
#include "tjepa/core/files.hpp"
#include "tjepa/core/hash.hpp"
#include "tjepa/core/param_set.hpp"
#include "tjepa/io/checkpoint.hpp"
#include "tjepa/version.hpp"

namespace tjepa {

// What of this build changes the arithmetic: the compiler and the instruction set.
inline nlohmann::json arithmetic_build() {
#if defined(__AVX512BF16__)
  constexpr bool bf16 = true;
#else
  constexpr bool bf16 = false;
#endif
  return {{"compiler", __VERSION__}, {"simd", xsimd::default_arch::name()}, {"avx512_bf16", bf16}};
}

class PretrainCache {
 public:
  PretrainCache() = default;  // off: nothing is read or written
  // Creates dir if needed (FileError if it cannot, or if it is not a directory). data describes
  // the pre-training data (e.g. frame counts and fingerprint(WindowSource)); it is part of every
  // key.
  PretrainCache(std::filesystem::path dir, nlohmann::json data) : dir_(std::move(dir)), data_(std::move(data)) {
    require<FileError>(!dir_.empty(), "PretrainCache: empty directory name");
    make_directories(dir_, "the pre-training cache");
  }

  bool enabled() const { return !dir_.empty(); }

  // The key of one pre-trained encoder: row name, seed, its config (with anything particular to
  // the row, e.g. MAE's mask ratio), the data, the threads and the build.
  nlohmann::json key(const std::string& row, std::uint64_t seed, const nlohmann::json& config) const {
    return {{"format", "tjepa.pretrain_cache.v1"}, {"tjepa_version", version_string}, {"row", row},
            {"seed", seed}, {"config", config}, {"data", data_}, {"threads", max_threads()},
            {"build", arithmetic_build()}};
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
                   short_hash(key.dump()) + ".safetensors");
  }

  // Loads the encoder of `key` into params and returns its pre-training log entry; nullopt when
  // the cache is off or holds no such file. FileError for a file that does not load (corrupt,
  // truncated, other tensors or shapes), holds another key or no log entry; params are then
  // unchanged.
  template <class T>
  std::optional<nlohmann::json> load(const nlohmann::json& key, ParamSet<T>& params) const {
    if (!enabled()) return std::nullopt;
    const std::filesystem::path p = path(key);
    std::error_code ec;
    if (!std::filesystem::exists(p, ec)) return std::nullopt;
    const std::string name = p.string();
    nlohmann::json entry;
    {  // key and log entry first (a small file: read twice)
      const SafetensorsFile f = load_safetensors(p);
      const auto config = f.metadata.find("config"), log = f.metadata.find("pretraining");
      require<FileError>(config != f.metadata.end(), name, ": metadata has no 'config' (the cache key)");
      const nlohmann::json stored = nlohmann::json::parse(config->second, nullptr, false);
      require<FileError>(!stored.is_discarded(), name, ": metadata 'config' is not valid JSON");
      require<FileError>(stored == key, name, ": the cached encoder's key is not the one asked for (an edited or ",
                         "misnamed file, or a hash collision); delete the file");
      require<FileError>(log != f.metadata.end(), name, ": metadata has no 'pretraining' (the log entry)");
      entry = nlohmann::json::parse(log->second, nullptr, false);
      require<FileError>(entry.is_object(), name, ": metadata 'pretraining' is not a JSON object");
    }
    load_checkpoint<T>(p, {PrefixedParams<T>{"encoder.", &params}}, nullptr);
    return entry;
  }

  // Writes params under key with its pre-training log entry (atomically).
  template <class T>
  void save(const nlohmann::json& key, ParamSet<T>& params, const nlohmann::json& entry) const {
    if (!enabled()) return;
    CheckpointState s;
    s.config = key;
    s.metadata["pretraining"] = entry.dump();
    save_checkpoint<T>(path(key), {PrefixedParams<T>{"encoder.", &params}}, nullptr, s);
  }

 private:
  std::filesystem::path dir_;
  nlohmann::json data_;
};

}  // namespace tjepa
