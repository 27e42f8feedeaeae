#include "pingpong.hpp"

#include <optional>
#include <utility>

#include <fmt/format.h>

#include "affinity.hpp"
#include "cell/bus/reader.hpp"
#include "cell/bus/topic.hpp"
#include "cell/bus/view.hpp"
#include "cell/bus/waitset.hpp"
#include "cell/bus/writer.hpp"
#include "cell/common/time.hpp"
#include "cell/process/child.hpp"

namespace cell::bench {
namespace {

using std::chrono::milliseconds;

// Ping side: writer of pings, reader of pongs and the WaitSet the reader's read condition is
// attached to, for one message type. Members in creation order (children destroyed first).
template <bus::IdlType T>
struct PingEndpoints {
  PingEndpoints(const bus::Participant& participant,
                const bus::TopicDef<T>& ping_def,
                const bus::TopicDef<T>& pong_def)
      : ping_topic(participant, ping_def),
        pong_topic(participant, pong_def),
        writer(participant, ping_topic, ping_def),
        reader(participant, pong_topic, pong_def),
        waitset(participant) {
    waitset.attach(reader.condition(), 1);
  }

  bus::Topic<T> ping_topic;
  bus::Topic<T> pong_topic;
  bus::Writer<T> writer;
  bus::Reader<T> reader;
  bus::WaitSet waitset;
};

// One round trip: writes ping `seq` and waits up to `timeout` for the pong carrying the same
// seq (stale pongs are dropped). Returns the round trip in ns, or nullopt on timeout.
template <bus::IdlType T, typename Valid>
Result<std::optional<std::int64_t>> round_trip(PingEndpoints<T>& ep,
                                               T& sample,
                                               std::uint64_t seq,
                                               milliseconds timeout,
                                               const PingPongOptions& options,
                                               std::string_view what,
                                               Valid& valid) {
  const std::int64_t t0 = monotonic_ns();
  sample.seq = seq;
  sample.sent_ns = t0;
  if (auto written = ep.writer.write(sample); !written) {
    return std::move(written).error();
  }
  bool replied = false;
  bool malformed = false;
  const auto on_reply = [&](const T& reply) {
    if (reply.seq == seq) {
      replied = true;
      malformed = malformed || !valid(reply);
    }
  };
  while (!replied) {
    const bool readable = options.wait == PingWait::kWaitSet ? !ep.waitset.wait(timeout).empty()
                                                             : ep.reader.wait_for_data(timeout);
    if (!readable) {
      return std::optional<std::int64_t>();
    }
    if (options.take == PingTake::kLoan) {
      auto taken =
          ep.reader.take_each([&](const T& reply, const dds_sample_info_t&) { on_reply(reply); });
      if (!taken) {
        return std::move(taken).error();
      }
    } else {
      auto taken = ep.reader.take_copies();
      if (!taken) {
        return std::move(taken).error();
      }
      for (const bus::Owned<T>& reply : *taken) {
        on_reply(*reply);
      }
    }
  }
  const std::int64_t t1 = monotonic_ns();
  if (malformed) {
    return Error{Errc::kProtocol, fmt::format("{} pong #{} differs from its ping", what, seq)};
  }
  return std::optional<std::int64_t>(t1 - t0);
}

// One measured series: first contact, then `warmup` + `count` round trips, one outstanding at
// a time. `valid` checks a reply's content (the blob's payload length).
template <bus::IdlType T, typename Valid>
Result<std::vector<std::int64_t>> measure(PingEndpoints<T>& ep,
                                          T& sample,
                                          std::size_t warmup,
                                          std::size_t count,
                                          const PingPongOptions& options,
                                          std::string_view what,
                                          Valid&& valid) {
  // First contact: matching runs per direction, so the pong's writer may not have matched our
  // reader yet although our endpoints see theirs, and a pong written before that is lost
  // (volatile). Ping every 100 ms until one comes back.
  std::uint64_t seq = 0;
  const auto contact_deadline = SteadyClock::now() + options.match_timeout;
  for (;;) {
    auto first = round_trip(ep, sample, ++seq, milliseconds(100), options, what, valid);
    if (!first) {
      return std::move(first).error();
    }
    if (first->has_value()) {
      break;
    }
    if (SteadyClock::now() > contact_deadline) {
      return Error{Errc::kTimeout, fmt::format("no {} pong within {} ms of matching ({} pings)",
                                               what, options.match_timeout.count(), seq)};
    }
  }
  std::vector<std::int64_t> rtt_ns;
  rtt_ns.reserve(count);
  for (std::size_t i = 0; i < warmup + count; ++i) {
    auto rtt = round_trip(ep, sample, ++seq, options.reply_timeout, options, what, valid);
    if (!rtt) {
      return std::move(rtt).error();
    }
    if (!rtt->has_value()) {
      return Error{Errc::kTimeout, fmt::format("no {} pong for ping #{} within {} ms", what, seq,
                                               options.reply_timeout.count())};
    }
    if (i >= warmup) {
      rtt_ns.push_back(**rtt);
    }
  }
  return rtt_ns;
}

Error with_output(Error error, const process::Child& pong) {
  if (!pong.output().empty()) {
    error.message += "; pong process output:\n" + pong.output();
  }
  return error;
}

Result<PingPongResult> ping_with(const bus::Participant& participant,
                                 const PingPongOptions& options) {
  PingEndpoints<cell_bench_Small> small(participant, ping_pong_def(kPingSmall, options.qos),
                                        ping_pong_def(kPongSmall, options.qos));
  PingEndpoints<cell_bench_Blob> blob(participant, ping_pong_def(kPingBlob, options.qos),
                                      ping_pong_def(kPongBlob, options.qos));
  // Matching is per endpoint pair and asynchronous: wait for all four from our side.
  if (!small.writer.wait_for_readers(1, options.match_timeout) ||
      !small.reader.wait_for_writers(1, options.match_timeout) ||
      !blob.writer.wait_for_readers(1, options.match_timeout) ||
      !blob.reader.wait_for_writers(1, options.match_timeout)) {
    return Error{Errc::kTimeout, fmt::format("pong process did not match within {} ms",
                                             options.match_timeout.count())};
  }
  PingPongResult result;
  cell_bench_Small small_sample{};
  auto small_rtt = measure(small, small_sample, options.warmup, options.count_small, options,
                           "small", [](const cell_bench_Small&) { return true; });
  if (!small_rtt) {
    return std::move(small_rtt).error();
  }
  result.small_ns = std::move(*small_rtt);

  const std::vector<std::uint8_t> payload(options.blob_bytes, 0xA5);
  cell_bench_Blob blob_sample{};
  bus::borrow(blob_sample.payload, payload);
  auto blob_rtt = measure(
      blob, blob_sample, options.warmup, options.count_blob, options, "blob",
      [&](const cell_bench_Blob& reply) { return reply.payload._length == options.blob_bytes; });
  if (!blob_rtt) {
    return std::move(blob_rtt).error();
  }
  result.blob_ns = std::move(*blob_rtt);
  return result;
}

}  // namespace

std::string_view to_string(PingQos qos) noexcept {
  return qos == PingQos::kCommand ? "command" : "keep_last1";
}

Result<PingQos> parse_ping_qos(std::string_view text) {
  if (text == "command") {
    return PingQos::kCommand;
  }
  if (text == "keep_last1") {
    return PingQos::kKeepLast1;
  }
  return Error{Errc::kInvalidArgument,
               fmt::format("unknown ping-pong QoS '{}' (expected command or keep_last1)", text)};
}

Result<PingPongResult> run_ping(const bus::Participant& participant,
                                const std::string& self_exe,
                                const PingPongOptions& options) {
  process::SpawnOptions spawn;
  spawn.executable = self_exe;
  spawn.args = {"--role",      "pong",
                "--domain",    std::to_string(participant.domain_id()),
                "--partition", participant.partition(),
                "--qos",       std::string(to_string(options.qos))};
  auto pong = on_cpu(options.pong_cpu, [&] { return process::Child::spawn(spawn); });
  if (!pong) {
    return with_context(std::move(pong).error(), "starting the pong process");
  }
  auto result = ping_with(participant, options);  // endpoints deleted on return
  if (!result) {
    pong->stop(milliseconds(2000));
    return with_output(std::move(result).error(), *pong);
  }
  // The pong process leaves once our writers are gone.
  const auto exit = pong->wait_for(milliseconds(10000));
  if (!exit) {
    pong->stop(milliseconds(2000));
    return with_output(Error{Errc::kTimeout, "pong process did not exit after the ping ended"},
                       *pong);
  }
  if (!exit->exited || exit->code != 0) {
    return with_output(Error{Errc::kProtocol, "pong process ended with " + exit->describe()},
                       *pong);
  }
  return result;
}

Status run_pong(const bus::Participant& participant, PingQos qos, milliseconds idle_limit) {
  constexpr dds_attach_t kSmallToken = 1;
  constexpr dds_attach_t kBlobToken = 2;
  const auto ping_small_def = ping_pong_def(kPingSmall, qos);
  const auto pong_small_def = ping_pong_def(kPongSmall, qos);
  const auto ping_blob_def = ping_pong_def(kPingBlob, qos);
  const auto pong_blob_def = ping_pong_def(kPongBlob, qos);
  bus::Topic<cell_bench_Small> ping_small_topic(participant, ping_small_def);
  bus::Topic<cell_bench_Small> pong_small_topic(participant, pong_small_def);
  bus::Topic<cell_bench_Blob> ping_blob_topic(participant, ping_blob_def);
  bus::Topic<cell_bench_Blob> pong_blob_topic(participant, pong_blob_def);
  bus::Reader<cell_bench_Small> ping_small(participant, ping_small_topic, ping_small_def);
  bus::Writer<cell_bench_Small> pong_small(participant, pong_small_topic, pong_small_def);
  bus::Reader<cell_bench_Blob> ping_blob(participant, ping_blob_topic, ping_blob_def);
  bus::Writer<cell_bench_Blob> pong_blob(participant, pong_blob_topic, pong_blob_def);
  bus::WaitSet waitset(participant);
  waitset.attach(ping_small.condition(), kSmallToken);
  waitset.attach(ping_blob.condition(), kBlobToken);

  const auto idle_deadline = SteadyClock::now() + idle_limit;
  bool matched = false;
  Status failed = ok_status();
  // Writes the loaned sample straight back; remembers the first failure.
  const auto echo = [&failed](const auto& writer) {
    return [&failed, &writer](const auto& ping, const dds_sample_info_t&) {
      if (auto written = writer.write(ping); !written && failed) {
        failed = std::move(written);
      }
    };
  };
  for (;;) {
    const bus::Fired fired = waitset.wait(milliseconds(200));
    if (fired.contains(kSmallToken)) {
      if (auto taken = ping_small.take_each(echo(pong_small)); !taken) {
        return std::move(taken).error();
      }
    }
    if (fired.contains(kBlobToken)) {
      if (auto taken = ping_blob.take_each(echo(pong_blob)); !taken) {
        return std::move(taken).error();
      }
    }
    if (!failed) {
      return failed;
    }
    if (!fired.empty()) {
      matched = true;  // pings came: the ping side is here
    } else {           // idle: has the ping side come, or gone?
      const std::uint32_t writers = ping_small.matched_writers() + ping_blob.matched_writers();
      if (writers > 0) {
        matched = true;
      } else if (matched) {
        return ok_status();
      } else if (SteadyClock::now() > idle_deadline) {
        return Error{Errc::kTimeout,
                     fmt::format("no ping writer matched within {} ms", idle_limit.count())};
      }
    }
  }
}

}  // namespace cell::bench
