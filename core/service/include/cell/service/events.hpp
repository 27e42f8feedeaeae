#pragma once

#include <atomic>
#include <string>
#include <string_view>

#include "cell/bus/participant.hpp"
#include "cell/bus/topic.hpp"
#include "cell/bus/writer.hpp"

namespace cell::service {

/// Publishes CellEvents (faults, refusals, recoveries) under this service's id, and logs
/// each one. Thread-safe.
class EventPublisher {
 public:
  EventPublisher(const bus::Participant& participant, std::string source);

  /// `code` is a stable tag ("dpr.deadline_torques"); `text` a sentence for an operator.
  void publish(cell_health_Severity severity, std::string_view code, std::string_view text,
               std::string_view robot_id = {}, std::string_view job_id = {});

 private:
  std::string source_;
  bus::Topic<cell_health_CellEvent> topic_;
  bus::Writer<cell_health_CellEvent> writer_;
  std::atomic<std::uint64_t> seq_{0};
};

}  // namespace cell::service
