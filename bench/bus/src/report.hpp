#pragma once

#include <cstdint>
#include <cstdio>
#include <optional>
#include <string>
#include <string_view>
#include <vector>

#include <nlohmann/json.hpp>

#include "stats.hpp"
#include "stream.hpp"

/// The bus benchmark's results: the side-by-side table for people, JSON for machines.
namespace cell::bench {

/// The foundation issue's criterion: the wrapper's p50 round trip at most this many times
/// ddsperf's, for every message size.
inline constexpr double kMaxP50Ratio = 1.5;

/// cell::bus and ddsperf round trips for one message size, per repetition.
struct SizeComparison {
  std::string label;                  ///< "16 B", "4 KiB"
  std::uint32_t wire_bytes = 0;       ///< serialised bytes of the cell message's fields
  std::uint32_t ddsperf_size = 0;     ///< ddsperf "size S" (KS topic: 12 + sequence length)
  std::vector<Summary> cell_runs;     ///< one per repetition
  std::vector<Summary> ddsperf_runs;  ///< one per repetition; empty when ddsperf did not run
  Summary cell_pooled;                ///< every cell round trip of every repetition
};

/// Field-wise median of per-repetition summaries (count: the sum). Weighs every repetition
/// equally: ddsperf runs for a duration and does more round trips when the machine is fast,
/// so pooling would favour it. Zeros when `runs` is empty.
Summary median_of(const std::vector<Summary>& runs);

/// Everything one run of bus_bench measured, plus how it ran.
struct BenchReport {
  std::uint32_t domain_id = 0;
  std::string partition;
  std::string cyclonedds_uri;
  std::string ddsperf;    ///< resolved path, empty when not run
  std::string placement;  ///< "same (CPU 1)", "split (CPUs 0/1)", "none"
  std::string ping_side;  ///< how the cell ping waits and takes, e.g. "WaitSet + take_each"
  int rt_priority = 0;    ///< SCHED_FIFO priority of the stream publisher's thread, 0: none
  unsigned cpus = 0;
  bool quick = false;
  std::size_t repeat = 1;
  std::vector<SizeComparison> sizes;
  std::vector<StreamResult> streams;
  std::vector<std::string> warnings;
};

/// median cell p50 / median ddsperf p50 for one size; nullopt without ddsperf numbers.
std::optional<double> p50_ratio(const SizeComparison& size) noexcept;

/// "PASS" when every size with ddsperf numbers is within kMaxP50Ratio, "FAIL" when one is
/// not, "n/a" when no size has ddsperf numbers.
std::string_view criterion(const BenchReport& report) noexcept;

/// The human-readable report: round-trip table side by side, criterion line, the wrapper's
/// full distribution, per-repetition p50s, the stream table, warnings.
void print_report(std::FILE* out, const BenchReport& report);

/// The same as JSON (every duration in microseconds, keys suffixed _us).
nlohmann::json report_json(const BenchReport& report);

/// JSON form of a Summary: {"count", "min_us", "p50_us", "p90_us", "p99_us", "max_us",
/// "mean_us"}. from_json throws nlohmann::json::exception on a missing or mistyped key.
void to_json(nlohmann::json& j, const Summary& s);
void from_json(const nlohmann::json& j, Summary& s);

}  // namespace cell::bench
