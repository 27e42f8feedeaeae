#pragma once

#include <atomic>
#include <chrono>
#include <cstdint>
#include <mutex>
#include <string>
#include <thread>

#include "cell/bus/participant.hpp"
#include "cell/bus/reader.hpp"
#include "cell/bus/waitset.hpp"
#include "cell/bus/writer.hpp"
#include "cell/service/common_config.hpp"

namespace cell::service {

/// Publishes this service's ServiceHeartbeat and answers PingRequests, on its own thread so
/// that a busy or real-time main loop needs no cooperation beyond tick(). The heartbeat
/// writer's liveliness is MANUAL_BY_TOPIC with a 3 s lease: a killed or frozen process is
/// noticed by every reader within 3 s. If the main loop stops calling tick() for
/// stall_timeout_s the heartbeat reports HEALTH_DEGRADED "main loop stalled".
/// All methods are thread-safe.
class HealthReporter {
 public:
  HealthReporter(const bus::Participant& participant, const CommonConfig& config,
                 std::string kind);
  ~HealthReporter();  ///< publishes HEALTH_STOPPING, disposes the instance, joins the thread
  HealthReporter(const HealthReporter&) = delete;
  HealthReporter& operator=(const HealthReporter&) = delete;

  /// Sets the reported state and detail, and publishes at once when they changed.
  void set(cell_health_HealthState state, std::string detail = {});

  /// The main loop is alive. Cheap (one atomic store): call it every iteration.
  void tick() noexcept;

  cell_health_HealthState state() const;
  std::uint64_t heartbeats_sent() const noexcept { return sent_.load(); }

 private:
  void loop();
  void publish_locked();
  void answer_pings();

  const bus::Participant& participant_;
  std::string service_id_;
  std::string kind_;
  std::string host_;
  std::chrono::nanoseconds period_;
  std::chrono::nanoseconds stall_timeout_;
  std::chrono::steady_clock::time_point started_;

  bus::Topic<cell_health_ServiceHeartbeat> heartbeat_topic_;
  bus::Topic<cell_health_PingRequest> ping_topic_;
  bus::Topic<cell_health_PingReply> pong_topic_;
  bus::Writer<cell_health_ServiceHeartbeat> heartbeat_writer_;
  bus::Reader<cell_health_PingRequest> ping_reader_;
  bus::Writer<cell_health_PingReply> pong_writer_;
  bus::GuardCondition wake_;
  bus::WaitSet waitset_;

  mutable std::mutex mutex_;
  cell_health_HealthState state_ = cell_health_HEALTH_STARTING;
  std::string detail_;
  bool stalled_ = false;
  std::uint64_t seq_ = 0;
  std::atomic<std::int64_t> last_tick_ns_;
  std::atomic<std::uint64_t> sent_{0};
  std::atomic<bool> stop_{false};
  std::thread thread_;
};

/// Name of a health state: "serving", "degraded", ...
std::string_view to_string(cell_health_HealthState state) noexcept;

}  // namespace cell::service
