#pragma once
// NamedTensor: a named float array with a shape, the unit in which fitted statistics (the
// preprocessor's baseline, means, stds, ...) travel into and out of a checkpoint.
#include <cstddef>
#include <cstdint>
#include <span>
#include <string>
#include <string_view>
#include <vector>

#include "tjepa/core/error.hpp"

namespace tjepa {

struct NamedTensor {
  std::string name;
  std::vector<std::int64_t> shape;
  std::vector<float> values;  // row-major, product(shape) entries
};

// The tensor called `name` in `tensors`; throws FileError (`who` names the caller) if absent.
inline const NamedTensor& find_tensor(std::span<const NamedTensor> tensors, std::string_view name,
                                      std::string_view who) {
  for (const auto& t : tensors)
    if (t.name == name) return t;
  fail<FileError>(who, ": no tensor named '", name, "' in the saved state");
}

}  // namespace tjepa
