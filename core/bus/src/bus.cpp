#include <unistd.h>

#include <atomic>
#include <cstdlib>
#include <random>
#include <string_view>

#include <fmt/format.h>

#include "cell/bus/entity.hpp"
#include "cell/bus/participant.hpp"
#include "cell/bus/qos.hpp"
#include "cell/bus/reader.hpp"
#include "cell/bus/request_reply.hpp"
#include "cell/bus/waitset.hpp"
#include "cell/bus/writer.hpp"
#include "cell/common/log.hpp"

namespace cell::bus {

BusError::BusError(dds_return_t code, std::string_view what)
    : std::runtime_error(fmt::format("{}: {}", what, dds_strretcode(code))), code_(code) {}

void Entity::reset() noexcept {
  if (handle_ > 0) {
    const dds_return_t rc = dds_delete(handle_);
    if (rc != DDS_RETCODE_OK && rc != DDS_RETCODE_ALREADY_DELETED &&
        rc != DDS_RETCODE_BAD_PARAMETER) {
      log::warn("dds_delete", dds_strretcode(rc));
    }
    handle_ = 0;
  }
}

dds_entity_t check_created(dds_entity_t handle, std::string_view what) {
  if (handle < 0) {
    throw BusError(handle, what);
  }
  return handle;
}

// ---------------------------------------------------------------------------------------------
namespace qos {

Qos state() {
  Qos q = make_qos();
  dds_qset_reliability(q.get(), DDS_RELIABILITY_RELIABLE, DDS_SECS(1));
  dds_qset_durability(q.get(), DDS_DURABILITY_TRANSIENT_LOCAL);
  dds_qset_history(q.get(), DDS_HISTORY_KEEP_LAST, 1);
  return q;
}

Qos stream(std::int32_t depth) {
  Qos q = make_qos();
  dds_qset_reliability(q.get(), DDS_RELIABILITY_BEST_EFFORT, 0);
  dds_qset_durability(q.get(), DDS_DURABILITY_VOLATILE);
  dds_qset_history(q.get(), DDS_HISTORY_KEEP_LAST, depth);
  return q;
}

Qos reliable_stream(std::int32_t depth) {
  Qos q = make_qos();
  dds_qset_reliability(q.get(), DDS_RELIABILITY_RELIABLE, DDS_MSECS(100));
  dds_qset_durability(q.get(), DDS_DURABILITY_VOLATILE);
  dds_qset_history(q.get(), DDS_HISTORY_KEEP_LAST, depth);
  return q;
}

Qos command(double lifespan_s) {
  Qos q = make_qos();
  dds_qset_reliability(q.get(), DDS_RELIABILITY_RELIABLE, DDS_SECS(1));
  dds_qset_durability(q.get(), DDS_DURABILITY_TRANSIENT_LOCAL);
  dds_qset_history(q.get(), DDS_HISTORY_KEEP_ALL, 0);
  dds_qset_lifespan(q.get(), static_cast<dds_duration_t>(lifespan_s * 1e9));
  return q;
}

Qos recent(std::int32_t depth) {
  Qos q = make_qos();
  dds_qset_reliability(q.get(), DDS_RELIABILITY_RELIABLE, DDS_SECS(1));
  dds_qset_durability(q.get(), DDS_DURABILITY_TRANSIENT_LOCAL);
  dds_qset_history(q.get(), DDS_HISTORY_KEEP_LAST, depth);
  return q;
}

Qos heartbeat(double lease_s) {
  Qos q = state();
  // No auto-dispose: a writer that loses liveliness leaves its instance NOT_ALIVE_NO_WRITERS
  // (a dead service), distinct from the explicit dispose of a clean stop.
  dds_qset_writer_data_lifecycle(q.get(), false);
  dds_qset_liveliness(q.get(), DDS_LIVELINESS_MANUAL_BY_TOPIC,
                      static_cast<dds_duration_t>(lease_s * 1e9));
  return q;
}

}  // namespace qos

// ---------------------------------------------------------------------------------------------
Participant::Participant(std::uint32_t domain_id, std::string partition)
    : domain_id_(domain_id), partition_(std::move(partition)) {
  if (partition_.empty()) {
    throw BusError(DDS_RETCODE_BAD_PARAMETER, "create participant: empty partition name");
  }
  const char* uri = std::getenv("CYCLONEDDS_URI");
  const bool secured = uri != nullptr && std::string_view(uri).find(",file:") != std::string_view::npos;
  participant_ = Entity(check_created(
      dds_create_participant(domain_id, nullptr, nullptr),
      fmt::format("create participant on domain {}{}", domain_id,
                  secured ? " (with DDS Security: check the certificate, key and signed "
                            "documents named in CYCLONEDDS_URI; Cyclone says why on stderr)"
                          : "")));
  Qos q = make_qos();
  dds_qset_partition1(q.get(), partition_.c_str());
  publisher_ = Entity(check_created(dds_create_publisher(participant_.get(), q.get(), nullptr),
                                    "create publisher '" + partition_ + "'"));
  subscriber_ = Entity(check_created(dds_create_subscriber(participant_.get(), q.get(), nullptr),
                                     "create subscriber '" + partition_ + "'"));
}

// ---------------------------------------------------------------------------------------------
GuardCondition::GuardCondition(const Participant& participant)
    : entity_(check_created(dds_create_guardcondition(participant.get()),
                            "create guard condition")) {}

void GuardCondition::trigger() const noexcept { dds_set_guardcondition(entity_.get(), true); }
void GuardCondition::reset() const noexcept { dds_set_guardcondition(entity_.get(), false); }
bool GuardCondition::triggered() const noexcept {
  bool value = false;
  dds_read_guardcondition(entity_.get(), &value);
  return value;
}

bool Fired::contains(dds_attach_t token) const noexcept {
  for (std::size_t i = 0; i < count_; ++i) {
    if (tokens_[i] == token) {
      return true;
    }
  }
  return false;
}

void Fired::add(dds_attach_t token) noexcept {
  if (count_ < tokens_.size()) {
    tokens_[count_++] = token;
  }
}

WaitSet::WaitSet(const Participant& participant)
    : entity_(check_created(dds_create_waitset(participant.get()), "create waitset")) {}

void WaitSet::attach(dds_entity_t entity, dds_attach_t token) {
  const dds_return_t rc = dds_waitset_attach(entity_.get(), entity, token);
  if (rc != DDS_RETCODE_OK) {
    throw BusError(rc, "waitset attach");
  }
}

void WaitSet::detach(dds_entity_t entity) noexcept { dds_waitset_detach(entity_.get(), entity); }

Fired WaitSet::wait(std::chrono::nanoseconds timeout) const {
  std::array<dds_attach_t, 16> xs{};
  Fired fired;
  const dds_return_t n = dds_waitset_wait(entity_.get(), xs.data(), xs.size(),
                                          std::max<dds_duration_t>(0, timeout.count()));
  for (dds_return_t i = 0; i < n && i < static_cast<dds_return_t>(xs.size()); ++i) {
    fired.add(xs[i]);
  }
  return fired;
}

Fired WaitSet::wait_until(std::chrono::steady_clock::time_point deadline) const {
  return wait(deadline - std::chrono::steady_clock::now());
}

// ---------------------------------------------------------------------------------------------
namespace detail {

Error write_error(dds_return_t rc, const std::string& topic, const char* op) {
  return Error{Errc::kBus, fmt::format("{} on '{}': {}", op, topic, dds_strretcode(rc))};
}

Error read_error(dds_return_t rc, const std::string& topic, const char* op) {
  return write_error(rc, topic, op);
}

std::uint32_t matched_readers(dds_entity_t writer) noexcept {
  dds_publication_matched_status_t status{};
  if (dds_get_publication_matched_status(writer, &status) != DDS_RETCODE_OK) {
    return 0;
  }
  return status.current_count;
}

std::uint32_t matched_writers(dds_entity_t reader) noexcept {
  dds_subscription_matched_status_t status{};
  if (dds_get_subscription_matched_status(reader, &status) != DDS_RETCODE_OK) {
    return 0;
  }
  return status.current_count;
}

bool wait_matched(dds_entity_t participant, dds_entity_t entity, std::uint32_t status,
                  std::uint32_t count, std::chrono::milliseconds timeout,
                  std::uint32_t (*matched)(dds_entity_t) noexcept) {
  if (matched(entity) >= count) {
    return true;
  }
  const auto deadline = std::chrono::steady_clock::now() + timeout;
  Entity waitset(dds_create_waitset(participant));
  if (!waitset) {
    return false;
  }
  std::uint32_t old_mask = 0;
  dds_get_status_mask(entity, &old_mask);
  dds_set_status_mask(entity, old_mask | status);
  dds_waitset_attach(waitset.get(), entity, 0);
  bool ok = false;
  for (;;) {
    if (matched(entity) >= count) {
      ok = true;
      break;
    }
    const auto left = deadline - std::chrono::steady_clock::now();
    if (left <= std::chrono::nanoseconds::zero()) {
      break;
    }
    dds_waitset_wait(waitset.get(), nullptr, 0,
                     std::chrono::duration_cast<std::chrono::nanoseconds>(left).count());
    std::uint32_t triggered = 0;
    dds_take_status(entity, &triggered, status);  // clear so the next wait blocks
  }
  dds_waitset_detach(waitset.get(), entity);
  dds_set_status_mask(entity, old_mask);
  return ok;
}

bool wait_readable(dds_entity_t participant, dds_entity_t condition,
                   std::chrono::steady_clock::time_point deadline) {
  Entity waitset(dds_create_waitset(participant));
  if (!waitset) {
    return false;
  }
  dds_waitset_attach(waitset.get(), condition, 0);
  const auto left = std::max(std::chrono::nanoseconds::zero(),
                             std::chrono::duration_cast<std::chrono::nanoseconds>(
                                 deadline - std::chrono::steady_clock::now()));
  const dds_return_t n = dds_waitset_wait(waitset.get(), nullptr, 0, left.count());
  dds_waitset_detach(waitset.get(), condition);
  return n > 0;
}

}  // namespace detail

std::string make_client_id(std::string_view name) {
  // Unique per call, not just per process: replies live on transient-local topics, so a second
  // requester in the same process (or a later process that got the same pid) must never take
  // an earlier requester's reply for its own.
  static std::atomic<std::uint32_t> counter{0};
  static const std::uint32_t nonce = std::random_device{}();
  char host[256] = {};
  gethostname(host, sizeof host - 1);
  return fmt::format("{}@{}:{}.{}.{:08x}", name, host, getpid(), counter.fetch_add(1), nonce);
}

}  // namespace cell::bus
