#pragma once
// PrefixedParams: a ParamSet together with the prefix its names carry in a whole model's state
// dict. The JEPA model is several ParamSets (context encoder, predictor, target encoder, ...);
// gradient clipping, AdamW and checkpoints work on a list of them, and the prefix makes the full
// PyTorch name: "context_encoder." + "blocks.0.attn.qkv.weight".
#include <span>
#include <string>
#include <unordered_set>

#include "tjepa/core/error.hpp"
#include "tjepa/core/param_set.hpp"

namespace tjepa {

template <class T>
struct PrefixedParams {
  std::string prefix;            // e.g. "context_encoder."; may be empty
  ParamSet<T>* params = nullptr; // not owned
};

// Checks that every part is set and allocated and that no full name appears twice.
template <class T>
void check_prefixed_params(std::span<const PrefixedParams<T>> parts, const char* who) {
  std::unordered_set<std::string> seen;
  for (const auto& part : parts) {
    require<ConfigError>(part.params != nullptr, who, ": part with prefix '", part.prefix,
                         "' has no ParamSet (null pointer)");
    require<ConfigError>(part.params->allocated(), who, ": ParamSet with prefix '", part.prefix,
                         "' is not allocated, expected allocate() to have been called");
    for (const auto& info : part.params->infos()) {
      const std::string full = part.prefix + info.name;
      require<ConfigError>(seen.insert(full).second, who, ": parameter name '", full,
                           "' appears twice, expected unique full names");
    }
  }
}

}  // namespace tjepa
