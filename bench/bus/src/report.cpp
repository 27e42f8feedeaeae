#include "report.hpp"

#include <algorithm>

#include <fmt/format.h>

#include "cell/common/version.hpp"

namespace cell::bench {
namespace {

std::string us(double value) { return fmt::format("{:.1f}", value); }

std::string ratio_text(const std::optional<double>& ratio) {
  return ratio ? fmt::format("{:.2f}x", *ratio) : std::string("n/a");
}

double median(std::vector<double> values) {
  if (values.empty()) {
    return 0.0;
  }
  std::sort(values.begin(), values.end());
  const std::size_t mid = values.size() / 2;
  return values.size() % 2 == 1 ? values[mid] : 0.5 * (values[mid - 1] + values[mid]);
}

std::string p50s(const std::vector<Summary>& runs) {
  std::string out;
  for (const Summary& run : runs) {
    out += (out.empty() ? "" : " ") + us(run.p50_us);
  }
  return out.empty() ? "-" : out;
}

std::string stream_row(std::string_view profile,
                       const std::string& sent,
                       const std::string& received,
                       const std::string& lost,
                       const std::string& gaps,
                       const std::string& lat50,
                       const std::string& lat99,
                       const std::string& lat_max,
                       const std::string& jit50,
                       const std::string& jit99,
                       const std::string& jit_max,
                       const std::string& overruns) {
  return fmt::format(
      "{:<16} {:>6} {:>6} {:>5} {:>5} | {:>8} {:>8} {:>8} | {:>8} {:>8} {:>8} | {}\n", profile,
      sent, received, lost, gaps, lat50, lat99, lat_max, jit50, jit99, jit_max, overruns);
}

}  // namespace

void to_json(nlohmann::json& j, const Summary& s) {
  j = nlohmann::json{{"count", s.count},    {"min_us", s.min_us}, {"p50_us", s.p50_us},
                     {"p90_us", s.p90_us},  {"p99_us", s.p99_us}, {"max_us", s.max_us},
                     {"mean_us", s.mean_us}};
}

void from_json(const nlohmann::json& j, Summary& s) {
  j.at("count").get_to(s.count);
  j.at("min_us").get_to(s.min_us);
  j.at("p50_us").get_to(s.p50_us);
  j.at("p90_us").get_to(s.p90_us);
  j.at("p99_us").get_to(s.p99_us);
  j.at("max_us").get_to(s.max_us);
  j.at("mean_us").get_to(s.mean_us);
}

Summary median_of(const std::vector<Summary>& runs) {
  Summary m;
  const auto field = [&](double Summary::*member) {
    std::vector<double> values;
    values.reserve(runs.size());
    for (const Summary& run : runs) {
      values.push_back(run.*member);
    }
    return median(std::move(values));
  };
  for (const Summary& run : runs) {
    m.count += run.count;
  }
  m.min_us = field(&Summary::min_us);
  m.p50_us = field(&Summary::p50_us);
  m.p90_us = field(&Summary::p90_us);
  m.p99_us = field(&Summary::p99_us);
  m.max_us = field(&Summary::max_us);
  m.mean_us = field(&Summary::mean_us);
  return m;
}

std::optional<double> p50_ratio(const SizeComparison& size) noexcept {
  if (size.cell_runs.empty() || size.ddsperf_runs.empty()) {
    return std::nullopt;
  }
  const double ddsperf = median_of(size.ddsperf_runs).p50_us;
  if (ddsperf <= 0.0) {
    return std::nullopt;
  }
  return median_of(size.cell_runs).p50_us / ddsperf;
}

std::string_view criterion(const BenchReport& report) noexcept {
  bool any = false;
  for (const SizeComparison& size : report.sizes) {
    if (const auto ratio = p50_ratio(size)) {
      any = true;
      if (*ratio > kMaxP50Ratio) {
        return "FAIL";
      }
    }
  }
  return any ? "PASS" : "n/a";
}

void print_report(std::FILE* out, const BenchReport& report) {
  fmt::print(out, "bus_bench: cell {} on Cyclone DDS {}, {} CPUs, domain {}, partition {}{}\n",
             version(), dds_version(), report.cpus, report.domain_id, report.partition,
             report.quick ? " (--quick: too few samples for conclusions)" : "");
  fmt::print(out, "CYCLONEDDS_URI={}\n", report.cyclonedds_uri);
  if (!report.sizes.empty()) {
    fmt::print(out,
               "\nRound trip between two processes [us]: reliable, one message in flight; cell "
               "ping side: {};\nCPU placement {}; median of {} repetition(s), cell and ddsperf "
               "interleaved\n",
               report.ping_side, report.placement, report.repeat);
    const auto row = [&](const std::string& label, const std::string& n, const Summary* c,
                         const Summary* d, const std::string& ratio) {
      const auto cell = [](const Summary* s, double Summary::*member) {
        return s != nullptr ? us(s->*member) : std::string("n/a");
      };
      fmt::print(out, "{:<8} {:>7} | {:>8} {:>8} {:>8} {:>8} | {:>8} {:>8} {:>8} {:>8} | {}\n",
                 label, n, cell(c, &Summary::p50_us), cell(c, &Summary::p90_us),
                 cell(c, &Summary::p99_us), cell(c, &Summary::mean_us), cell(d, &Summary::p50_us),
                 cell(d, &Summary::p90_us), cell(d, &Summary::p99_us), cell(d, &Summary::mean_us),
                 ratio);
    };
    fmt::print(out, "{:<8} {:>7} | {:>8} {:>8} {:>8} {:>8} | {:>8} {:>8} {:>8} {:>8} | {}\n",
               "message", "n", "cell p50", "p90", "p99", "mean", "ddsperf", "p90", "p99", "mean",
               "cell/ddsperf p50");
    for (const SizeComparison& size : report.sizes) {
      const Summary c = median_of(size.cell_runs);
      const Summary d = median_of(size.ddsperf_runs);
      row(size.label, std::to_string(c.count), &c, size.ddsperf_runs.empty() ? nullptr : &d,
          ratio_text(p50_ratio(size)));
    }
    std::string ratios;
    for (const SizeComparison& size : report.sizes) {
      ratios += fmt::format("{}{} {}", ratios.empty() ? "" : ", ", size.label,
                            ratio_text(p50_ratio(size)));
    }
    fmt::print(out, "Criterion: cell::bus round trip p50 within {:.1f}x of ddsperf: {} ({})\n",
               kMaxP50Ratio, criterion(report), ratios);

    fmt::print(out, "\ncell::bus round trip, all repetitions pooled [us]\n");
    fmt::print(out, "{:<8} {:>7} {:>8} {:>8} {:>8} {:>8} {:>8} {:>8}\n", "message", "n", "min",
               "p50", "p90", "p99", "max", "mean");
    for (const SizeComparison& size : report.sizes) {
      const Summary& c = size.cell_pooled;
      fmt::print(out, "{:<8} {:>7} {:>8} {:>8} {:>8} {:>8} {:>8} {:>8}\n", size.label, c.count,
                 us(c.min_us), us(c.p50_us), us(c.p90_us), us(c.p99_us), us(c.max_us),
                 us(c.mean_us));
    }
    for (const SizeComparison& size : report.sizes) {
      fmt::print(out, "{} p50 per repetition [us]: cell {} | ddsperf (size {}) {}\n", size.label,
                 p50s(size.cell_runs), size.ddsperf_size, p50s(size.ddsperf_runs));
    }
  }
  if (!report.streams.empty()) {
    const StreamResult& first = report.streams.front();
    fmt::print(out,
               "\nRobotState stream, {:g} Hz for {:g} s, two processes, not pinned, publisher "
               "{} [us]\n(latency: header stamp to take, wall clock; jitter: |period - nominal| "
               "at the publisher; overruns: wake-ups more than a period late)\n",
               first.rate_hz, first.duration_s,
               report.rt_priority > 0 ? fmt::format("SCHED_FIFO {}", report.rt_priority)
                                      : std::string("SCHED_OTHER"));
    fmt::print(out, "{}",
               stream_row("profile", "sent", "recv", "lost", "gaps", "lat p50", "lat p99",
                          "lat max", "jit p50", "jit p99", "jit max", "overruns"));
    for (const StreamResult& s : report.streams) {
      fmt::print(
          out, "{}",
          stream_row(to_string(s.profile), std::to_string(s.publisher.sent),
                     std::to_string(s.received), std::to_string(s.lost), std::to_string(s.gaps),
                     us(s.latency.p50_us), us(s.latency.p99_us), us(s.latency.max_us),
                     us(s.publisher.period_jitter.p50_us), us(s.publisher.period_jitter.p99_us),
                     us(s.publisher.period_jitter.max_us), std::to_string(s.publisher.overruns)));
    }
    for (const StreamResult& s : report.streams) {
      if (s.lost + s.duplicates + s.out_of_order + s.publisher.write_errors > 0) {
        fmt::print(out, "{}: first lost seq {}, {} duplicates, {} out of order, {} write errors\n",
                   to_string(s.profile), s.first_lost, s.duplicates, s.out_of_order,
                   s.publisher.write_errors);
      }
    }
  }
  for (const std::string& warning : report.warnings) {
    fmt::print(out, "warning: {}\n", warning);
  }
  std::fflush(out);
}

nlohmann::json report_json(const BenchReport& report) {
  nlohmann::json sizes = nlohmann::json::array();
  for (const SizeComparison& size : report.sizes) {
    const auto ratio = p50_ratio(size);
    sizes.push_back(
        {{"message", size.label},
         {"wire_bytes", size.wire_bytes},
         {"ddsperf_size", size.ddsperf_size},
         {"cell", median_of(size.cell_runs)},
         {"ddsperf", size.ddsperf_runs.empty() ? nlohmann::json()
                                               : nlohmann::json(median_of(size.ddsperf_runs))},
         {"ratio_p50", ratio ? nlohmann::json(*ratio) : nlohmann::json()},
         {"cell_pooled", size.cell_pooled},
         {"cell_runs", size.cell_runs},
         {"ddsperf_runs", size.ddsperf_runs}});
  }
  nlohmann::json streams = nlohmann::json::array();
  for (const StreamResult& s : report.streams) {
    streams.push_back({{"profile", std::string(to_string(s.profile))},
                       {"rate_hz", s.rate_hz},
                       {"duration_s", s.duration_s},
                       {"sent", s.publisher.sent},
                       {"received", s.received},
                       {"lost", s.lost},
                       {"first_lost_seq", s.first_lost},
                       {"gaps", s.gaps},
                       {"duplicates", s.duplicates},
                       {"out_of_order", s.out_of_order},
                       {"write_errors", s.publisher.write_errors},
                       {"overruns", s.publisher.overruns},
                       {"latency", s.latency},
                       {"period_jitter", s.publisher.period_jitter},
                       {"write", s.publisher.write}});
  }
  return {
      {"bench", "bus_bench"},
      {"cell_version", std::string(version())},
      {"dds_version", std::string(dds_version())},
      {"cpus", report.cpus},
      {"domain_id", report.domain_id},
      {"partition", report.partition},
      {"cyclonedds_uri", report.cyclonedds_uri},
      {"ddsperf", report.ddsperf},
      {"placement", report.placement},
      {"ping_side", report.ping_side},
      {"stream_rt_priority", report.rt_priority},
      {"quick", report.quick},
      {"repeat", report.repeat},
      {"round_trip", sizes},
      {"criterion", {{"max_ratio_p50", kMaxP50Ratio}, {"result", std::string(criterion(report))}}},
      {"stream", streams},
      {"warnings", report.warnings}};
}

}  // namespace cell::bench
