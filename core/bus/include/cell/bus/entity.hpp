#pragma once

#include <memory>
#include <stdexcept>
#include <string>
#include <string_view>
#include <utility>

#include <dds/dds.h>

namespace cell::bus {

/// Setup failure of a DDS entity (STYLE.md §4, channel 2): thrown by constructors only.
/// what() reads "create reader 'cell/robot/state': Bad parameter".
class BusError : public std::runtime_error {
 public:
  BusError(dds_return_t code, std::string_view what);
  dds_return_t code() const noexcept { return code_; }

 private:
  dds_return_t code_;
};

/// Sole owner of one Cyclone entity; move-only. Deleting a parent deletes its children, so
/// ALREADY_DELETED from a child is normal, not an error.
class Entity {
 public:
  Entity() = default;
  explicit Entity(dds_entity_t handle) noexcept : handle_(handle) {}
  Entity(Entity&& other) noexcept : handle_(std::exchange(other.handle_, 0)) {}
  Entity& operator=(Entity&& other) noexcept {
    if (this != &other) {
      reset();
      handle_ = std::exchange(other.handle_, 0);
    }
    return *this;
  }
  Entity(const Entity&) = delete;
  Entity& operator=(const Entity&) = delete;
  ~Entity() { reset(); }

  dds_entity_t get() const noexcept { return handle_; }
  explicit operator bool() const noexcept { return handle_ > 0; }

  /// Deletes the entity (and its children). noexcept: failures are logged.
  void reset() noexcept;

 private:
  dds_entity_t handle_ = 0;
};

/// Setup only: a negative create result becomes BusError(what).
dds_entity_t check_created(dds_entity_t handle, std::string_view what);

/// Owning QoS pointer.
using Qos = std::unique_ptr<dds_qos_t, decltype(&dds_delete_qos)>;
inline Qos make_qos() { return Qos(dds_create_qos(), &dds_delete_qos); }

}  // namespace cell::bus
