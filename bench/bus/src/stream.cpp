#include "stream.hpp"

#include <sched.h>

#include <algorithm>
#include <cerrno>
#include <cmath>
#include <cstring>
#include <ctime>
#include <optional>
#include <string>
#include <thread>
#include <utility>
#include <vector>

#include <fmt/format.h>
#include <nlohmann/json.hpp>

#include "cell/bus/reader.hpp"
#include "cell/bus/topic.hpp"
#include "cell/bus/view.hpp"
#include "cell/bus/waitset.hpp"
#include "cell/bus/writer.hpp"
#include "cell/common/time.hpp"
#include "cell/process/child.hpp"
#include "report.hpp"

namespace cell::bench {
namespace {

using std::chrono::milliseconds;

constexpr std::string_view kReportTag = "BUS_BENCH_STREAM_PUB ";

const bus::TopicDef<cell_robot_RobotState>& topic_def(StreamProfile profile) {
  return profile == StreamProfile::kStream ? bus::topics::kRobotState : kRobotStateReliable;
}

std::int64_t to_ns(const timespec& ts) {
  return static_cast<std::int64_t>(ts.tv_sec) * 1'000'000'000 + ts.tv_nsec;
}

timespec from_ns(std::int64_t ns) {
  timespec ts{};
  ts.tv_sec = static_cast<time_t>(ns / 1'000'000'000);
  ts.tv_nsec = static_cast<long>(ns % 1'000'000'000);
  return ts;
}

}  // namespace

void count_delivery(const std::vector<std::uint64_t>& seqs, std::uint64_t sent, StreamResult& out) {
  std::vector<std::uint8_t> seen(sent + 1, 0);
  std::uint64_t highest = 0;
  for (const std::uint64_t seq : seqs) {
    if (seq < highest) {
      ++out.out_of_order;
    } else if (seq > highest + 1) {
      ++out.gaps;
    }
    highest = std::max(highest, seq);
    if (seq >= 1 && seq <= sent) {
      if (seen[seq] != 0) {
        ++out.duplicates;
      }
      seen[seq] = 1;
    }
  }
  if (sent > highest) {
    ++out.gaps;  // the tail never came
  }
  const auto unique = static_cast<std::uint64_t>(std::count(seen.begin(), seen.end(), 1));
  out.lost = sent - unique;
  const auto missing = std::find(seen.begin() + 1, seen.end(), 0);
  out.first_lost = missing == seen.end() ? 0 : static_cast<std::uint64_t>(missing - seen.begin());
}

std::string_view to_string(StreamProfile profile) noexcept {
  return profile == StreamProfile::kStream ? "stream" : "reliable_stream";
}

Result<StreamProfile> parse_stream_profile(std::string_view text) {
  if (text == "stream") {
    return StreamProfile::kStream;
  }
  if (text == "reliable_stream") {
    return StreamProfile::kReliableStream;
  }
  return Error{
      Errc::kInvalidArgument,
      fmt::format("unknown stream profile '{}' (expected stream or reliable_stream)", text)};
}

std::string format_publisher_report(const StreamPublisherReport& report) {
  const nlohmann::json j = {{"sent", report.sent},
                            {"write_errors", report.write_errors},
                            {"overruns", report.overruns},
                            {"period_jitter", report.period_jitter},
                            {"write", report.write}};
  return std::string(kReportTag) + j.dump();
}

Result<StreamPublisherReport> parse_publisher_report(std::string_view output) {
  const std::size_t at = output.rfind(kReportTag);
  if (at == std::string_view::npos) {
    return Error{Errc::kProtocol,
                 fmt::format("no '{}' line in the publisher's output:\n{}", kReportTag, output)};
  }
  const std::size_t begin = at + kReportTag.size();
  const std::size_t end = output.find('\n', begin);
  const std::string_view text =
      output.substr(begin, end == std::string_view::npos ? std::string_view::npos : end - begin);
  try {
    const nlohmann::json j = nlohmann::json::parse(text);
    StreamPublisherReport report;
    report.sent = j.at("sent").get<std::uint64_t>();
    report.write_errors = j.at("write_errors").get<std::uint64_t>();
    report.overruns = j.at("overruns").get<std::uint64_t>();
    report.period_jitter = j.at("period_jitter").get<Summary>();
    report.write = j.at("write").get<Summary>();
    return report;
  } catch (const nlohmann::json::exception& e) {
    return Error{Errc::kProtocol,
                 fmt::format("unreadable publisher report '{}': {}", text, e.what())};
  }
}

Result<StreamPublisherReport> run_stream_publisher(const bus::Participant& participant,
                                                   const StreamOptions& options) {
  const auto& def = topic_def(options.profile);
  bus::Topic<cell_robot_RobotState> topic(participant, def);
  bus::Writer<cell_robot_RobotState> writer(participant, topic, def);
  if (!writer.wait_for_readers(1, milliseconds(10000))) {
    return Error{Errc::kTimeout, fmt::format("no reader of '{}' ({}) within 10 s", def.name,
                                             to_string(options.profile))};
  }
  // Matching is asymmetric: give the reader time to match us too, so sample 1 is not dropped
  // by a reader that does not know this writer yet (a one-time wait, not a poll).
  std::this_thread::sleep_for(options.settle);
  if (options.rt_priority > 0) {  // the pacing thread only; Cyclone's threads stay as they are
    sched_param param{};
    param.sched_priority = options.rt_priority;
    if (sched_setscheduler(0, SCHED_FIFO, &param) != 0) {
      return Error{Errc::kInvalidArgument, fmt::format("SCHED_FIFO priority {} refused: {}",
                                                       options.rt_priority, std::strerror(errno))};
    }
  }

  // A realistic sample: 6 joints, every sequence and string filled.
  const std::string robot_id = "ibm7545";
  const std::string frame_id = "ibm7545/base";
  const std::string fault_text = "none";
  const std::string trajectory_id = "bench-trajectory-000001";
  std::vector<double> position(options.joints, 0.0);
  std::vector<double> velocity(options.joints, 0.0);
  std::vector<double> setpoint(options.joints, 0.0);
  std::vector<double> effort(options.joints, 0.0);
  cell_robot_RobotState state{};
  state.robot_id = bus::borrow(robot_id);
  state.header.frame_id = bus::borrow(frame_id);
  state.fault_text = bus::borrow(fault_text);
  state.trajectory_id = bus::borrow(trajectory_id);
  bus::borrow(state.position_rad_or_mm, position);
  bus::borrow(state.velocity_rad_or_mm_per_s, velocity);
  bus::borrow(state.setpoint_rad_or_mm, setpoint);
  bus::borrow(state.effort_raw, effort);
  state.base_T_tool.orientation.w = 1.0;
  state.gripper = cell_robot_GRIPPER_CLOSED;
  state.mode = cell_robot_MODE_MOVING;
  state.homed = true;
  state.moving = true;

  const auto count = static_cast<std::uint64_t>(std::llround(options.duration_s * options.rate_hz));
  const auto period_ns = static_cast<std::int64_t>(std::llround(1e9 / options.rate_hz));
  std::vector<std::int64_t> wake_ns;
  std::vector<std::int64_t> write_ns;
  wake_ns.reserve(count);
  write_ns.reserve(count);
  StreamPublisherReport report;

  std::int64_t target_ns = monotonic_ns() + period_ns;
  for (std::uint64_t i = 1; i <= count; ++i) {
    const timespec target = from_ns(target_ns);
    while (clock_nanosleep(CLOCK_MONOTONIC, TIMER_ABSTIME, &target, nullptr) == EINTR) {
    }
    timespec woke{};
    clock_gettime(CLOCK_MONOTONIC, &woke);
    const std::int64_t woke_ns = to_ns(woke);
    wake_ns.push_back(woke_ns);
    if (woke_ns - target_ns > period_ns) {
      ++report.overruns;
    }
    const double t_s = static_cast<double>(i) / options.rate_hz;
    for (std::uint32_t j = 0; j < options.joints; ++j) {
      const double phase = 0.5 * static_cast<double>(j);
      position[j] = 0.8 * std::sin(t_s + phase);
      velocity[j] = 0.8 * std::cos(t_s + phase);
      setpoint[j] = position[j] + 1e-4;
      effort[j] = 1000.0 * (setpoint[j] - position[j]);
    }
    state.base_T_tool.position_mm.x = 400.0 + 100.0 * position[0];
    state.trajectory_progress = static_cast<double>(i) / static_cast<double>(count);
    state.cycle_count = i;
    state.header.seq = i;
    state.header.stamp_ns = wall_time_ns();
    const std::int64_t before = monotonic_ns();
    if (writer.write(state)) {
      ++report.sent;
    } else {
      ++report.write_errors;
    }
    write_ns.push_back(monotonic_ns() - before);
    target_ns += period_ns;
  }
  if (options.profile == StreamProfile::kReliableStream) {
    dds_wait_for_acks(writer.get(), DDS_SECS(5));
  }
  std::vector<std::int64_t> jitter_ns;
  jitter_ns.reserve(wake_ns.size());
  for (std::size_t i = 1; i < wake_ns.size(); ++i) {
    jitter_ns.push_back(std::llabs(wake_ns[i] - wake_ns[i - 1] - period_ns));
  }
  report.period_jitter = summarize(jitter_ns);
  report.write = summarize(write_ns);
  return report;
}

Result<StreamResult> run_stream_subscriber(const bus::Participant& participant,
                                           const std::string& self_exe,
                                           const StreamOptions& options) {
  const auto& def = topic_def(options.profile);
  bus::Topic<cell_robot_RobotState> topic(participant, def);
  bus::Reader<cell_robot_RobotState> reader(participant, topic, def);
  bus::WaitSet waitset(participant);
  waitset.attach(reader.condition(), 1);

  process::SpawnOptions spawn;
  spawn.executable = self_exe;
  spawn.args = {"--role",        "stream-pub",
                "--profile",     std::string(to_string(options.profile)),
                "--duration",    fmt::format("{:g}", options.duration_s),
                "--rate-hz",     fmt::format("{:g}", options.rate_hz),
                "--domain",      std::to_string(participant.domain_id()),
                "--partition",   participant.partition(),
                "--rt-priority", std::to_string(options.rt_priority)};
  auto publisher = process::Child::spawn(spawn);
  if (!publisher) {
    return with_context(std::move(publisher).error(), "starting the stream publisher");
  }
  const auto fail = [&](Errc code, const std::string& what) {
    publisher->stop(milliseconds(2000));
    return Error{code, what + "; publisher output:\n" + publisher->output()};
  };
  if (!reader.wait_for_writers(1, milliseconds(10000))) {
    return fail(Errc::kTimeout, "stream publisher did not match within 10 s");
  }

  const auto expected = static_cast<std::size_t>(options.duration_s * options.rate_hz) + 16;
  std::vector<std::int64_t> latency_ns;
  std::vector<std::uint64_t> seqs;
  latency_ns.reserve(expected);
  seqs.reserve(expected);
  const auto on_sample = [&](const cell_robot_RobotState& sample, const dds_sample_info_t&) {
    latency_ns.push_back(wall_time_ns() - sample.header.stamp_ns);
    seqs.push_back(sample.header.seq);
  };
  const auto deadline =
      SteadyClock::now() + milliseconds(static_cast<long>(options.duration_s * 1000.0) + 30000);
  std::optional<process::ExitInfo> exit;
  for (;;) {
    const bus::Fired fired = waitset.wait(milliseconds(100));
    if (auto taken = reader.take_each(on_sample); !taken) {
      return fail(taken.error().code, taken.error().message);
    }
    if (fired.empty()) {                                    // quiet: has the publisher finished?
      if ((exit = publisher->wait_for(milliseconds(0)))) {  // also collects its output
        break;
      }
    }
    if (SteadyClock::now() > deadline) {
      return fail(Errc::kTimeout, "stream publisher did not finish in time");
    }
  }
  // Publisher gone: take whatever is still queued.
  while (!waitset.wait(milliseconds(100)).empty()) {
    if (auto taken = reader.take_each(on_sample); !taken) {
      return std::move(taken).error();
    }
  }
  publisher->wait_for(milliseconds(1000));  // collects the rest of its output
  if (!exit->exited || exit->code != 0) {
    return Error{Errc::kProtocol, "stream publisher ended with " + exit->describe() +
                                      "; output:\n" + publisher->output()};
  }
  auto report = parse_publisher_report(publisher->output());
  if (!report) {
    return std::move(report).error();
  }
  StreamResult result;
  result.profile = options.profile;
  result.duration_s = options.duration_s;
  result.rate_hz = options.rate_hz;
  result.publisher = *report;
  result.received = seqs.size();
  count_delivery(seqs, report->sent, result);
  result.latency = summarize(latency_ns);
  return result;
}

}  // namespace cell::bench
