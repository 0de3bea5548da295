#pragma once
// Shared float storage with copy-on-write: either an owned aligned buffer or a read-only view into
// a memory-mapped file. Copies share the bytes; the first write through a shared or mapped view
// makes a private copy, so a mapped multi-GB recording is only ever copied when someone edits it.
#include <algorithm>
#include <cstddef>
#include <memory>
#include <span>

#include "tjepa/core/aligned.hpp"

namespace tjepa::detail {

class FloatStorage {
 public:
  FloatStorage() = default;
  // n owned values, all equal to `value`.
  explicit FloatStorage(std::size_t n, float value = 0.0f) {
    auto v = std::make_shared<AlignedVector<float>>(n, value);
    data_ = v->data();
    size_ = n;
    owner_ = std::move(v);
    writable_ = true;
  }
  // Takes ownership of the values.
  explicit FloatStorage(AlignedVector<float>&& values) {
    auto v = std::make_shared<AlignedVector<float>>(std::move(values));
    data_ = v->data();
    size_ = v->size();
    owner_ = std::move(v);
    writable_ = true;
  }
  // A read-only view whose bytes `owner` keeps alive (e.g. a mapped file).
  FloatStorage(const float* data, std::size_t n, std::shared_ptr<const void> owner)
      : owner_(std::move(owner)), data_(data), size_(n), writable_(false) {}

  std::size_t size() const { return size_; }
  const float* data() const { return data_; }
  std::span<const float> values() const { return {data_, size_}; }

  // Writable pointer; copies first if the bytes are mapped or shared with another copy.
  float* mutable_data() {
    if (!writable_ || owner_.use_count() != 1) {
      AlignedVector<float> copy(data_, data_ + size_);
      *this = FloatStorage(std::move(copy));
    }
    return const_cast<float*>(data_);
  }

  // A view of values [offset, offset + n) sharing this storage.
  FloatStorage slice(std::size_t offset, std::size_t n) const {
    FloatStorage s = *this;
    s.data_ = data_ + offset;
    s.size_ = n;
    return s;
  }

  // True if the values live in a mapped file or are shared by another copy.
  bool shared() const { return !writable_ || owner_.use_count() != 1; }

 private:
  std::shared_ptr<const void> owner_;
  const float* data_ = nullptr;
  std::size_t size_ = 0;
  bool writable_ = false;
};

}  // namespace tjepa::detail
