#include "cell/vision/edge.hpp"

#include <fmt/format.h>

#include <algorithm>
#include <cmath>
#include <optional>
#include <vector>

#include "fit.hpp"
#include "support.hpp"

namespace cell::vision {
namespace {

using detail::invalid;
Error out_of_range(std::string what) { return Error{Errc::kOutOfRange, std::move(what)}; }

using detail::perp;

/// Liang-Barsky: the parameter interval [lo, hi] of p + t d inside [x0, x1] x [y0, y1],
/// intersected with the given one; false when empty.
bool clip(const Eigen::Vector2d& p,
          const Eigen::Vector2d& d,
          double x0,
          double x1,
          double y0,
          double y1,
          double& lo,
          double& hi) {
  const std::array<double, 4> pk{-d.x(), d.x(), -d.y(), d.y()};
  const std::array<double, 4> qk{p.x() - x0, x1 - p.x(), p.y() - y0, y1 - p.y()};
  for (std::size_t k = 0; k < 4; ++k) {
    if (std::abs(pk[k]) < 1e-12) {
      if (qk[k] < 0.0) {
        return false;
      }
      continue;
    }
    const double t = qk[k] / pk[k];
    if (pk[k] < 0.0) {
      lo = std::max(lo, t);
    } else {
      hi = std::min(hi, t);
    }
  }
  return lo <= hi;
}

/// Bilinear grey value at (x, y); the caller keeps (x, y) one pixel inside the image.
double bilinear(const cv::Mat& image, double x, double y) {
  const int x0 = static_cast<int>(std::floor(x));
  const int y0 = static_cast<int>(std::floor(y));
  const double tx = x - x0;
  const double ty = y - y0;
  const std::uint8_t* r0 = image.ptr<std::uint8_t>(y0);
  const std::uint8_t* r1 = image.ptr<std::uint8_t>(y0 + 1);
  return (1 - ty) * ((1 - tx) * r0[x0] + tx * r0[x0 + 1]) +
         ty * ((1 - tx) * r1[x0] + tx * r1[x0 + 1]);
}

}  // namespace

Eigen::Vector2d EdgeWindow::along() const { return (p3 - p1).normalized(); }
Eigen::Vector2d EdgeWindow::across() const { return (p2 - p1).normalized(); }

Result<EdgeWindow> suggest_window(const Eigen::Vector2d& start,
                                  const Eigen::Vector2d& end,
                                  double tolerance_px,
                                  int width_px,
                                  int height_px,
                                  double min_length_px) {
  if (!start.allFinite() || !end.allFinite() || !std::isfinite(tolerance_px)) {
    return invalid("edge prediction is not finite");
  }
  if (!(tolerance_px > 0.0)) {
    return invalid(fmt::format("the search tolerance must be > 0 px, got {}", tolerance_px));
  }
  const double length = (end - start).norm();
  if (length < 1e-6) {
    return invalid(fmt::format("the predicted edge's end points coincide at ({:.2f}, {:.2f})",
                               start.x(), start.y()));
  }
  if (width_px < 3 || height_px < 3) {
    return invalid(fmt::format("image {} x {} px is too small to search", width_px, height_px));
  }
  const Eigen::Vector2d u = (end - start) / length;
  const Eigen::Vector2d n = perp(u);
  // Is any of the predicted edge in the image at all?
  {
    double lo = 0.0;
    double hi = length;
    if (!clip(start, u, -0.5, width_px - 0.5, -0.5, height_px - 0.5, lo, hi)) {
      return out_of_range(
          fmt::format("the predicted edge ({:.1f}, {:.1f}) -> ({:.1f}, {:.1f}) "
                      "lies entirely outside the {} x {} image",
                      start.x(), start.y(), end.x(), end.y(), width_px, height_px));
    }
  }
  EdgeWindow w;
  w.half_width_px = tolerance_px;
  double t0 = tolerance_px;
  double t1 = length - tolerance_px;
  if (t1 - t0 < min_length_px) {
    // Shorter than the tolerance can guarantee: the middle of the predicted edge only.
    w.guaranteed = false;
    t0 = 0.5 * length - 0.5 * min_length_px;
    t1 = 0.5 * length + 0.5 * min_length_px;
  }
  // Keep the whole cross-section inside the image, one pixel in for the 3 x 3 weights.
  double lo = t0;
  double hi = t1;
  const double x0 = 1.0;
  const double x1 = width_px - 2.0;
  const double y0 = 1.0;
  const double y1 = height_px - 2.0;
  const bool a = clip(start - tolerance_px * n, u, x0, x1, y0, y1, lo, hi);
  const bool b = a && clip(start + tolerance_px * n, u, x0, x1, y0, y1, lo, hi);
  if (!a || !b || hi - lo < min_length_px) {
    return out_of_range(fmt::format(
        "search window abolished: no {:.0f} px of the edge ({:.1f}, "
        "{:.1f}) -> ({:.1f}, {:.1f}) has its +-{:.1f} px cross-section "
        "inside the {} x {} image (a long side lies outside)",
        min_length_px, start.x(), start.y(), end.x(), end.y(), tolerance_px, width_px, height_px));
  }
  w.clipped = lo > t0 + 1e-9 || hi < t1 - 1e-9;
  w.p1 = start + lo * u - tolerance_px * n;
  w.p2 = start + lo * u + tolerance_px * n;
  w.p3 = start + hi * u - tolerance_px * n;
  return w;
}

int wong_weight(const cv::Mat& image, int u, int v) noexcept {
  const std::uint8_t* top = image.ptr<std::uint8_t>(v - 1);
  const std::uint8_t* mid = image.ptr<std::uint8_t>(v);
  const std::uint8_t* bot = image.ptr<std::uint8_t>(v + 1);
  const int a = top[u - 1];
  const int b = top[u];
  const int c = top[u + 1];
  const int g = mid[u - 1];
  const int h = mid[u + 1];
  const int d = bot[u - 1];
  const int e = bot[u];
  const int f = bot[u + 1];
  return std::abs(a + b + c - d - e - f) + std::abs(c + h + f - a - g - d);
}

Status EdgeFinderOptions::validate() const {
  if (!(weight_fraction > 0.0 && weight_fraction < 1.0)) {
    return invalid(fmt::format("edges.weight_fraction must be in (0, 1), got {}", weight_fraction));
  }
  if (min_weight < 1) {
    return invalid(fmt::format("edges.min_weight must be >= 1, got {}", min_weight));
  }
  if (!(end_search_px >= 0.0)) {
    return invalid(fmt::format("edges.end_search_px must be >= 0, got {}", end_search_px));
  }
  if (profile_half_px < 2 || profile_half_px > 16) {
    return invalid(fmt::format("edges.profile_half_px must be in 2..16, got {}", profile_half_px));
  }
  if (!(outlier_px > 0.0)) {
    return invalid(fmt::format("edges.outlier_px must be > 0, got {}", outlier_px));
  }
  return ok_status();
}

Result<EdgeMeasurement> find_edge(const cv::Mat& image,
                                  const EdgeWindow& window,
                                  const EdgeFinderOptions& options) {
  if (image.empty() || image.type() != CV_8UC1) {
    return invalid("the edge finder needs a non-empty 8-bit grey image");
  }
  CELL_TRY(options.validate());
  const double length = window.length_px();
  const double width = (window.p2 - window.p1).norm();
  if (!(length >= 1.0) || !(width >= 1.0) || !window.p1.allFinite() || !window.p2.allFinite() ||
      !window.p3.allFinite()) {
    return invalid("degenerate search window");
  }
  const Eigen::Vector2d u = window.along();
  const Eigen::Vector2d n = window.across();
  auto inside = [&](const Eigen::Vector2d& p) {
    return p.x() >= 1.0 && p.y() >= 1.0 && p.x() <= image.cols - 2.0 && p.y() <= image.rows - 2.0;
  };
  auto weight_at = [&](const Eigen::Vector2d& p) -> int {
    if (!inside(p)) {
      return 0;
    }
    return wong_weight(image, static_cast<int>(std::lround(p.x())),
                       static_cast<int>(std::lround(p.y())));
  };
  const int steps_t = static_cast<int>(std::floor(length));
  const int steps_s = static_cast<int>(std::floor(width));
  int max_weight = 0;
  for (int t = 0; t <= steps_t; ++t) {
    for (int s = 0; s <= steps_s; ++s) {
      max_weight = std::max(max_weight, weight_at(window.p1 + t * u + s * n));
    }
  }
  const double threshold =
      std::max<double>(options.min_weight, options.weight_fraction * max_weight);
  // Candidate end points: inward from each short side, the local maxima across the window above
  // the threshold, on the first cross-section that has any.
  auto candidates = [&](bool from_start) {
    std::vector<Eigen::Vector2d> out;
    const int reach = static_cast<int>(std::floor(options.end_search_px));
    for (int k = 0; k <= reach && out.empty(); ++k) {
      const double t = from_start ? k : length - k;
      if (t < 0.0 || t > length) {
        break;
      }
      std::vector<int> profile(static_cast<std::size_t>(steps_s + 1));
      for (int s = 0; s <= steps_s; ++s) {
        profile[static_cast<std::size_t>(s)] = weight_at(window.p1 + t * u + s * n);
      }
      for (int s = 0; s <= steps_s; ++s) {
        const int wgt = profile[static_cast<std::size_t>(s)];
        const int left = s > 0 ? profile[static_cast<std::size_t>(s - 1)] : -1;
        const int right = s < steps_s ? profile[static_cast<std::size_t>(s) + 1] : -1;
        if (wgt >= threshold && wgt >= left && wgt > right) {
          out.push_back(window.p1 + t * u + s * n);
        }
      }
    }
    return out;
  };
  const auto first = candidates(true);
  const auto last = candidates(false);
  if (first.empty() || last.empty()) {
    return out_of_range(fmt::format(
        "no edge in the window: no candidate end point (weight >= {:.0f}) within {:.0f} px of the "
        "window's {} (largest weight in the window {})",
        threshold, options.end_search_px, first.empty() ? "start" : "end", max_weight));
  }
  // The pair whose connecting pixels are the heaviest on average.
  double best_mean = -1.0;
  Eigen::Vector2d a = first.front();
  Eigen::Vector2d b = last.front();
  for (const auto& p : first) {
    for (const auto& q : last) {
      const double len = (q - p).norm();
      const int steps = std::max(1, static_cast<int>(std::ceil(len)));
      double sum = 0.0;
      for (int k = 0; k <= steps; ++k) {
        sum += weight_at(p + (q - p) * (static_cast<double>(k) / steps));
      }
      const double mean = sum / (steps + 1);
      if (mean > best_mean) {
        best_mean = mean;
        a = p;
        b = q;
      }
    }
  }
  // Sub-pixel: across the chosen segment, the area between the grey plateaus, every pixel.
  const Eigen::Vector2d d = (b - a).normalized();
  const Eigen::Vector2d m = perp(d);
  const int half = options.profile_half_px;
  std::vector<Eigen::Vector2d> points;
  const int steps = static_cast<int>(std::floor((b - a).norm()));
  std::vector<double> profile(static_cast<std::size_t>(2 * half + 1));
  for (int k = 0; k <= steps; ++k) {
    const Eigen::Vector2d q = a + k * d;
    if (!inside(q + half * m) || !inside(q - half * m)) {
      continue;
    }
    for (int i = 0; i <= 2 * half; ++i) {  // across, from -half to +half
      const Eigen::Vector2d p = q + (i - half) * m;
      profile[static_cast<std::size_t>(i)] = bilinear(image, p.x(), p.y());
    }
    const double lo_end = 0.5 * (profile[0] + profile[1]);
    const double hi_end = 0.5 * (profile[profile.size() - 1] + profile[profile.size() - 2]);
    const double bright = std::max(lo_end, hi_end);
    const double dark = std::min(lo_end, hi_end);
    if (bright - dark < 12.0) {
      continue;  // no step here
    }
    double sum = 0.0;
    for (double v : profile) {
      sum += (v - dark) / (bright - dark);
    }
    // Bright at the -half end: the edge lies `sum` samples in from it; else from the +half end.
    const double offset = lo_end > hi_end ? -half - 0.5 + sum : half + 0.5 - sum;
    if (std::abs(offset) > half - 1.0) {
      continue;  // the step is not inside the profile
    }
    points.push_back(q + offset * m);
  }
  if (points.size() < 4) {
    return out_of_range(
        fmt::format("no edge in the window: only {} edge points along the "
                    "candidate pair (4 needed)",
                    points.size()));
  }
  auto line = detail::fit_line(points, m);
  if (!line) {
    return out_of_range("no edge in the window: the edge points do not make a line");
  }
  std::vector<Eigen::Vector2d> kept;
  for (const auto& p : points) {
    if (std::abs(line->distance(p)) <= options.outlier_px) {
      kept.push_back(p);
    }
  }
  if (kept.size() < 4) {
    return out_of_range(fmt::format("no edge in the window: {} of {} edge points on one line",
                                    kept.size(), points.size()));
  }
  line = detail::fit_line(kept, m);
  EdgeMeasurement out;
  double sum2 = 0.0;
  double t_min = 1e300;
  double t_max = -1e300;
  for (const auto& p : kept) {
    const double r = line->distance(p);
    sum2 += r * r;
    const double t = (p - window.p1).dot(u);
    t_min = std::min(t_min, t);
    t_max = std::max(t_max, t);
  }
  // End points: the extent of the edge points, on the fitted line.
  const Eigen::Vector2d dir = perp(line->n);
  auto on_line = [&](double t) {
    const Eigen::Vector2d p = window.p1 + t * u;
    Eigen::Vector2d foot = p - line->distance(p) * line->n;
    return foot;
  };
  (void)dir;
  out.start_px = on_line(t_min);
  out.end_px = on_line(t_max);
  out.residual_px = std::sqrt(sum2 / static_cast<double>(kept.size()));
  out.point_count = static_cast<int>(kept.size());
  out.mean_weight = best_mean;
  return out;
}

}  // namespace cell::vision
