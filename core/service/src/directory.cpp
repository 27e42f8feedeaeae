#include "cell/service/directory.hpp"

#include <algorithm>
#include <array>
#include <atomic>
#include <map>

#include <fmt/format.h>

#include "cell/bus/sample.hpp"
#include "cell/bus/topics.hpp"
#include "cell/bus/view.hpp"
#include "cell/common/time.hpp"
#include "cell/service/health.hpp"

namespace cell::service {
namespace {

constexpr dds_attach_t kUnread = 1;

// Every instance state, sample state and view state: the whole reader cache.
constexpr std::uint32_t kEverything = DDS_ANY_STATE;

std::string next_client_name(std::string_view client) {
  static std::atomic<unsigned> counter{0};
  return fmt::format("{}#{}", client, counter.fetch_add(1) + 1);
}

double ms_since(std::chrono::steady_clock::time_point t0) {
  return std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count();
}

}  // namespace

std::string_view ServiceEntry::status() const noexcept {
  return lost ? std::string_view("lost") : to_string(state);
}

ServiceDirectory::ServiceDirectory(const bus::Participant& participant, std::string_view client)
    : participant_(participant),
      topic_(participant, bus::topics::kHeartbeat),
      reader_(participant, topic_, bus::topics::kHeartbeat),
      unread_(bus::check_created(
          dds_create_readcondition(
              reader_.get(),
              DDS_NOT_READ_SAMPLE_STATE | DDS_ANY_VIEW_STATE | DDS_ANY_INSTANCE_STATE),
          "create read condition 'cell/health/heartbeat'")),
      waitset_(participant),
      client_(client) {
  waitset_.attach(unread_.get(), kUnread);
}

Result<std::vector<ServiceEntry>> ServiceDirectory::snapshot() {
  std::map<std::string, ServiceEntry, std::less<>> by_id;
  std::vector<dds_instance_handle_t> stopped;
  auto read = reader_.read_each(
      [&](const cell_health_ServiceHeartbeat& beat, const dds_sample_info_t& info) {
        // Cyclone 0.10 disposes (rather than unregisters) the instances of a writer whose
        // liveliness lapses, because writers autodispose by default: so "disposed" alone does
        // not mean a clean stop. A clean stop says HEALTH_STOPPING before it disposes.
        const bool disposed = info.instance_state == DDS_IST_NOT_ALIVE_DISPOSED;
        if (disposed && beat.state == cell_health_HEALTH_STOPPING) {
          stopped.push_back(info.instance_handle);
          return;
        }
        ServiceEntry entry;
        entry.service_id = bus::str(beat.service_id);
        entry.kind = bus::str(beat.service_kind);
        entry.host = bus::str(beat.host);
        entry.pid = beat.pid;
        entry.state = beat.state;
        entry.detail = bus::str(beat.detail);
        entry.uptime_s = beat.uptime_s;
        entry.version = bus::str(beat.version);
        entry.last_heartbeat_ns = beat.stamp_ns;
        entry.seq = beat.seq;
        entry.lost = disposed || info.instance_state == DDS_IST_NOT_ALIVE_NO_WRITERS;
        auto it = by_id.find(entry.service_id);
        if (it == by_id.end()) {
          by_id.emplace(entry.service_id, std::move(entry));
        } else if (entry.last_heartbeat_ns >= it->second.last_heartbeat_ns) {
          it->second = std::move(entry);  // keep-last-1 makes this rare; keep the newest
        }
      },
      kEverything);
  if (!read) {
    return std::move(read).error();
  }
  // Forget cleanly stopped services (and free their instances), so a long-lived directory
  // does not accumulate them.
  // Copy mode, not a loan: Cyclone 0.10 hands back its cached loan with as many slots as the
  // largest loan ever taken on this reader (read_each's 256), whatever buffer size we pass.
  for (const dds_instance_handle_t handle : stopped) {
    bus::Owned<cell_health_ServiceHeartbeat> sample;
    void* buf[1] = {&sample.get()};
    dds_sample_info_t info{};
    while (dds_take_instance(reader_.get(), buf, &info, 1, 1, handle) > 0) {
    }
  }
  std::vector<ServiceEntry> out;
  out.reserve(by_id.size());
  for (auto& [id, entry] : by_id) {
    out.push_back(std::move(entry));
  }
  return out;
}

bool ServiceDirectory::wait_for_change(std::chrono::steady_clock::time_point deadline) {
  return !waitset_.wait_until(deadline).empty();
}

Result<std::vector<ServiceEntry>> ServiceDirectory::wait_settled(
    std::chrono::milliseconds timeout,
    const std::set<std::string>& expected,
    std::chrono::milliseconds quiet) {
  using Clock = std::chrono::steady_clock;
  const auto deadline = Clock::now() + timeout;
  auto last_change = Clock::now();
  std::set<std::string> known;
  std::uint32_t known_writers = 0;
  for (;;) {
    auto snap = snapshot();
    if (!snap) {
      return snap;
    }
    std::set<std::string> ids;
    for (const auto& entry : *snap) {
      ids.insert(entry.service_id);
    }
    const std::uint32_t writers = reader_.matched_writers();
    const auto now = Clock::now();
    if (ids != known || writers != known_writers) {
      known = std::move(ids);
      known_writers = writers;
      last_change = now;
    }
    if (!expected.empty() &&
        std::includes(known.begin(), known.end(), expected.begin(), expected.end())) {
      return snap;
    }
    if (!known.empty() && now - last_change >= quiet) {
      return snap;
    }
    if (now >= deadline) {
      return snap;
    }
    (void)wait_for_change(known.empty() ? deadline : std::min(deadline, last_change + quiet));
  }
}

Result<std::vector<PingResult>> ServiceDirectory::ping(std::chrono::milliseconds timeout,
                                                       const std::set<std::string>& expect) {
  using Clock = std::chrono::steady_clock;
  const auto deadline = Clock::now() + timeout;
  if (!pinger_) {
    pinger_.emplace(participant_, bus::topics::kPingRequest, bus::topics::kPingReply,
                    bus::make_client_id(next_client_name(client_)));
  }
  auto left = [&] {
    return std::max(std::chrono::milliseconds(0),
                    std::chrono::duration_cast<std::chrono::milliseconds>(deadline - Clock::now()));
  };
  // The request topic is volatile: a service whose ping reader is not matched yet would never
  // see the request. Wait (within the budget) until every expected service can hear it.
  const auto wanted = static_cast<std::uint32_t>(std::max<std::size_t>(1, expect.size()));
  (void)pinger_->requests().wait_for_readers(wanted, left());
  (void)pinger_->replies().wait_for_writers(wanted, left());

  cell_health_PingRequest request{};
  const std::string everyone;
  request.target_service_id = bus::borrow(everyone);
  request.sent_ns = wall_time_ns();
  const auto sent = Clock::now();  // readers are matched: send() only writes now
  auto seq = pinger_->send(request, left());
  if (!seq) {
    return Error{seq.error().code,
                 fmt::format("ping on domain {} partition '{}': {}", participant_.domain_id(),
                             participant_.partition(), seq.error().message)};
  }
  std::map<std::string, PingResult, std::less<>> replies;
  auto done = pinger_->wait_reply(*seq, deadline, [&](const cell_health_PingReply& reply) {
    const std::string id(bus::str(reply.service_id));
    if (replies.count(id) == 0) {
      replies.emplace(id,
                      PingResult{id, std::string(bus::str(reply.host)), reply.pid, ms_since(sent)});
    }
    if (expect.empty()) {
      return false;  // collect until the deadline
    }
    return std::all_of(expect.begin(), expect.end(),
                       [&](const std::string& want) { return replies.count(want) > 0; });
  });
  if (!done && done.error().code != Errc::kTimeout) {
    return std::move(done).error();
  }
  std::vector<PingResult> out;
  out.reserve(replies.size());
  for (auto& [id, result] : replies) {
    out.push_back(std::move(result));
  }
  return out;
}

}  // namespace cell::service
