// bus_bench: the cell's bus wrapper (core/bus) against Cyclone's ddsperf, plus a 1 kHz
// RobotState stream. See bench/README.md for what each part measures and why it is fair.
#include <unistd.h>

#include <cstdio>
#include <cstdlib>
#include <exception>
#include <filesystem>
#include <string>
#include <thread>
#include <utility>
#include <vector>

#include <CLI/CLI.hpp>
#include <fmt/format.h>

#include "affinity.hpp"
#include "cell/bus/entity.hpp"
#include "cell/bus/participant.hpp"
#include "cell/common/log.hpp"
#include "cell/process/child.hpp"
#include "ddsperf.hpp"
#include "pingpong.hpp"
#include "report.hpp"
#include "stats.hpp"
#include "stream.hpp"

#ifndef CELL_BENCH_DDS_URI
#define CELL_BENCH_DDS_URI ""
#endif

namespace {

using namespace cell;
using namespace cell::bench;
using std::chrono::milliseconds;

constexpr int kExitFailed = 1;  // a measurement broke
constexpr int kExitUsage = 2;   // bad command line
constexpr int kExitBus = 3;     // no participant

struct Options {
  bool quick = false;
  bool json = false;
  double duration_s = 10.0;
  std::size_t count = 0;  // 0: the defaults per size
  std::size_t warmup = 1000;
  double ddsperf_duration_s = 5.0;
  std::size_t repeat = 1;
  std::string domain;  // number, "auto", or empty: $CELL_DOMAIN_ID or 77
  std::string partition;
  std::string ddsperf = "ddsperf";
  bool no_ddsperf = false;
  bool no_pingpong = false;
  bool no_stream = false;
  double rate_hz = 1000.0;
  std::uint32_t blob_bytes = 4096;
  std::string role;  // internal: "pong" or "stream-pub"
  std::string profile = "stream";
  std::string placement = "same";
  std::string ping_wait = "waitset";
  std::string ping_take = "loan";
  std::string qos = "command";
  int rt_priority = 0;
};

Result<std::uint32_t> resolve_domain(const std::string& text) {
  std::string value = text;
  if (value.empty()) {
    const char* env = std::getenv("CELL_DOMAIN_ID");
    value = env != nullptr && *env != '\0' ? env : "77";
  }
  if (value == "auto") {  // away from the tests' 100 + pid % 100 and from the default 77
    return static_cast<std::uint32_t>(150 + getpid() % 80);
  }
  char* end = nullptr;
  const unsigned long id = std::strtoul(value.c_str(), &end, 10);
  if (end == value.c_str() || *end != '\0' || id > 232) {
    return Error{Errc::kInvalidArgument,
                 fmt::format("domain '{}' is not a number in 0..232 or 'auto'", value)};
  }
  return static_cast<std::uint32_t>(id);
}

std::string self_exe() {
  std::error_code ec;
  const auto path = std::filesystem::read_symlink("/proc/self/exe", ec);
  return ec ? std::string("bus_bench") : path.string();
}

PingPongOptions ping_pong_options(const Options& options, const CpuPlan& cpus) {
  PingPongOptions pingpong;
  pingpong.warmup = options.warmup;
  pingpong.count_small = options.count != 0 ? options.count : (options.quick ? 2000 : 20000);
  pingpong.count_blob = options.count != 0 ? options.count : (options.quick ? 2000 : 10000);
  pingpong.blob_bytes = options.blob_bytes;
  pingpong.pong_cpu = cpus.pong_cpu;
  pingpong.wait = options.ping_wait == "waitset" ? PingWait::kWaitSet : PingWait::kWaitForData;
  pingpong.take = options.ping_take == "loan" ? PingTake::kLoan : PingTake::kCopy;
  pingpong.qos = options.qos == "command" ? PingQos::kCommand : PingQos::kKeepLast1;
  return pingpong;
}

// --role pong / --role stream-pub: the other process of a measurement.
int run_role(const Options& options, std::uint32_t domain) {
  log::init(fmt::format("bus_bench-{}", options.role), log::Level::kWarn);
  try {
    bus::Participant participant(domain, options.partition);
    if (options.role == "pong") {
      auto qos = parse_ping_qos(options.qos);
      if (!qos) {
        log::error("bad_qos", qos.error().message);
        return kExitUsage;
      }
      if (auto done = run_pong(participant, *qos, milliseconds(30000)); !done) {
        log::error("pong_failed", done.error().message);
        return kExitFailed;
      }
      return EXIT_SUCCESS;
    }
    auto profile = parse_stream_profile(options.profile);
    if (!profile) {
      log::error("bad_profile", profile.error().message);
      return kExitUsage;
    }
    StreamOptions stream;
    stream.profile = *profile;
    stream.duration_s = options.duration_s;
    stream.rate_hz = options.rate_hz;
    stream.rt_priority = options.rt_priority;
    auto report = run_stream_publisher(participant, stream);
    if (!report) {
      log::error("stream_pub_failed", report.error().message);
      return kExitFailed;
    }
    std::printf("%s\n", format_publisher_report(*report).c_str());
    std::fflush(stdout);
    return EXIT_SUCCESS;
  } catch (const bus::BusError& e) {
    log::error("bus", e.what());
    return kExitBus;
  }
}

bool executable(const std::string& path) {
  return path.find('/') != std::string::npos && access(path.c_str(), X_OK) == 0;
}

void progress(const Options& options, const std::string& text) {
  if (!options.json) {
    std::fprintf(stderr, "bus_bench: %s\n", text.c_str());
  }
}

// One repetition of the round-trip comparison for both sizes: the cell wrapper (one pong
// process serves both sizes) and ddsperf (one pair per size), in the order `cell_first`.
Status compare_once(const bus::Participant& participant,
                    const std::string& self,
                    const PingPongOptions& pingpong,
                    const std::string& ddsperf,
                    const Options& options,
                    const CpuPlan& cpus,
                    bool cell_first,
                    SizeComparison& small,
                    SizeComparison& blob,
                    std::vector<std::int64_t>& small_ns,
                    std::vector<std::int64_t>& blob_ns,
                    BenchReport& report) {
  const auto run_cell = [&]() -> Status {
    progress(options, fmt::format("cell::bus ping-pong: {} x {}, {} x {}", pingpong.count_small,
                                  small.label, pingpong.count_blob, blob.label));
    auto measured = run_ping(participant, self, pingpong);
    if (!measured) {
      return with_context(std::move(measured).error(), "cell::bus ping-pong");
    }
    // Same estimator as ddsperf's per-second lines (stats.hpp).
    constexpr std::int64_t kWindowNs = 1'000'000'000;
    small.cell_runs.push_back(summarize_windowed(measured->small_ns, kWindowNs));
    blob.cell_runs.push_back(summarize_windowed(measured->blob_ns, kWindowNs));
    small_ns.insert(small_ns.end(), measured->small_ns.begin(), measured->small_ns.end());
    blob_ns.insert(blob_ns.end(), measured->blob_ns.begin(), measured->blob_ns.end());
    return ok_status();
  };
  const auto run_reference = [&]() -> Status {
    for (SizeComparison* size : {&small, &blob}) {
      progress(options, fmt::format("ddsperf ping-pong: size {} for {:g} s", size->ddsperf_size,
                                    options.ddsperf_duration_s));
      DdsperfOptions run_options;
      run_options.executable = ddsperf;
      run_options.domain_id = report.domain_id;
      run_options.size_bytes = size->ddsperf_size;
      run_options.duration_s = options.ddsperf_duration_s;
      run_options.ping_cpu = cpus.ping_cpu;
      run_options.pong_cpu = cpus.pong_cpu;
      auto run = run_ddsperf(run_options);
      if (!run) {
        return with_context(std::move(run).error(), "ddsperf");
      }
      if (run->participants > 2) {
        report.warnings.push_back(fmt::format(
            "ddsperf saw {} ddsperf participants on domain {} (expected 2): another ddsperf "
            "shares the domain and every ping waits for all pongs; use another --domain",
            run->participants, report.domain_id));
      }
      auto rt = round_trip_from_ddsperf(run->lines);
      if (!rt) {
        return with_context(std::move(rt).error(), "ddsperf");
      }
      size->ddsperf_runs.push_back(*rt);
    }
    return ok_status();
  };
  const bool reference = !ddsperf.empty();
  CELL_TRY(cell_first || !reference ? run_cell() : run_reference());
  if (reference) {
    CELL_TRY(cell_first ? run_reference() : run_cell());
  }
  return ok_status();
}

int run_bench(const Options& options, std::uint32_t domain) {
  log::init("bus_bench", log::Level::kWarn);
  BenchReport report;
  report.domain_id = domain;
  report.partition = options.partition;
  report.cyclonedds_uri =
      std::getenv("CYCLONEDDS_URI") != nullptr ? std::getenv("CYCLONEDDS_URI") : "";
  report.cpus = std::thread::hardware_concurrency();
  report.quick = options.quick;
  report.repeat = options.repeat;
  report.rt_priority = options.rt_priority;
  const std::string self = self_exe();

  const auto placement = parse_placement(options.placement);
  if (!placement) {
    std::fprintf(stderr, "bus_bench: --pin: %s\n", placement.error().message.c_str());
    return kExitUsage;
  }
  const auto cpus = plan_cpus(*placement, allowed_cpus());
  if (!cpus) {
    std::fprintf(stderr, "bus_bench: --pin: %s\n", cpus.error().message.c_str());
    return kExitUsage;
  }
  report.placement =
      *placement == Placement::kNone ? std::string("none (scheduler's choice)")
      : *placement == Placement::kSame
          ? fmt::format("same (both processes on CPU {})", cpus->ping_cpu)
          : fmt::format("split (ping on CPU {}, pong on CPU {})", cpus->ping_cpu, cpus->pong_cpu);

  const PingPongOptions pingpong = ping_pong_options(options, *cpus);
  report.ping_side = fmt::format(
      "{} + {}, QoS {}", options.ping_wait == "waitset" ? "WaitSet" : "Reader::wait_for_data",
      options.ping_take == "loan" ? "Reader::take_each (loan)" : "Reader::take_copies",
      options.qos == "command" ? "command (RELIABLE KEEP_ALL)" : "RELIABLE KEEP_LAST 1");

  std::string ddsperf;
  if (!options.no_pingpong && !options.no_ddsperf) {
    ddsperf = process::which(options.ddsperf);
    if (!executable(ddsperf)) {
      report.warnings.push_back(
          fmt::format("'{}' not found: no ddsperf comparison (Debian package cyclonedds-tools)",
                      options.ddsperf));
      ddsperf.clear();
    }
  }
  report.ddsperf = ddsperf;

  try {
    if (!options.no_pingpong) {
      // This thread runs the ping loop; pinning it before the participant exists also pins the
      // threads Cyclone creates for the domain. Restored before the stream's participant.
      const cpu_set_t all = save_affinity();
      if (auto pinned = pin_thread(cpus->ping_cpu, all); !pinned) {
        log::error("pin_failed", pinned.error().message);
        return kExitFailed;
      }
      const std::uint32_t blob_wire = blob_wire_bytes(options.blob_bytes);
      SizeComparison small{"16 B", kSmallWireBytes, kSmallWireBytes, {}, {}, {}};
      SizeComparison blob{options.blob_bytes == 4096 ? "4 KiB" : fmt::format("{} B", blob_wire),
                          blob_wire,
                          blob_wire,
                          {},
                          {},
                          {}};
      std::vector<std::int64_t> small_ns;
      std::vector<std::int64_t> blob_ns;
      {
        bus::Participant participant(domain, options.partition);
        for (std::size_t rep = 1; rep <= options.repeat; ++rep) {
          progress(options, fmt::format("round trip, repetition {}/{}", rep, options.repeat));
          const bool cell_first = rep % 2 == 1;  // alternate, so neither always goes first
          if (auto done = compare_once(participant, self, pingpong, ddsperf, options, *cpus,
                                       cell_first, small, blob, small_ns, blob_ns, report);
              !done) {
            log::error("round_trip_failed", done.error().message);
            return kExitFailed;
          }
        }
      }
      (void)pin_thread(-1, all);
      small.cell_pooled = summarize(small_ns);
      blob.cell_pooled = summarize(blob_ns);
      report.sizes = {std::move(small), std::move(blob)};
    }
    if (!options.no_stream) {
      bus::Participant participant(domain, options.partition);
      for (const StreamProfile profile : {StreamProfile::kStream, StreamProfile::kReliableStream}) {
        progress(options, fmt::format("RobotState stream ({}): {:g} Hz for {:g} s",
                                      to_string(profile), options.rate_hz, options.duration_s));
        StreamOptions stream;
        stream.profile = profile;
        stream.duration_s = options.duration_s;
        stream.rate_hz = options.rate_hz;
        stream.rt_priority = options.rt_priority;
        auto result = run_stream_subscriber(participant, self, stream);
        if (!result) {
          log::error("stream_failed", result.error().message);
          return kExitFailed;
        }
        report.streams.push_back(*result);
      }
    }
  } catch (const bus::BusError& e) {
    log::error("bus", e.what());
    return kExitBus;
  }
  if (options.json) {
    std::printf("%s\n", report_json(report).dump(2).c_str());
    std::fflush(stdout);
  } else {
    print_report(stdout, report);
  }
  return EXIT_SUCCESS;
}

}  // namespace

static int main_body(int argc, char** argv) {
  Options options;
  CLI::App app("Bus benchmark: cell::bus round trip vs ddsperf, and a 1 kHz RobotState stream",
               "bus_bench");
  app.add_flag("--quick", options.quick,
               "Short run for a smoke test: few round trips, 2 s ddsperf, 1 s streams");
  app.add_flag("--json", options.json, "Print the results as JSON on stdout (no table)");
  app.add_option("--duration", options.duration_s, "RobotState stream duration [s] (default 10)")
      ->check(CLI::Range(0.1, 3600.0));
  app.add_option("--count", options.count,
                 "Measured round trips per message size (default 20000 small, 10000 4 KiB)")
      ->check(CLI::Range(1, 100000000));
  app.add_option("--warmup", options.warmup, "Unmeasured round trips per size (default 1000)");
  app.add_option("--ddsperf-duration", options.ddsperf_duration_s,
                 "ddsperf ping run time per size [s] (default 5; about 1 s of it is discovery)")
      ->check(CLI::Range(1.0, 3600.0));
  app.add_option("--repeat", options.repeat,
                 "Repetitions of the round-trip comparison, cell and ddsperf interleaved")
      ->check(CLI::Range(1, 100));
  app.add_option("--domain", options.domain,
                 "DDS domain id, or 'auto' (150 + pid % 80); default $CELL_DOMAIN_ID or 77");
  app.add_option("--partition", options.partition, "Partition (default bench-<pid>)");
  app.add_option("--ddsperf", options.ddsperf, "ddsperf executable (default: from PATH)");
  app.add_option("--pin", options.placement,
                 "CPU placement of the round trip's two processes: same (default), split, none")
      ->check(CLI::IsMember({"same", "split", "none"}));
  app.add_option("--ping-wait", options.ping_wait,
                 "Diagnostic: how the cell ping waits: waitset (default) or wait_for_data")
      ->check(CLI::IsMember({"waitset", "wait_for_data"}));
  app.add_option("--ping-take", options.ping_take,
                 "Diagnostic: how the cell ping takes: loan (take_each, default) or copy "
                 "(take_copies)")
      ->check(CLI::IsMember({"loan", "copy"}));
  app.add_option("--qos", options.qos,
                 "QoS of the cell ping-pong topics: command (RELIABLE KEEP_ALL, default) or "
                 "keep_last1 (RELIABLE KEEP_LAST 1, as ddsperf's ping/pong)")
      ->check(CLI::IsMember({"command", "keep_last1"}));
  app.add_flag("--no-ddsperf", options.no_ddsperf, "Skip the ddsperf comparison");
  app.add_flag("--no-pingpong", options.no_pingpong, "Skip the round-trip benchmark");
  app.add_flag("--no-stream", options.no_stream, "Skip the RobotState stream");
  app.add_option("--rate-hz", options.rate_hz, "RobotState rate [Hz] (default 1000)")
      ->check(CLI::Range(1.0, 20000.0));
  app.add_option("--rt-priority", options.rt_priority,
                 "RobotState publisher's pacing thread as SCHED_FIFO at this priority (0: off)")
      ->check(CLI::Range(0, 99));
  app.add_option("--blob-bytes", options.blob_bytes, "Payload of the large message (default 4096)")
      ->check(CLI::Range(1, 60000));
  app.add_option("--role", options.role, "Internal: run as the other process")
      ->check(CLI::IsMember({"pong", "stream-pub"}))
      ->group("");
  app.add_option("--profile", options.profile, "Internal: stream profile of --role stream-pub")
      ->group("");
  try {
    app.parse(argc, argv);
  } catch (const CLI::ParseError& e) {
    return app.exit(e) == 0 ? EXIT_SUCCESS : kExitUsage;
  }
  const bool duration_given = app.count("--duration") > 0;
  const bool warmup_given = app.count("--warmup") > 0;
  const bool ddsperf_given = app.count("--ddsperf-duration") > 0;
  if (options.quick) {
    options.duration_s = duration_given ? options.duration_s : 1.0;
    options.warmup = warmup_given ? options.warmup : 500;
    options.ddsperf_duration_s = ddsperf_given ? options.ddsperf_duration_s : 2.0;
  }
  const auto domain = resolve_domain(options.domain);
  if (!domain) {
    std::fprintf(stderr, "bus_bench: --domain: %s\n", domain.error().message.c_str());
    return kExitUsage;
  }
  if (options.partition.empty()) {
    options.partition = fmt::format("bench-{}", getpid());
  }
  if (!options.role.empty()) {
    return run_role(options, *domain);
  }
  // Same Cyclone configuration for us, our children and ddsperf: loopback only, unless the
  // caller chose one.
  if (const char* uri = std::getenv("CYCLONEDDS_URI"); uri == nullptr || *uri == '\0') {
    setenv("CYCLONEDDS_URI", CELL_BENCH_DDS_URI, 1);
  }
  return run_bench(options, *domain);
}

// Nothing escapes main: an exception is printed and fails the run.
int main(int argc, char** argv) {
  try {
    return main_body(argc, argv);
  } catch (const std::exception& e) {
    std::fprintf(stderr, "bus_bench: %s\n", e.what());
  } catch (...) {
    std::fprintf(stderr, "bus_bench: an exception not derived from std::exception\n");
  }
  return 1;
}
