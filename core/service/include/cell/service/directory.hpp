#pragma once

#include <chrono>
#include <cstdint>
#include <optional>
#include <set>
#include <string>
#include <string_view>
#include <vector>

#include "cell/bus/entity.hpp"
#include "cell/bus/participant.hpp"
#include "cell/bus/reader.hpp"
#include "cell/bus/request_reply.hpp"
#include "cell/bus/topic.hpp"
#include "cell/bus/waitset.hpp"
#include "cell/common/result.hpp"

namespace cell::service {

/// One service as its latest heartbeat (topic cell/health/heartbeat) describes it.
struct ServiceEntry {
  std::string service_id;  ///< unique instance name on the bus, e.g. "echo2"
  std::string kind;        ///< executable kind, e.g. "echo"
  std::string host;        ///< hostname of the process
  std::int32_t pid = 0;    ///< process id on `host`
  cell_health_HealthState state = cell_health_HEALTH_STARTING;  ///< as last reported
  std::string detail;                  ///< why degraded/fault; empty when serving
  double uptime_s = 0.0;               ///< process uptime when the heartbeat was sent
  std::string version;                 ///< cell version of the process
  std::int64_t last_heartbeat_ns = 0;  ///< wall clock (ns since epoch) the heartbeat was sent
  std::uint64_t seq = 0;               ///< heartbeat counter of the writer
  /// True when the service vanished without a clean stop: the process died or hung and its
  /// 3 s liveliness lease expired (instance NOT_ALIVE_NO_WRITERS, or NOT_ALIVE_DISPOSED with a
  /// last state other than stopping: Cyclone 0.10 disposes the instances of a lapsed writer
  /// that autodisposes, which is the default). A service that stops cleanly publishes
  /// "stopping" and disposes its instance: it is simply absent from the directory.
  bool lost = false;

  /// "lost" when `lost`, else the reported state: "starting", "serving", "degraded", ...
  std::string_view status() const noexcept;
};

/// Round trip of one ping to one service.
struct PingResult {
  std::string service_id;  ///< who answered
  std::string host;        ///< its hostname
  std::int32_t pid = 0;    ///< its process id on `host`
  /// Requester's monotonic time from the write to the reply being taken. The first request
  /// after discovery pays Cyclone's first-contact delay (about 10 ms on loopback): ping twice
  /// to measure the steady round trip.
  double rtt_ms = 0.0;
};

/// The live services of one cell (the participant's domain and partition), from their
/// heartbeats. The heartbeat topic is transient-local, so a new directory sees every live
/// service as soon as discovery completes; wait_settled() waits for that. A service that died
/// before the directory was created is absent, not lost: nothing is left to tell of it.
///
/// Used by `cell status` and `cellctl ping`, and by tests. Not thread-safe: one thread at a
/// time. Must not outlive `participant`. Constructors throw bus::BusError on setup failure
/// (STYLE.md §4 channel 2); every other method reports failures as Result errors.
class ServiceDirectory {
 public:
  /// Creates the heartbeat reader. The ping requester is created on the first ping(); its
  /// client id is "<client>#<n>@<host>:<pid>".
  explicit ServiceDirectory(const bus::Participant& participant, std::string_view client = "cell");

  /// Every service whose heartbeat is in the reader now, alive or lost, sorted by
  /// service_id. Cleanly stopped services are absent and purged from the reader.
  /// Errors: kBus when reading fails.
  Result<std::vector<ServiceEntry>> snapshot();

  /// Waits for discovery to settle, then returns snapshot(): returns once at least one
  /// service is known and neither the set of services nor the number of matched heartbeat
  /// writers changed for `quiet`, or once every id in `expected` is present (whichever comes
  /// first), or when `timeout` passes (returning what is known then, possibly nothing).
  /// Blocks on a DDS waitset, never sleep-polls. Errors: kBus.
  Result<std::vector<ServiceEntry>> wait_settled(
      std::chrono::milliseconds timeout,
      const std::set<std::string>& expected = {},
      std::chrono::milliseconds quiet = std::chrono::milliseconds(300));

  /// Blocks until a new heartbeat or an instance state change arrives, or `deadline`.
  /// Returns whether something arrived.
  bool wait_for_change(std::chrono::steady_clock::time_point deadline);

  /// Sends one PingRequest to every service (target "") and collects replies until
  /// `timeout` passes or every id in `expect` answered. Before sending it waits (within the
  /// same timeout) until `expect.size()` ping readers are matched, so a service that is
  /// discovered late still gets the request. Results are sorted by service_id; a service that
  /// did not answer is absent. Errors: kTimeout when no ping server is on the bus at all;
  /// kBus when writing or reading fails.
  Result<std::vector<PingResult>> ping(std::chrono::milliseconds timeout,
                                       const std::set<std::string>& expect = {});

  /// Number of heartbeat writers currently matched (alive or not yet timed out).
  std::uint32_t matched_writers() const noexcept { return reader_.matched_writers(); }

 private:
  const bus::Participant& participant_;
  bus::Topic<cell_health_ServiceHeartbeat> topic_;
  bus::Reader<cell_health_ServiceHeartbeat> reader_;
  bus::Entity unread_;  ///< read condition: samples (valid or not) not read yet
  bus::WaitSet waitset_;
  std::string client_;
  std::optional<bus::Requester<cell_health_PingRequest, cell_health_PingReply>> pinger_;
};

}  // namespace cell::service
