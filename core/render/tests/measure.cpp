#include "measure.hpp"

#include <algorithm>
#include <cmath>

#include <Eigen/LU>

namespace cell::render::testing {

std::optional<Line2> fit_edge(const cv::Mat& image, const Eigen::Vector2d& p0,
                              const Eigen::Vector2d& p1, const Eigen::Vector2d& inside,
                              int half_window) {
  const Eigen::Vector2d d = p1 - p0;
  const bool steep = std::abs(d.x()) <= std::abs(d.y());  // iterate rows for steep edges
  // In the transposed frame (for shallow edges) "x" is the row index and "y" the column.
  auto at = [&](int along, int across) -> double {
    const int r = steep ? along : across;
    const int c = steep ? across : along;
    if (r < 0 || c < 0 || r >= image.rows || c >= image.cols) {
      return NAN;
    }
    return image.at<std::uint8_t>(r, c);
  };
  const double a0 = steep ? p0.y() : p0.x();
  const double a1 = steep ? p1.y() : p1.x();
  const double c0 = steep ? p0.x() : p0.y();
  const double c1 = steep ? p1.x() : p1.y();
  const Eigen::Vector2d mid = 0.5 * (p0 + p1);
  const double inside_across = steep ? inside.x() - mid.x() : inside.y() - mid.y();
  const bool dark_after = inside_across > 0.0;  // dark at larger across-coordinates
  const double lo = std::min(a0, a1) + 0.15 * std::abs(a1 - a0);
  const double hi = std::max(a0, a1) - 0.15 * std::abs(a1 - a0);
  std::vector<Eigen::Vector2d> samples;  // (across position of the edge, along)
  for (int along = static_cast<int>(std::ceil(lo)); along <= static_cast<int>(std::floor(hi));
       ++along) {
    const double t = (along - a0) / (a1 - a0);
    const double predicted = c0 + t * (c1 - c0);
    const int centre = static_cast<int>(std::lround(predicted));
    const int first = centre - half_window;
    const int last = centre + half_window;
    const double bright = at(along, dark_after ? first : last);
    const double dark = at(along, dark_after ? last : first);
    if (!std::isfinite(bright) || !std::isfinite(dark) || bright - dark < 20.0) {
      continue;
    }
    double dark_length = 0.0;
    bool ok = true;
    for (int c = first; c <= last; ++c) {
      const double v = at(along, c);
      if (!std::isfinite(v)) {
        ok = false;
        break;
      }
      dark_length += (bright - v) / (bright - dark);
    }
    if (!ok) {
      continue;
    }
    const double edge = dark_after ? last + 0.5 - dark_length : first - 0.5 + dark_length;
    samples.emplace_back(edge, along);
  }
  if (samples.size() < 5) {
    return std::nullopt;
  }
  // Least squares across = m * along + q.
  double sa = 0.0;
  double sc = 0.0;
  double saa = 0.0;
  double sac = 0.0;
  const double n = static_cast<double>(samples.size());
  for (const auto& s : samples) {
    sa += s.y();
    sc += s.x();
    saa += s.y() * s.y();
    sac += s.y() * s.x();
  }
  const double m = (n * sac - sa * sc) / (n * saa - sa * sa);
  const double q = (sc - m * sa) / n;
  const double along_mid = sa / n;
  Line2 line;
  if (steep) {  // x = m y + q
    line.point = Eigen::Vector2d(m * along_mid + q, along_mid);
    line.direction = Eigen::Vector2d(m, 1.0).normalized();
  } else {  // y = m x + q
    line.point = Eigen::Vector2d(along_mid, m * along_mid + q);
    line.direction = Eigen::Vector2d(1.0, m).normalized();
  }
  return line;
}

Eigen::Vector2d intersect(const Line2& a, const Line2& b) {
  // a.point + s a.dir = b.point + t b.dir
  Eigen::Matrix2d m;
  m << a.direction.x(), -b.direction.x(), a.direction.y(), -b.direction.y();
  const Eigen::Vector2d st = m.inverse() * (b.point - a.point);
  return a.point + st.x() * a.direction;
}

std::vector<Eigen::Vector2d> measure_polygon_corners(const cv::Mat& image,
                                                     const std::vector<Eigen::Vector2d>& predicted,
                                                     int half_window) {
  const std::size_t n = predicted.size();
  Eigen::Vector2d centre = Eigen::Vector2d::Zero();
  for (const auto& p : predicted) {
    centre += p;
  }
  centre /= static_cast<double>(n);
  std::vector<Line2> edges;
  for (std::size_t i = 0; i < n; ++i) {
    auto line = fit_edge(image, predicted[i], predicted[(i + 1) % n], centre, half_window);
    if (!line) {
      return {};
    }
    edges.push_back(*line);
  }
  std::vector<Eigen::Vector2d> corners;
  for (std::size_t i = 0; i < n; ++i) {
    corners.push_back(intersect(edges[(i + n - 1) % n], edges[i]));
  }
  return corners;
}

double ramp_width_px(const cv::Mat& image, int row, int c0, int c1) {
  auto at = [&](int c) { return static_cast<double>(image.at<std::uint8_t>(row, c)); };
  const double a = at(c0);
  const double b = at(c1 - 1);
  const double contrast = std::abs(b - a);
  const double lo = std::min(a, b) + 0.2 * contrast;
  const double hi = std::max(a, b) - 0.2 * contrast;
  double n = 0.0;
  double sx = 0.0;
  double sy = 0.0;
  double sxx = 0.0;
  double sxy = 0.0;
  double steepest = 0.0;
  for (int c = c0; c < c1; ++c) {
    const double v = at(c);
    if (c + 1 < c1) {
      steepest = std::max(steepest, std::abs(at(c + 1) - v));
    }
    if (v >= lo && v <= hi) {
      n += 1.0;
      sx += c;
      sy += v;
      sxx += static_cast<double>(c) * c;
      sxy += c * v;
    }
  }
  if (n >= 3.0) {
    const double slope = (n * sxy - sx * sy) / (n * sxx - sx * sx);
    return contrast / std::abs(slope);
  }
  return steepest > 0.0 ? contrast / steepest : 0.0;
}

}  // namespace cell::render::testing
