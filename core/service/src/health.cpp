#include "cell/service/health.hpp"

#include <unistd.h>

#include <fmt/format.h>

#include "cell/bus/topics.hpp"
#include "cell/bus/view.hpp"
#include "cell/common/log.hpp"
#include "cell/common/time.hpp"
#include "cell/common/version.hpp"

namespace cell::service {
namespace {

constexpr dds_attach_t kPing = 1;
constexpr dds_attach_t kWake = 2;

std::string hostname() {
  char host[256] = {};
  gethostname(host, sizeof host - 1);
  return host;
}

}  // namespace

std::string_view to_string(cell_health_HealthState state) noexcept {
  switch (state) {
    case cell_health_HEALTH_STARTING:
      return "starting";
    case cell_health_HEALTH_SERVING:
      return "serving";
    case cell_health_HEALTH_DEGRADED:
      return "degraded";
    case cell_health_HEALTH_FAULT:
      return "fault";
    case cell_health_HEALTH_STOPPING:
      return "stopping";
  }
  return "unknown";
}

HealthReporter::HealthReporter(const bus::Participant& participant, const CommonConfig& config,
                               std::string kind)
    : participant_(participant),
      service_id_(config.service_id),
      kind_(std::move(kind)),
      host_(hostname()),
      period_(std::chrono::nanoseconds(static_cast<std::int64_t>(config.heartbeat_period_s * 1e9))),
      stall_timeout_(
          std::chrono::nanoseconds(static_cast<std::int64_t>(config.stall_timeout_s * 1e9))),
      started_(std::chrono::steady_clock::now()),
      heartbeat_topic_(participant, bus::topics::kHeartbeat),
      ping_topic_(participant, bus::topics::kPingRequest),
      pong_topic_(participant, bus::topics::kPingReply),
      heartbeat_writer_(participant, heartbeat_topic_, bus::topics::kHeartbeat),
      ping_reader_(participant, ping_topic_, bus::topics::kPingRequest),
      pong_writer_(participant, pong_topic_, bus::topics::kPingReply),
      wake_(participant),
      waitset_(participant),
      last_tick_ns_(monotonic_ns()) {
  waitset_.attach(ping_reader_.condition(), kPing);
  waitset_.attach(wake_.get(), kWake);
  {
    std::lock_guard lock(mutex_);
    publish_locked();
  }
  thread_ = std::thread([this] { loop(); });
}

HealthReporter::~HealthReporter() {
  stop_ = true;
  wake_.trigger();
  thread_.join();
  std::lock_guard lock(mutex_);
  state_ = cell_health_HEALTH_STOPPING;
  publish_locked();
  // Dispose: readers drop us at once (a crash instead shows as lost liveliness).
  cell_health_ServiceHeartbeat key{};
  key.service_id = bus::borrow(service_id_);
  key.service_kind = bus::borrow(kind_);
  key.host = bus::borrow(host_);
  key.detail = bus::borrow(detail_);
  const std::string version_text(version());
  key.version = bus::borrow(version_text);
  (void)heartbeat_writer_.dispose(key);
}

void HealthReporter::set(cell_health_HealthState state, std::string detail) {
  std::lock_guard lock(mutex_);
  if (state == state_ && detail == detail_) {
    return;
  }
  state_ = state;
  detail_ = std::move(detail);
  log::info("health", std::string(to_string(state_)), {{"detail", detail_}});
  publish_locked();
}

cell_health_HealthState HealthReporter::state() const {
  std::lock_guard lock(mutex_);
  return state_;
}

void HealthReporter::tick() noexcept {
  last_tick_ns_.store(monotonic_ns(), std::memory_order_relaxed);
}

void HealthReporter::publish_locked() {
  const auto now = std::chrono::steady_clock::now();
  const std::int64_t silent_ns = monotonic_ns() - last_tick_ns_.load(std::memory_order_relaxed);
  const bool stalled = silent_ns > stall_timeout_.count() &&
                       state_ != cell_health_HEALTH_STOPPING &&
                       state_ != cell_health_HEALTH_STARTING;
  if (stalled != stalled_) {
    stalled_ = stalled;
    if (stalled) {
      log::warn("health", "main loop stalled", {{"silent_s", fmt::format("{:.1f}", static_cast<double>(silent_ns) * 1e-9)}});
    }
  }
  std::string detail = detail_;
  cell_health_HealthState state = state_;
  if (stalled && state == cell_health_HEALTH_SERVING) {
    state = cell_health_HEALTH_DEGRADED;
    detail = fmt::format("main loop stalled for {:.1f} s", static_cast<double>(silent_ns) * 1e-9);
  }
  const std::string version_text(version());
  cell_health_ServiceHeartbeat beat{};
  beat.service_id = bus::borrow(service_id_);
  beat.service_kind = bus::borrow(kind_);
  beat.host = bus::borrow(host_);
  beat.pid = static_cast<std::int32_t>(getpid());
  beat.state = state;
  beat.detail = bus::borrow(detail);
  beat.uptime_s = std::chrono::duration<double>(now - started_).count();
  beat.stamp_ns = wall_time_ns();
  beat.version = bus::borrow(version_text);
  beat.seq = ++seq_;
  if (auto status = heartbeat_writer_.write(beat); !status) {
    log::warn("heartbeat", status.error().message);
  } else {
    sent_.fetch_add(1);
  }
}

void HealthReporter::answer_pings() {
  (void)ping_reader_.take_each([&](const cell_health_PingRequest& ping, const dds_sample_info_t&) {
    const std::string_view target = bus::str(ping.target_service_id);
    if (!target.empty() && target != service_id_) {
      return;
    }
    cell_health_PingReply reply{};
    reply.request_id = ping.request_id;  // borrowed from the loan, valid during this call
    reply.service_id = bus::borrow(service_id_);
    reply.host = bus::borrow(host_);
    reply.pid = static_cast<std::int32_t>(getpid());
    reply.sent_ns = ping.sent_ns;
    reply.replied_ns = wall_time_ns();
    if (auto status = pong_writer_.write(reply); !status) {
      log::warn("ping", status.error().message);
    }
  });
}

void HealthReporter::loop() {
  auto next_beat = std::chrono::steady_clock::now() + period_;
  while (!stop_) {
    const bus::Fired fired = waitset_.wait_until(next_beat);
    if (stop_) {
      break;
    }
    if (fired.contains(kWake)) {
      wake_.reset();
    }
    if (fired.contains(kPing)) {
      answer_pings();
    }
    const auto now = std::chrono::steady_clock::now();
    if (now >= next_beat) {
      std::lock_guard lock(mutex_);
      publish_locked();
      next_beat += period_;
      if (next_beat < now) {
        next_beat = now + period_;  // we were suspended: do not burst
      }
    }
  }
}

}  // namespace cell::service
