#pragma once

#include <chrono>
#include <cstdint>
#include <string>

#include "cell/bus/entity.hpp"
#include "cell/bus/participant.hpp"
#include "cell/bus/topic.hpp"
#include "cell/bus/waitset.hpp"
#include "cell/common/result.hpp"

namespace cell::bus {

namespace detail {
Error write_error(dds_return_t rc, const std::string& topic, const char* op);
std::uint32_t matched_readers(dds_entity_t writer) noexcept;
bool wait_matched(dds_entity_t participant, dds_entity_t entity, std::uint32_t status,
                  std::uint32_t count, std::chrono::milliseconds timeout,
                  std::uint32_t (*matched)(dds_entity_t) noexcept);
}  // namespace detail

/// A typed DataWriter in the participant's partition. Writes never throw: failures come
/// back as kBus errors. Thread-safe (Cyclone serialises writes on one writer).
template <IdlType T>
class Writer {
 public:
  /// With the topic's own QoS profile.
  Writer(const Participant& participant, const Topic<T>& topic, const TopicDef<T>& def)
      : Writer(participant, topic, make_qos(def).get()) {}

  /// With an explicit QoS (nullptr: Cyclone defaults).
  Writer(const Participant& participant, const Topic<T>& topic, const dds_qos_t* qos)
      : participant_(participant.get()),
        topic_name_(topic.name()),
        entity_(check_created(dds_create_writer(participant.publisher(), topic.get(), qos,
                                                nullptr),
                              "create writer '" + topic.name() + "'")) {}

  /// Publishes `sample` (serialised before returning: borrowed pointers may go away after).
  Status write(const T& sample) const {
    const dds_return_t rc = dds_write(entity_.get(), &sample);
    if (rc != DDS_RETCODE_OK) {
      return detail::write_error(rc, topic_name_, "write");
    }
    return ok_status();
  }

  /// Disposes the instance whose key fields `sample` carries (readers see NOT_ALIVE_DISPOSED).
  Status dispose(const T& sample) const {
    const dds_return_t rc = dds_dispose(entity_.get(), &sample);
    return rc == DDS_RETCODE_OK ? ok_status() : Status(detail::write_error(rc, topic_name_,
                                                                          "dispose"));
  }

  /// Unregisters the instance (readers see NOT_ALIVE_NO_WRITERS once no writer remains).
  Status unregister(const T& sample) const {
    const dds_return_t rc = dds_unregister_instance(entity_.get(), &sample);
    return rc == DDS_RETCODE_OK ? ok_status()
                                : Status(detail::write_error(rc, topic_name_, "unregister"));
  }

  /// Asserts liveliness (MANUAL_BY_TOPIC writers; every write also asserts it).
  Status assert_liveliness() const {
    const dds_return_t rc = dds_assert_liveliness(entity_.get());
    return rc == DDS_RETCODE_OK ? ok_status()
                                : Status(detail::write_error(rc, topic_name_, "liveliness"));
  }

  /// Number of readers currently matched.
  std::uint32_t matched_readers() const noexcept { return detail::matched_readers(entity_.get()); }

  /// Blocks until at least `count` readers matched or `timeout` passed; returns whether they did.
  bool wait_for_readers(std::uint32_t count, std::chrono::milliseconds timeout) const {
    return detail::wait_matched(participant_, entity_.get(), DDS_PUBLICATION_MATCHED_STATUS,
                                count, timeout, &detail::matched_readers);
  }

  dds_entity_t get() const noexcept { return entity_.get(); }
  const std::string& topic_name() const noexcept { return topic_name_; }

 private:
  dds_entity_t participant_;
  std::string topic_name_;
  Entity entity_;
};

}  // namespace cell::bus
