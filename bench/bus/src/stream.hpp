#pragma once

#include <chrono>
#include <cstdint>
#include <string>
#include <string_view>
#include <vector>

#include "cell/bus/participant.hpp"
#include "cell/bus/topics.hpp"
#include "cell/common/result.hpp"
#include "stats.hpp"

/// A 1 kHz cell_robot_RobotState stream between two processes, as the gateway publishes it:
/// delivery (sent, received, lost by header.seq), latency (header.stamp_ns, wall clock, same
/// host) and the publisher's period jitter.
namespace cell::bench {

/// The reliable variant of the robot state topic: same name and type as
/// bus::topics::kRobotState, QoS reliable_stream (RELIABLE, KEEP_LAST 64).
inline constexpr bus::TopicDef<cell_robot_RobotState> kRobotStateReliable{
    "cell/robot/state", bus::QosProfile::kReliableStream, 64};

/// Which QoS profile the stream uses.
enum class StreamProfile : std::uint8_t {
  kStream,          ///< bus::topics::kRobotState: BEST_EFFORT, KEEP_LAST 16
  kReliableStream,  ///< kRobotStateReliable: RELIABLE, KEEP_LAST 64
};

/// "stream" or "reliable_stream".
std::string_view to_string(StreamProfile profile) noexcept;

/// Parses "stream" / "reliable_stream". Errors: kInvalidArgument naming the text.
Result<StreamProfile> parse_stream_profile(std::string_view text);

/// The stream to run.
struct StreamOptions {
  StreamProfile profile = StreamProfile::kStream;
  double duration_s = 10.0;               ///< publishing time, after matching and settling
  double rate_hz = 1000.0;                ///< publishing rate
  std::uint32_t joints = 6;               ///< length of each joint sequence
  std::chrono::milliseconds settle{500};  ///< after the writer matched, before sample 1
  int rt_priority = 0;  ///< >0: the publisher's pacing thread runs SCHED_FIFO at this priority
};

/// What the publisher measured (printed by the `--role stream-pub` process as one line
/// "BUS_BENCH_STREAM_PUB {json}").
struct StreamPublisherReport {
  std::uint64_t sent = 0;          ///< samples written successfully (seq 1..sent)
  std::uint64_t write_errors = 0;  ///< writes that failed
  std::uint64_t overruns = 0;      ///< wake-ups later than one full period
  Summary period_jitter;           ///< |actual period - nominal| between consecutive wake-ups
  Summary write;                   ///< time spent in Writer::write
};

/// The whole stream measurement.
struct StreamResult {
  StreamProfile profile = StreamProfile::kStream;
  double duration_s = 0.0;
  double rate_hz = 0.0;
  StreamPublisherReport publisher;
  std::uint64_t received = 0;      ///< valid samples taken (duplicates included)
  std::uint64_t lost = 0;          ///< seqs in 1..sent never received
  std::uint64_t first_lost = 0;    ///< the lowest of them (0: none), to tell start-up from
                                   ///< mid-stream loss
  std::uint64_t gaps = 0;          ///< places where seq jumped forward by more than 1
  std::uint64_t duplicates = 0;    ///< seqs received more than once
  std::uint64_t out_of_order = 0;  ///< seqs lower than one received before
  Summary latency;                 ///< receive wall clock - header.stamp_ns
};

/// Fills out.lost, first_lost, gaps, duplicates and out_of_order from the header.seq values
/// received (in arrival order) from a publisher that sent 1..sent. Seqs outside 1..sent count as
/// gaps or reordering only.
void count_delivery(const std::vector<std::uint64_t>& seqs, std::uint64_t sent, StreamResult& out);

/// Formats / parses the publisher's report line. Parsing errors: kProtocol naming the text.
std::string format_publisher_report(const StreamPublisherReport& report);
Result<StreamPublisherReport> parse_publisher_report(std::string_view output);

/// Subscriber side (this process): creates the reader (profile's QoS) and a WaitSet, starts
/// `self_exe --role stream-pub`, takes every sample with a loan until the publisher exits,
/// then drains and reads the publisher's report. Errors: kIo (publisher not started),
/// kTimeout (no match, or the publisher did not finish in duration + 30 s), kProtocol
/// (publisher failed or its report is unreadable), kBus (take failed).
Result<StreamResult> run_stream_subscriber(const bus::Participant& participant,
                                           const std::string& self_exe,
                                           const StreamOptions& options);

/// Publisher side (the `--role stream-pub` process): waits for the reader, settles, then
/// writes duration * rate samples paced by clock_nanosleep(CLOCK_MONOTONIC, TIMER_ABSTIME),
/// each with header.seq = 1, 2, ... and header.stamp_ns = wall clock just before the write;
/// with the reliable profile waits for acknowledgements. Returns its report.
/// Errors: kTimeout when no reader matched within 10 s; kInvalidArgument when rt_priority is
/// set and SCHED_FIFO is refused (needs CAP_SYS_NICE or an rtprio limit).
Result<StreamPublisherReport> run_stream_publisher(const bus::Participant& participant,
                                                   const StreamOptions& options);

}  // namespace cell::bench
