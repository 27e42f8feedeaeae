#pragma once

#include <array>
#include <chrono>
#include <cstddef>

#include "cell/bus/entity.hpp"
#include "cell/bus/participant.hpp"

namespace cell::bus {

/// A condition the application triggers (shutdown, a queue filled by another thread).
/// trigger() is thread-safe and async-signal-unsafe; call it from a normal thread.
class GuardCondition {
 public:
  explicit GuardCondition(const Participant& participant);
  void trigger() const noexcept;
  void reset() const noexcept;
  bool triggered() const noexcept;
  dds_entity_t get() const noexcept { return entity_.get(); }

 private:
  Entity entity_;
};

/// Tokens of the attachments that fired in one wait (at most 16).
class Fired {
 public:
  bool contains(dds_attach_t token) const noexcept;
  bool empty() const noexcept { return count_ == 0; }
  std::size_t size() const noexcept { return count_; }
  void add(dds_attach_t token) noexcept;

 private:
  std::array<dds_attach_t, 16> tokens_{};
  std::size_t count_ = 0;
};

/// A Cyclone waitset: block until an attached condition (read condition, guard condition,
/// status condition of an entity) triggers or a deadline passes. Never sleep-poll.
class WaitSet {
 public:
  explicit WaitSet(const Participant& participant);

  /// Attaches `entity` (a condition or an entity whose status mask is set); `token` comes
  /// back in Fired. Throws BusError on a bad entity (setup).
  void attach(dds_entity_t entity, dds_attach_t token);
  void detach(dds_entity_t entity) noexcept;

  /// Waits up to `timeout`; returns the tokens that fired (empty on timeout).
  Fired wait(std::chrono::nanoseconds timeout) const;

  /// Waits until the absolute steady deadline.
  Fired wait_until(std::chrono::steady_clock::time_point deadline) const;

 private:
  Entity entity_;
};

}  // namespace cell::bus
