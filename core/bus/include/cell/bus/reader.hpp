#pragma once

#include <array>
#include <chrono>
#include <concepts>
#include <cstdint>
#include <string>
#include <vector>

#include "cell/bus/entity.hpp"
#include "cell/bus/participant.hpp"
#include "cell/bus/sample.hpp"
#include "cell/bus/topic.hpp"
#include "cell/bus/waitset.hpp"
#include "cell/common/result.hpp"

namespace cell::bus {

namespace detail {
Error read_error(dds_return_t rc, const std::string& topic, const char* op);
std::uint32_t matched_writers(dds_entity_t reader) noexcept;
bool wait_matched(dds_entity_t participant, dds_entity_t entity, std::uint32_t status,
                  std::uint32_t count, std::chrono::milliseconds timeout,
                  std::uint32_t (*matched)(dds_entity_t) noexcept);
bool wait_readable(dds_entity_t participant, dds_entity_t condition,
                   std::chrono::steady_clock::time_point deadline);
}  // namespace detail

/// A typed DataReader in the participant's partition.
///
/// Loan mode (take_each, read_each): fn sees Cyclone's own buffers; the loan is returned
/// before the call ends, however it ends; fn copies what it keeps. Copy mode (take_copies):
/// samples are deserialised into Owned<T> that the caller keeps.
/// Never throws after construction; failures come back as kBus errors. One thread at a time.
template <IdlType T>
class Reader {
 public:
  Reader(const Participant& participant, const Topic<T>& topic, const TopicDef<T>& def)
      : Reader(participant, topic, make_qos(def).get()) {}

  Reader(const Participant& participant, const Topic<T>& topic, const dds_qos_t* qos)
      : participant_(participant.get()),
        topic_name_(topic.name()),
        entity_(check_created(dds_create_reader(participant.subscriber(), topic.get(), qos,
                                                nullptr),
                              "create reader '" + topic.name() + "'")),
        condition_(check_created(dds_create_readcondition(entity_.get(), DDS_ANY_STATE),
                                 "create read condition '" + topic.name() + "'")) {}

  /// Takes every valid sample available now and calls fn(sample, info) on each.
  /// Invalid samples (dispose/unregister notifications) are taken and skipped.
  template <std::invocable<const T&, const dds_sample_info_t&> Fn>
  Result<std::size_t> take_each(Fn&& fn) {
    return process<kTakeBatch>(true, DDS_ANY_STATE, fn);
  }

  /// Reads (without removing) at most 64 samples whose states match `mask` (e.g.
  /// DDS_ALIVE_INSTANCE_STATE | DDS_ANY_SAMPLE_STATE | DDS_ANY_VIEW_STATE).
  template <std::invocable<const T&, const dds_sample_info_t&> Fn>
  Result<std::size_t> read_each(Fn&& fn, std::uint32_t mask = DDS_ANY_STATE) {
    return process<kReadBatch>(false, mask, fn);
  }

  /// Takes up to `max` valid samples as owned copies.
  Result<std::vector<Owned<T>>> take_copies(std::size_t max = 64) {
    std::vector<Owned<T>> owned(max);
    std::vector<void*> buf(max);
    std::vector<dds_sample_info_t> info(max);
    for (std::size_t i = 0; i < max; ++i) {
      buf[i] = &owned[i].get();
    }
    const dds_return_t n = dds_take(entity_.get(), buf.data(), info.data(), max,
                                    static_cast<std::uint32_t>(max));
    if (n < 0) {
      return detail::read_error(n, topic_name_, "take");
    }
    std::vector<Owned<T>> out;
    out.reserve(static_cast<std::size_t>(n));
    for (dds_return_t i = 0; i < n; ++i) {
      if (info[i].valid_data) {
        out.push_back(std::move(owned[i]));
      }
    }
    return out;
  }

  /// Blocks until data is available or `timeout` passes; returns whether data is there.
  bool wait_for_data(std::chrono::milliseconds timeout) const {
    return detail::wait_readable(participant_, condition_.get(),
                                 std::chrono::steady_clock::now() + timeout);
  }

  /// Number of writers currently matched.
  std::uint32_t matched_writers() const noexcept { return detail::matched_writers(entity_.get()); }

  /// Blocks until at least `count` writers matched or `timeout` passed.
  bool wait_for_writers(std::uint32_t count, std::chrono::milliseconds timeout) const {
    return detail::wait_matched(participant_, entity_.get(), DDS_SUBSCRIPTION_MATCHED_STATUS,
                                count, timeout, &detail::matched_writers);
  }

  /// The read condition (any sample state) to attach to a WaitSet.
  dds_entity_t condition() const noexcept { return condition_.get(); }
  dds_entity_t get() const noexcept { return entity_.get(); }
  const std::string& topic_name() const noexcept { return topic_name_; }

 private:
  // One loan size for every loan path: Cyclone 0.10.2 reuses a reader's cached loan and then
  // fills as many pointers as the largest loan ever taken on that reader, whatever size the
  // call passes, so mixing sizes on one reader overflows the smaller buffer.
  static constexpr std::uint32_t kTakeBatch = 64;  // a take loops until the reader is empty
  static constexpr std::uint32_t kReadBatch = 64;  // a read returns at most this many samples

  template <std::uint32_t kBatch, typename Fn>
  Result<std::size_t> process(bool take, std::uint32_t mask, Fn& fn) {
    std::size_t handled = 0;
    for (;;) {
      std::array<void*, kBatch> buf{};  // all null: Cyclone lends its buffers
      std::array<dds_sample_info_t, kBatch> info{};
      const dds_return_t n =
          take ? dds_take_mask(entity_.get(), buf.data(), info.data(), kBatch, kBatch, mask)
               : dds_read_mask(entity_.get(), buf.data(), info.data(), kBatch, kBatch, mask);
      if (n < 0) {
        return detail::read_error(n, topic_name_, take ? "take" : "read");
      }
      struct Loan {  // returned however we leave, exception included
        dds_entity_t reader;
        void** buf;
        dds_return_t n;
        ~Loan() {
          if (n > 0) {
            dds_return_loan(reader, buf, n);
          }
        }
      } loan{entity_.get(), buf.data(), n};
      for (dds_return_t i = 0; i < n; ++i) {
        if (info[i].valid_data) {
          fn(*static_cast<const T*>(buf[i]), info[i]);
          ++handled;
        }
      }
      // A read (not take) returns the same samples again: one batch is all it can give.
      if (!take || n < static_cast<dds_return_t>(kBatch)) {
        return handled;
      }
    }
  }

  dds_entity_t participant_;
  std::string topic_name_;
  Entity entity_;
  Entity condition_;
};

}  // namespace cell::bus
