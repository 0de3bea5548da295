#pragma once
// ParamSet: every parameter of a model in one flat aligned buffer, with named views.
//
// Names follow the reference PyTorch model ("blocks.3.attn.qkv.weight", "pos_embed", ...), so a
// checkpoint maps one-to-one. Gradients live in a second buffer with the identical layout, so
// zero_grad, clipping, AdamW and the EMA are each one loop over a flat array.
//
// Life cycle: modules call add() while they are built (getting a ParamId back), then allocate()
// makes the buffers (values 0). A module keeps only ParamIds, so the same module code runs on any
// ParamSet of the same layout: that is how the EMA target encoder shares the context encoder's code.
#include <algorithm>
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <span>
#include <string>
#include <string_view>
#include <unordered_map>
#include <vector>

#include "tjepa/core/aligned.hpp"
#include "tjepa/core/error.hpp"
#include "tjepa/core/detail/parallel.hpp"

namespace tjepa {

// A handle to one tensor of a ParamSet: its offset and size in the flat buffer.
struct ParamId {
  std::size_t index = static_cast<std::size_t>(-1);  // position in ParamSet::infos()
  std::size_t offset = 0;                            // first element in the flat buffer
  std::size_t size = 0;                              // number of elements
};

// How init_params (model/init.hpp) fills a tensor; modules choose it when they register it.
enum class ParamInit {
  zeros,         // biases, the predictor's mask token (zero_init_mask_tokens)
  ones,          // LayerNorm weights
  trunc_normal,  // Linear weights, position table, query token: N(0, 0.02²) truncated at ±2
  uniform,       // U(−bound, bound): PyTorch's default for Conv2d and Linear (bound 1/√fan_in)
};

struct ParamInfo {
  std::string name;                // reference PyTorch name
  std::vector<std::int64_t> shape; // PyTorch shape, e.g. {576, 192} for a Linear(192 -> 576)
  std::size_t offset = 0;
  std::size_t size = 0;
  // AdamW weight decay applies (I-JEPA's rule: not a bias and not 1-D).
  bool decay = false;
  ParamInit init = ParamInit::zeros;
  double bound = 0;  // ParamInit::uniform's bound
};

// I-JEPA's parameter-group rule: weight decay on everything except biases and 1-D tensors.
inline bool default_decay(std::string_view name, const std::vector<std::int64_t>& shape) {
  const bool bias = name.size() >= 4 && name.substr(name.size() - 4) == "bias";
  return !bias && shape.size() != 1;
}

template <class T>
class ParamSet {
 public:
  using Scalar = T;

  // Registers a tensor. Offsets are padded to 64 bytes so every view is aligned.
  ParamId add(std::string name, std::vector<std::int64_t> shape, ParamInit init = ParamInit::zeros, double bound = 0) {
    require<ConfigError>(!allocated(), "ParamSet::add('", name, "'): the set is already allocated");
    require<ConfigError>(!name.empty(), "ParamSet::add: empty name");
    require<ConfigError>(!by_name_.contains(name), "ParamSet::add: duplicate name '", name, "'");
    std::size_t n = 1;
    for (auto s : shape) {
      require<ShapeError>(s > 0, "ParamSet::add('", name, "'): dimension ", s, ", expected > 0");
      n *= static_cast<std::size_t>(s);
    }
    constexpr std::size_t pad = alignment / sizeof(T) > 0 ? alignment / sizeof(T) : 1;
    const std::size_t offset = (total_ + pad - 1) / pad * pad;
    require<ConfigError>(init != ParamInit::uniform || (std::isfinite(bound) && bound > 0), "ParamSet::add('", name,
                         "'): uniform bound ", bound, ", expected a finite value > 0");
    ParamInfo info{std::move(name), std::move(shape), offset, n, false, init, bound};
    info.decay = default_decay(info.name, info.shape);
    const ParamId id{infos_.size(), offset, n};
    by_name_.emplace(info.name, id.index);
    infos_.push_back(std::move(info));
    total_ = offset + n;
    return id;
  }

  // Makes the value and gradient buffers, both zero.
  void allocate() {
    require<ConfigError>(!allocated(), "ParamSet::allocate: already allocated");
    value_.assign(total_, T(0));
    grad_.assign(total_, T(0));
    allocated_ = true;
  }
  bool allocated() const { return allocated_; }

  // Flat buffers (padding between tensors stays zero in values and gradients).
  std::span<T> values() { return value_; }
  std::span<const T> values() const { return value_; }
  std::span<T> grads() { return grad_; }
  std::span<const T> grads() const { return grad_; }
  std::size_t flat_size() const { return total_; }

  T* value(const ParamId& id) { return value_.data() + id.offset; }
  const T* value(const ParamId& id) const { return value_.data() + id.offset; }
  T* grad(const ParamId& id) { return grad_.data() + id.offset; }
  const T* grad(const ParamId& id) const { return grad_.data() + id.offset; }

  std::span<T> value_span(const ParamId& id) { return {value(id), id.size}; }
  std::span<const T> value_span(const ParamId& id) const { return {value(id), id.size}; }
  std::span<T> grad_span(const ParamId& id) { return {grad(id), id.size}; }
  std::span<const T> grad_span(const ParamId& id) const { return {grad(id), id.size}; }

  void zero_grad() { detail::parallel_fill(grad_.data(), grad_.data() + grad_.size(), T(0)); }

  // Iteration by name, in registration order.
  const std::vector<ParamInfo>& infos() const { return infos_; }
  std::size_t count() const { return infos_.size(); }
  // Number of scalar parameters (without padding).
  std::size_t numel() const {
    std::size_t n = 0;
    for (const auto& i : infos_) n += i.size;
    return n;
  }
  ParamId id(std::size_t index) const {
    require<ConfigError>(index < infos_.size(), "ParamSet::id: index ", index, " out of range [0, ",
                         infos_.size(), ")");
    const auto& i = infos_[index];
    return {index, i.offset, i.size};
  }
  bool contains(std::string_view name) const { return by_name_.contains(std::string(name)); }
  ParamId id(std::string_view name) const {
    auto it = by_name_.find(std::string(name));
    if (it == by_name_.end()) fail<ConfigError>("ParamSet: no parameter named '", name, "'");
    return id(it->second);
  }

  // Decay / no-decay groups for AdamW, as lists of parameter indices.
  std::vector<std::size_t> decay_group() const { return group(true); }
  std::vector<std::size_t> no_decay_group() const { return group(false); }
  void set_decay(std::string_view name, bool decay) { infos_[id(name).index].decay = decay; }

  // Same names, shapes and offsets: buffers of the two sets can be combined element-wise.
  bool same_layout(const ParamSet& o) const {
    if (o.infos_.size() != infos_.size() || o.total_ != total_) return false;
    for (std::size_t i = 0; i < infos_.size(); ++i)
      if (infos_[i].name != o.infos_[i].name || infos_[i].shape != o.infos_[i].shape ||
          infos_[i].offset != o.infos_[i].offset)
        return false;
    return true;
  }

 private:
  std::vector<std::size_t> group(bool decay) const {
    std::vector<std::size_t> out;
    for (std::size_t i = 0; i < infos_.size(); ++i)
      if (infos_[i].decay == decay) out.push_back(i);
    return out;
  }

  std::vector<ParamInfo> infos_;
  std::unordered_map<std::string, std::size_t> by_name_;
  std::size_t total_ = 0;
  bool allocated_ = false;
  AlignedVector<T> value_, grad_;
};

}  // namespace tjepa
