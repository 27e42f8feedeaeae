#include "stats.hpp"

#include <algorithm>
#include <cmath>
#include <numeric>

namespace cell::bench {

std::int64_t percentile_ns(const std::vector<std::int64_t>& sorted_ns, double q) noexcept {
  if (sorted_ns.empty()) {
    return 0;
  }
  const double rank = std::ceil(q * static_cast<double>(sorted_ns.size()));
  const std::size_t index =
      rank <= 1.0 ? 0 : std::min(sorted_ns.size() - 1, static_cast<std::size_t>(rank) - 1);
  return sorted_ns[index];
}

Summary summarize(std::vector<std::int64_t>& samples_ns) {
  Summary s;
  if (samples_ns.empty()) {
    return s;
  }
  std::sort(samples_ns.begin(), samples_ns.end());
  constexpr double kUsPerNs = 1e-3;
  const long double sum = std::accumulate(samples_ns.begin(), samples_ns.end(), 0.0L);
  s.count = samples_ns.size();
  s.min_us = static_cast<double>(samples_ns.front()) * kUsPerNs;
  s.max_us = static_cast<double>(samples_ns.back()) * kUsPerNs;
  s.p50_us = static_cast<double>(percentile_ns(samples_ns, 0.50)) * kUsPerNs;
  s.p90_us = static_cast<double>(percentile_ns(samples_ns, 0.90)) * kUsPerNs;
  s.p99_us = static_cast<double>(percentile_ns(samples_ns, 0.99)) * kUsPerNs;
  s.mean_us = static_cast<double>(sum / static_cast<long double>(s.count)) * kUsPerNs;
  return s;
}

Summary summarize_windowed(const std::vector<std::int64_t>& series_ns, std::int64_t window_ns) {
  std::vector<std::int64_t> all = series_ns;
  Summary total = summarize(all);
  if (series_ns.empty()) {
    return total;
  }
  double p50 = 0.0;
  double p90 = 0.0;
  double p99 = 0.0;
  std::vector<std::int64_t> window;
  std::int64_t elapsed = 0;
  const auto close_window = [&] {
    if (window.empty()) {
      return;
    }
    const Summary w = summarize(window);
    const auto n = static_cast<double>(w.count);
    p50 += n * w.p50_us;
    p90 += n * w.p90_us;
    p99 += n * w.p99_us;
    window.clear();
    elapsed = 0;
  };
  for (const std::int64_t sample : series_ns) {
    window.push_back(sample);
    elapsed += sample;
    if (elapsed >= window_ns) {
      close_window();
    }
  }
  close_window();
  const auto n = static_cast<double>(total.count);
  total.p50_us = p50 / n;
  total.p90_us = p90 / n;
  total.p99_us = p99 / n;
  return total;
}

}  // namespace cell::bench
