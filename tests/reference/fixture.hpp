#pragma once
// The PyTorch fixture's dumps (tools/reference/fixture.py, committed under tests/data/reference/):
// its tensors as files and values, and the relative error against them. Shared by the reference
// tests and the `tjepa convert` tests of apps/tjepa.
#include <doctest/doctest.h>

#include <tjepa/tjepa.hpp>

#include <cmath>
#include <cstdint>
#include <filesystem>
#include <span>
#include <string>
#include <vector>

namespace tjepa::reference_fixture {

inline std::filesystem::path fixture_dir() { return std::filesystem::path(TJEPA_TEST_DATA_DIR) / "reference"; }

// The tensors of f under `prefix`, without it, as a file of their own.
inline SafetensorsFile fixture_part(const SafetensorsFile& f, const std::string& prefix) {
  SafetensorsFile out;
  for (const std::string& name : f.names())
    if (name.starts_with(prefix)) out.add(name.substr(prefix.size()), f.at(name));
  out.set_source(f.source() + " [" + prefix + "]");
  return out;
}

// f with every F64 tensor as F32 (the float64 fixture's model for a float model).
inline SafetensorsFile fixture_as_float(const SafetensorsFile& f) {
  SafetensorsFile out;
  for (const std::string& name : f.names()) {
    const Tensor& t = f.at(name);
    if (t.dtype != Dtype::F64 || name.ends_with(".stats")) {
      out.add(name, t);
      continue;
    }
    const auto v = t.to_vector<double>();
    out.add(name, Tensor::from(std::vector<float>(v.begin(), v.end()), t.shape));
  }
  out.metadata = f.metadata;
  out.set_source(f.source() + " [as float32]");
  return out;
}

// ‖a − b‖ / ‖b‖ (‖a‖ when b is 0), over the entries [skip_begin, skip_end) left out.
template <class T>
double fixture_error(std::span<const T> a, const std::vector<double>& b, std::size_t skip_begin = 0,
                     std::size_t skip_end = 0) {
  REQUIRE(a.size() == b.size());
  double diff = 0, nb = 0, na = 0;
  for (std::size_t i = 0; i < b.size(); ++i) {
    if (i >= skip_begin && i < skip_end) continue;
    diff += (double(a[i]) - b[i]) * (double(a[i]) - b[i]);
    nb += b[i] * b[i];
    na += double(a[i]) * double(a[i]);
  }
  return std::sqrt(diff) / std::sqrt(nb > 0 ? nb : (na > 0 ? na : 1.0));
}

inline std::vector<double> fixture_values(const SafetensorsFile& f, const std::string& name) {
  REQUIRE_MESSAGE(f.contains(name), "fixture tensor ", name);
  const Tensor& t = f.at(name);
  if (t.dtype == Dtype::F32) {
    const auto v = t.to_vector<float>();
    return {v.begin(), v.end()};
  }
  return t.to_vector<double>();
}

inline std::vector<int> fixture_ints(const SafetensorsFile& f, const std::string& name) {
  const auto v = f.at(name).to_vector<std::int64_t>();
  return {v.begin(), v.end()};
}
}  // namespace tjepa::reference_fixture
