#include "ddsperf.hpp"

#include <algorithm>
#include <chrono>
#include <cstdio>
#include <limits>
#include <set>
#include <string>

#include <fmt/format.h>

#include "affinity.hpp"
#include "cell/process/child.hpp"

namespace cell::bench {

Result<DdsperfLine> parse_ddsperf_line(std::string_view line) {
  const auto bad = [&](std::string_view why) {
    return Error{Errc::kInvalidArgument,
                 fmt::format("not a ddsperf latency line ({}): '{}'", why, line)};
  };
  // "[pid] T  host:pid size S mean ..": the time is the first token after "] ".
  const std::size_t close = line.find("] ");
  const std::size_t size_at = line.find(" size ");
  if (close == std::string_view::npos || size_at == std::string_view::npos || size_at < close) {
    return bad("no '[pid] time ... size' prefix");
  }
  const std::string text(line);  // sscanf needs a terminated string
  DdsperfLine out;
  if (std::sscanf(text.c_str() + close + 2, "%lf", &out.t_s) != 1) {
    return bad("no time stamp");
  }
  unsigned size = 0;
  unsigned long long count = 0;
  const int fields = std::sscanf(text.c_str() + size_at + 1,
                                 "size %u mean %lfus min %lfus 50%% %lfus 90%% %lfus 99%% %lfus "
                                 "max %lfus cnt %llu",
                                 &size, &out.mean_us, &out.min_us, &out.p50_us, &out.p90_us,
                                 &out.p99_us, &out.max_us, &count);
  if (fields != 8) {
    return bad(fmt::format("{} of 8 fields", std::max(fields, 0)));
  }
  out.size_bytes = size;
  out.count = count;
  return out;
}

std::vector<DdsperfLine> parse_ddsperf_output(std::string_view output) {
  std::vector<DdsperfLine> lines;
  std::size_t start = 0;
  while (start < output.size()) {
    std::size_t end = output.find('\n', start);
    if (end == std::string_view::npos) {
      end = output.size();
    }
    const std::string_view line = output.substr(start, end - start);
    if (line.find(" mean ") != std::string_view::npos) {
      if (auto parsed = parse_ddsperf_line(line)) {
        lines.push_back(*parsed);
      }
    }
    start = end + 1;
  }
  return lines;
}

std::size_t ddsperf_participants(std::string_view output) {
  std::set<std::string> seen;
  std::size_t start = 0;
  while (start < output.size()) {
    std::size_t end = output.find('\n', start);
    if (end == std::string_view::npos) {
      end = output.size();
    }
    const std::string_view line = output.substr(start, end - start);
    const std::size_t at = line.find("] participant ");
    const std::size_t tag = line.find(": new");
    if (at != std::string_view::npos && tag != std::string_view::npos && tag > at) {
      const std::size_t name = at + std::string_view("] participant ").size();
      seen.emplace(line.substr(name, tag - name));
    }
    start = end + 1;
  }
  return seen.size();
}

Result<Summary> round_trip_from_ddsperf(const std::vector<DdsperfLine>& lines) {
  Summary s;
  double min_us = std::numeric_limits<double>::infinity();
  double max_us = 0.0;
  double sum_mean = 0.0;
  double sum_p50 = 0.0;
  double sum_p90 = 0.0;
  double sum_p99 = 0.0;
  std::uint64_t total = 0;
  for (const DdsperfLine& line : lines) {
    const auto n = static_cast<double>(line.count);
    total += line.count;
    min_us = std::min(min_us, line.min_us);
    max_us = std::max(max_us, line.max_us);
    sum_mean += n * line.mean_us;
    sum_p50 += n * line.p50_us;
    sum_p90 += n * line.p90_us;
    sum_p99 += n * line.p99_us;
  }
  if (total == 0) {
    return Error{Errc::kInvalidArgument,
                 fmt::format("no ddsperf round trips to summarise ({} lines)", lines.size())};
  }
  // ddsperf prints half the round trip: double everything back to a round trip.
  const double n = static_cast<double>(total);
  s.count = total;
  s.min_us = 2.0 * min_us;
  s.max_us = 2.0 * max_us;
  s.mean_us = 2.0 * sum_mean / n;
  s.p50_us = 2.0 * sum_p50 / n;
  s.p90_us = 2.0 * sum_p90 / n;
  s.p99_us = 2.0 * sum_p99 / n;
  return s;
}

Result<DdsperfRun> run_ddsperf(const DdsperfOptions& options) {
  using std::chrono::milliseconds;
  const std::string domain = std::to_string(options.domain_id);
  process::SpawnOptions pong_options;
  pong_options.executable = options.executable;
  pong_options.args = {"-i", domain, "pong", "waitset"};
  auto pong = on_cpu(options.pong_cpu, [&] { return process::Child::spawn(pong_options); });
  if (!pong) {
    return with_context(std::move(pong).error(), "starting ddsperf pong");
  }
  process::SpawnOptions ping_options;
  ping_options.executable = options.executable;
  ping_options.args = {"-i",
                       domain,
                       "-D",
                       fmt::format("{:g}", options.duration_s),
                       "ping",
                       "size",
                       std::to_string(options.size_bytes),
                       "waitset"};
  auto ping = on_cpu(options.ping_cpu, [&] { return process::Child::spawn(ping_options); });
  if (!ping) {
    pong->stop(milliseconds(2000));
    return with_context(std::move(ping).error(), "starting ddsperf ping");
  }
  const auto limit = milliseconds(static_cast<long>(options.duration_s * 1000.0) + 15000);
  const auto exit = ping->wait_for(limit);
  pong->stop(milliseconds(2000));
  if (!exit) {
    ping->stop(milliseconds(1000));
    return Error{Errc::kTimeout,
                 fmt::format("ddsperf ping (size {}) still running after {} ms; output:\n{}",
                             options.size_bytes, limit.count(), ping->output())};
  }
  if (!exit->exited || exit->code != 0) {
    return Error{Errc::kProtocol,
                 fmt::format("ddsperf ping (size {}) ended with {}; output:\n{}",
                             options.size_bytes, exit->describe(), ping->output())};
  }
  DdsperfRun run;
  run.ping_output = ping->output();
  run.lines = parse_ddsperf_output(run.ping_output);
  run.participants = ddsperf_participants(run.ping_output);
  if (run.lines.empty()) {
    return Error{Errc::kProtocol,
                 fmt::format("ddsperf ping (size {}) printed no latency line; output:\n{}",
                             options.size_bytes, run.ping_output)};
  }
  return run;
}

}  // namespace cell::bench
