#pragma once

#include <cstring>
#include <utility>

#include "cell/bus/idl_types.hpp"

namespace cell::bus {

/// A deep copy of a sample that owns its strings and sequences (filled by Cyclone in copy
/// mode, Reader::take_copies). Frees them with dds_sample_free on destruction. Move-only.
template <IdlType T>
class Owned {
 public:
  Owned() noexcept { std::memset(&sample_, 0, sizeof sample_); }
  Owned(Owned&& other) noexcept {
    std::memcpy(&sample_, &other.sample_, sizeof sample_);
    std::memset(&other.sample_, 0, sizeof other.sample_);
  }
  Owned& operator=(Owned&& other) noexcept {
    if (this != &other) {
      dds_sample_free(&sample_, kDescriptor<T>, DDS_FREE_CONTENTS);
      std::memcpy(&sample_, &other.sample_, sizeof sample_);
      std::memset(&other.sample_, 0, sizeof other.sample_);
    }
    return *this;
  }
  Owned(const Owned&) = delete;
  Owned& operator=(const Owned&) = delete;
  ~Owned() { dds_sample_free(&sample_, kDescriptor<T>, DDS_FREE_CONTENTS); }

  T& get() noexcept { return sample_; }
  const T& get() const noexcept { return sample_; }
  T* operator->() noexcept { return &sample_; }
  const T* operator->() const noexcept { return &sample_; }
  const T& operator*() const noexcept { return sample_; }

 private:
  T sample_;
};

}  // namespace cell::bus
