#pragma once

#include <cstdint>
#include <string>

#include "cell/bus/entity.hpp"

namespace cell::bus {

/// A DDS domain participant plus one publisher and one subscriber carrying the cell's
/// partition: every reader and writer made from it lives in that partition, so several cells
/// (or concurrent tests) can share a domain without seeing each other.
/// Members are declared in creation order so destruction runs children first.
class Participant {
 public:
  /// Throws BusError when the participant cannot be created (bad domain id, bad
  /// CYCLONEDDS_URI configuration). `partition` must not be empty.
  Participant(std::uint32_t domain_id, std::string partition);

  dds_entity_t get() const noexcept { return participant_.get(); }
  dds_entity_t publisher() const noexcept { return publisher_.get(); }
  dds_entity_t subscriber() const noexcept { return subscriber_.get(); }
  std::uint32_t domain_id() const noexcept { return domain_id_; }
  const std::string& partition() const noexcept { return partition_; }

 private:
  std::uint32_t domain_id_;
  std::string partition_;
  Entity participant_;
  Entity publisher_;
  Entity subscriber_;
};

}  // namespace cell::bus
