#pragma once

#include <chrono>
#include <cstddef>
#include <cstdint>
#include <string>
#include <string_view>
#include <vector>

#include "cell/bus/participant.hpp"
#include "cell/bus/topics.hpp"
#include "cell/common/result.hpp"

/// Ping-pong round trip between two processes through the cell's typed bus wrapper
/// (cell::bus Writer/Reader/WaitSet), for a small and a sized message.
namespace cell::bench {

/// The ping-pong topics with their default QoS: reliable, volatile, keep-all
/// (QosProfile::kCommand), the profile of the cell's requests and replies. The pong side writes
/// every ping back on the pong topic. PingQos::kKeepLast1 swaps the profile (ping_pong_def).
inline constexpr bus::TopicDef<cell_bench_Small> kPingSmall{"cell/bench/ping",
                                                            bus::QosProfile::kCommand};
inline constexpr bus::TopicDef<cell_bench_Small> kPongSmall{"cell/bench/pong",
                                                            bus::QosProfile::kCommand};
inline constexpr bus::TopicDef<cell_bench_Blob> kPingBlob{"cell/bench/ping_blob",
                                                          bus::QosProfile::kCommand};
inline constexpr bus::TopicDef<cell_bench_Blob> kPongBlob{"cell/bench/pong_blob",
                                                          bus::QosProfile::kCommand};

/// Serialised size of a cell_bench_Small's fields: seq + sent_ns, 8 bytes each.
inline constexpr std::uint32_t kSmallWireBytes = 16;

/// Serialised size of a cell_bench_Blob's fields with `payload` octets: seq (8) + sent_ns (8)
/// + sequence length (4) + payload (XCDR2 adds a 4-byte header for the @appendable type).
constexpr std::uint32_t blob_wire_bytes(std::uint32_t payload) { return 20 + payload; }

/// QoS of the four ping-pong topics.
enum class PingQos : std::uint8_t {
  kCommand,    ///< QosProfile::kCommand: RELIABLE, KEEP_ALL (the cell's request/reply profile)
  kKeepLast1,  ///< QosProfile::kReliableStream depth 1: RELIABLE, KEEP_LAST 1 (ddsperf's
               ///< ping/pong QoS)
};

/// "command" / "keep_last1".
std::string_view to_string(PingQos qos) noexcept;

/// Parses "command" / "keep_last1". Errors: kInvalidArgument naming the text.
Result<PingQos> parse_ping_qos(std::string_view text);

/// `def` (one of the four topics above) with the profile of `qos`.
template <bus::IdlType T>
constexpr bus::TopicDef<T> ping_pong_def(const bus::TopicDef<T>& def, PingQos qos) {
  return qos == PingQos::kCommand ? def
                                  : bus::TopicDef<T>{def.name, bus::QosProfile::kReliableStream, 1};
}

/// How the ping side waits for a reply (a diagnostic of the wrapper's cost).
enum class PingWait : std::uint8_t {
  kWaitSet,      ///< one bus::WaitSet created up front (what services should do)
  kWaitForData,  ///< Reader::wait_for_data, which creates and deletes a waitset per call
};

/// How the ping side takes a reply (a diagnostic of the wrapper's cost).
enum class PingTake : std::uint8_t {
  kLoan,  ///< Reader::take_each: Cyclone's buffers, no copy
  kCopy,  ///< Reader::take_copies: deserialised into Owned<T>
};

/// What to measure.
struct PingPongOptions {
  std::size_t warmup = 1000;        ///< unmeasured round trips per size, after matching
  std::size_t count_small = 20000;  ///< measured round trips of cell_bench_Small
  std::size_t count_blob = 10000;   ///< measured round trips of cell_bench_Blob
  std::uint32_t blob_bytes = 4096;  ///< payload octets of the blob
  std::chrono::milliseconds match_timeout{10000};  ///< for the pong process to match
  std::chrono::milliseconds reply_timeout{2000};   ///< a longer round trip is an error
  int pong_cpu = -1;                   ///< CPU of the pong process (affinity.hpp); -1: not pinned
  PingWait wait = PingWait::kWaitSet;  ///< ping side only; the pong always uses a WaitSet
  PingTake take = PingTake::kLoan;     ///< ping side only; the pong always takes loans
  PingQos qos = PingQos::kCommand;     ///< both sides
};

/// Measured round trips, nanoseconds (CLOCK_MONOTONIC from before write to after take).
struct PingPongResult {
  std::vector<std::int64_t> small_ns;
  std::vector<std::int64_t> blob_ns;
};

/// Ping side. Creates the ping writers and pong readers on `participant`, starts
/// `self_exe --role pong` on the same domain and partition, waits for all four endpoints to
/// match, then for each size warms up and measures round trips one at a time: stamp, write,
/// wait for the reply (WaitSet by default), take it (a loan by default), stamp.
/// Finally deletes its endpoints and expects the pong process to exit 0.
/// Errors: kIo (pong not started), kTimeout (no match or a reply missing), kBus (a write or
/// take failed), kProtocol (a wrong reply or the pong process failed); each message carries
/// the pong's output where it helps.
Result<PingPongResult> run_ping(const bus::Participant& participant,
                                const std::string& self_exe,
                                const PingPongOptions& options);

/// Pong side (the `--role pong` process): waits on one WaitSet for both ping topics, takes
/// every ping with a loan and writes it back unchanged. Returns Ok once the ping writers that
/// had matched are gone. Errors: kTimeout when no ping writer matched within `idle_limit`,
/// kBus when a take or write fails.
Status run_pong(const bus::Participant& participant,
                PingQos qos,
                std::chrono::milliseconds idle_limit);

}  // namespace cell::bench
