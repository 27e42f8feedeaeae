#pragma once

#include <cstddef>
#include <cstdint>
#include <vector>

/// Latency statistics of the bus benchmark (bench/bus): order statistics of raw samples.
namespace cell::bench {

/// Order statistics of a set of durations, in microseconds.
struct Summary {
  std::size_t count = 0;  ///< number of samples
  double min_us = 0.0;
  double p50_us = 0.0;
  double p90_us = 0.0;
  double p99_us = 0.0;
  double max_us = 0.0;
  double mean_us = 0.0;
};

/// Nearest-rank percentile `q` (0 < q <= 1) of `sorted_ns` (ascending, nanoseconds), in
/// nanoseconds: the smallest sample such that at least q of all samples are <= it.
/// Returns 0 for an empty vector.
std::int64_t percentile_ns(const std::vector<std::int64_t>& sorted_ns, double q) noexcept;

/// Summary of `samples_ns` (nanoseconds, any order; sorted in place). All zero when empty.
Summary summarize(std::vector<std::int64_t>& samples_ns);

/// The series reduced the way ddsperf reduces its own: cut into consecutive windows of
/// `window_ns` elapsed time (elapsed = running sum of the samples, as the round trips run back
/// to back), percentiles per window, then averaged weighted by each window's count; count,
/// min, max and mean exact. Applied to the cell's round trips so that both sides of the
/// comparison go through the same estimator (which differs from the pooled percentile only
/// when the latency changes mode during the run). `series_ns` in measurement order.
Summary summarize_windowed(const std::vector<std::int64_t>& series_ns, std::int64_t window_ns);

}  // namespace cell::bench
