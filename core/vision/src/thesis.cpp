#include "cell/vision/thesis.hpp"

#include <fmt/format.h>

#include <algorithm>
#include <cmath>

#include "cell/vision/planar_7545.hpp"
#include "support.hpp"

namespace cell::vision {
namespace {

using detail::invalid;

int dist2(const ThesisPixel& a, const ThesisPixel& b) {
  const int dx = a.x() - b.x();
  const int dy = a.y() - b.y();
  return dx * dx + dy * dy;
}

double dist(const ThesisPixel& a, const ThesisPixel& b) { return std::sqrt(dist2(a, b)); }

/// Distance of p from the line through a and b (eq. 2.18/2.19).
double line_distance(const ThesisPixel& a, const ThesisPixel& b, const ThesisPixel& p) {
  const double la = b.y() - a.y();
  const double lb = a.x() - b.x();
  const double lc = -(la * a.x() + lb * a.y());
  const double norm = std::hypot(la, lb);
  return norm > 0.0 ? std::abs(la * p.x() + lb * p.y() + lc) / norm : dist(a, p);
}

}  // namespace

Status ThesisOptions::validate() const {
  if (threshold < 1 || threshold > 255) {
    return invalid(fmt::format("thesis.threshold must be in 1..255, got {}", threshold));
  }
  if (!(epsilon_px > 0.0)) {
    return invalid(fmt::format("thesis.epsilon_px must be > 0, got {}", epsilon_px));
  }
  if (lookback_px < 1 || merge_prefix_px < 1 || min_skeleton_px < 1) {
    return invalid("thesis.lookback_px, merge_prefix_px and min_skeleton_px must be >= 1");
  }
  if (max_groups < 1 || max_objects < 1) {
    return invalid("thesis.max_groups and max_objects must be >= 1");
  }
  if (!(corner_exclusion_px > 0.0)) {
    return invalid(
        fmt::format("thesis.corner_exclusion_px must be > 0, got {}", corner_exclusion_px));
  }
  if (first_row < 0 || last_row < first_row) {
    return invalid(fmt::format("thesis rows {}..{} are not a range", first_row, last_row));
  }
  if (!(camera_height_mm > 0.0) || !(part_height_mm >= 0.0) ||
      !(part_height_mm < camera_height_mm)) {
    return invalid(
        fmt::format("thesis.part_height_mm must be in [0, camera_height_mm = {}), "
                    "got {}",
                    camera_height_mm, part_height_mm));
  }
  if (!(aspect > 0.0)) {
    return invalid(fmt::format("thesis.aspect must be > 0, got {}", aspect));
  }
  if (!(circle_spread > 0.0 && square_tolerance > 0.0 && rectangle_tolerance > 0.0 &&
        triangle_line_px > 0.0 && triangle_corner_px > 0.0)) {
    return invalid("thesis shape tolerances must be > 0");
  }
  return ok_status();
}

std::vector<ThesisPixel> thesis_object_pixels(const cv::Mat& image, const ThesisOptions& options) {
  std::vector<ThesisPixel> out;
  const int last = std::min(options.last_row, image.rows - 1);
  for (int y = std::max(0, options.first_row); y <= last; ++y) {
    const std::uint8_t* row = image.ptr<std::uint8_t>(y);
    for (int x = 0; x < image.cols; ++x) {
      if (row[x] < options.threshold) {
        out.emplace_back(x, y);
      }
    }
  }
  return out;
}

std::vector<std::vector<ThesisPixel>> thesis_group(const std::vector<ThesisPixel>& pixels,
                                                   const ThesisOptions& options,
                                                   int* dropped_pixels) {
  std::vector<std::vector<ThesisPixel>> groups;
  int dropped = 0;
  if (pixels.empty()) {
    if (dropped_pixels != nullptr) {
      *dropped_pixels = 0;
    }
    return groups;
  }
  // Integer squared distances decide exactly as the code's sqrt(pow(..)) <= 20 does.
  const double e = options.epsilon_px;
  const int eps2 = static_cast<int>(std::floor(e * e + 1e-9));
  const std::size_t lookback = static_cast<std::size_t>(options.lookback_px);
  auto recent_match = [&](const std::vector<ThesisPixel>& g, const ThesisPixel& p) {
    const std::size_t from = g.size() > lookback ? g.size() - lookback : 0;
    for (std::size_t k = from; k < g.size(); ++k) {  // oldest of the recent ones first
      if (dist2(g[k], p) <= eps2) {
        return true;
      }
    }
    return false;
  };
  groups.push_back({pixels.front()});
  std::size_t current = 0;
  for (std::size_t i = 1; i < pixels.size(); ++i) {
    const ThesisPixel& p = pixels[i];
    // 1. the current group's last pixel, 2. its recent pixels,
    if (dist2(groups[current].back(), p) <= eps2 || recent_match(groups[current], p)) {
      groups[current].push_back(p);
      continue;
    }
    // 3. the other groups' recent pixels (the first match wins and becomes current),
    bool joined = false;
    for (std::size_t g = 0; g < groups.size(); ++g) {
      if (g != current && recent_match(groups[g], p)) {
        groups[g].push_back(p);
        current = g;
        joined = true;
        break;
      }
    }
    if (joined) {
      continue;
    }
    // 4. a new group (p[30][5]: the code overflowed beyond 30; we drop and count).
    if (static_cast<int>(groups.size()) < options.max_groups) {
      groups.push_back({p});
      current = groups.size() - 1;
    } else {
      ++dropped;
    }
  }
  if (dropped_pixels != nullptr) {
    *dropped_pixels = dropped;
  }
  return groups;
}

std::vector<ThesisPixel> thesis_skeleton(const std::vector<ThesisPixel>& group) {
  std::vector<ThesisPixel> out;
  const std::size_t n = group.size();
  for (std::size_t k = 0; k < n; ++k) {
    const bool first = k == 0 || group[k - 1].y() != group[k].y();
    const bool last = k + 1 == n || group[k + 1].y() != group[k].y();
    if (first || last) {
      out.push_back(group[k]);
    }
  }
  return out;
}

std::vector<std::vector<ThesisPixel>> thesis_merge(std::vector<std::vector<ThesisPixel>> skel,
                                                   const ThesisOptions& options,
                                                   ThesisReport* report) {
  const double e = options.epsilon_px;
  const int eps2 = static_cast<int>(std::floor(e * e + 1e-9));
  const std::size_t prefix = static_cast<std::size_t>(options.merge_prefix_px);
  std::vector<bool> gone(skel.size(), false);
  for (std::size_t g = 0; g < skel.size(); ++g) {
    if (gone[g]) {
      continue;
    }
    for (std::size_t i = g + 1; i < skel.size(); ++i) {
      if (gone[i] || skel[i].empty()) {
        continue;
      }
      // A pixel of g within epsilon of one of the first `prefix` pixels of i: i joins g.
      bool near = false;
      for (std::size_t b = 0; b < std::min(prefix, skel[i].size()) && !near; ++b) {
        for (const ThesisPixel& a : skel[g]) {
          if (dist2(a, skel[i][b]) <= eps2) {
            near = true;
            break;
          }
        }
      }
      if (near) {
        skel[g].insert(skel[g].end(), skel[i].begin(), skel[i].end());
        skel[i].clear();
        gone[i] = true;
      }
    }
  }
  std::vector<std::vector<ThesisPixel>> out;
  for (std::size_t g = 0; g < skel.size(); ++g) {
    if (gone[g]) {
      continue;
    }
    if (static_cast<int>(skel[g].size()) < options.min_skeleton_px) {
      if (report != nullptr) {
        ++report->dirt_groups;
      }
      continue;
    }
    if (static_cast<int>(out.size()) >= options.max_objects) {
      if (report != nullptr) {
        ++report->dropped_objects;
      }
      continue;
    }
    out.push_back(std::move(skel[g]));
  }
  return out;
}

std::vector<ThesisPixel> thesis_farthest_points(const std::vector<ThesisPixel>& skeleton,
                                                const Eigen::Vector2i& centre,
                                                int count,
                                                double exclusion_px) {
  std::vector<ThesisPixel> corners;
  for (int i = 0; i < count; ++i) {
    double best = 0.0;
    std::optional<ThesisPixel> found;
    for (const ThesisPixel& p : skeleton) {
      const double d = dist(p, centre);
      if (d > best) {
        bool excluded = false;
        for (const ThesisPixel& c : corners) {
          if (dist(p, c) <= exclusion_px) {
            excluded = true;
            break;
          }
        }
        if (!excluded) {
          best = d;
          found = p;
        }
      }
    }
    if (!found) {
      break;
    }
    corners.push_back(*found);
  }
  return corners;
}

std::array<ThesisPixel, 4> thesis_order_corners(const std::vector<ThesisPixel>& corners) {
  std::array<ThesisPixel, 4> in{corners[0], corners[1], corners[2], corners[3]};
  std::size_t top = 0;
  for (std::size_t i = 1; i < 4; ++i) {
    if (in[top].y() < in[i].y()) {  // the first corner of largest j
      top = i;
    }
  }
  std::swap(in[0], in[top]);
  double fr = 0.0;
  double nr = 150.0;  // the code's initial "nearest"; below we fall back if none is nearer
  std::size_t far = 1;
  std::size_t nearest = 0;
  for (std::size_t i = 1; i < 4; ++i) {
    const double d = dist(in[0], in[i]);
    if (d > fr) {
      fr = d;
      far = i;
    }
    if (d < nr) {
      nr = d;
      nearest = i;
    }
  }
  if (nearest == 0) {  // no corner within 150 px (the code would read a stale index)
    double best = 1e300;
    for (std::size_t i = 1; i < 4; ++i) {
      if (i != far && dist(in[0], in[i]) < best) {
        best = dist(in[0], in[i]);
        nearest = i;
      }
    }
  }
  std::array<ThesisPixel, 4> out;
  out[0] = in[0];
  out[2] = in[nearest];
  out[3] = in[far];
  for (std::size_t i = 1; i < 4; ++i) {
    if (i != nearest && i != far) {
      out[1] = in[i];
    }
  }
  return out;
}

std::optional<std::array<ThesisPixel, 3>> thesis_triangle(const std::vector<ThesisPixel>& skeleton,
                                                          const Eigen::Vector2i& box_min,
                                                          const Eigen::Vector2i& box_max,
                                                          const ThesisOptions& options) {
  if (skeleton.size() < 3) {
    return std::nullopt;
  }
  // First corner: a skeleton point at one of the external rectangle's corners.
  const std::array<ThesisPixel, 4> box{
      ThesisPixel(box_max.x(), box_max.y()), ThesisPixel(box_min.x(), box_max.y()),
      ThesisPixel(box_max.x(), box_min.y()), ThesisPixel(box_min.x(), box_min.y())};
  std::optional<ThesisPixel> first;
  double best = options.triangle_corner_px;
  for (const ThesisPixel& p : skeleton) {
    for (const ThesisPixel& c : box) {
      const double d = dist(p, c);
      if (d <= best) {
        best = d;
        first = p;
      }
    }
  }
  if (!first) {
    return std::nullopt;
  }
  // Second: the farthest skeleton point from the first (eq. 2.17).
  ThesisPixel second = *first;
  double ld = 0.0;
  for (const ThesisPixel& p : skeleton) {
    if (dist(p, *first) > ld) {
      ld = dist(p, *first);
      second = p;
    }
  }
  // Third: the farthest from the line through them (eq. 2.18, 2.19).
  ThesisPixel third = *first;
  double lmax = 0.0;
  for (const ThesisPixel& p : skeleton) {
    const double d = line_distance(*first, second, p);
    if (d > lmax) {
      lmax = d;
      third = p;
    }
  }
  if (lmax < 2.0) {
    return std::nullopt;
  }
  const std::array<ThesisPixel, 3> t{*first, second, third};
  // Check (eq. 2.20): from the middle of the longest side, the farthest skeleton point more
  // than a third of the shortest side from every corner must lie on a side.
  std::array<double, 3> side{dist(t[0], t[1]), dist(t[1], t[2]), dist(t[2], t[0])};
  const std::size_t longest =
      static_cast<std::size_t>(std::max_element(side.begin(), side.end()) - side.begin());
  const double r = *std::min_element(side.begin(), side.end()) / 3.0;
  const Eigen::Vector2d mid =
      0.5 * (t[longest].cast<double>() + t[(longest + 1) % 3].cast<double>());
  std::optional<ThesisPixel> t4;
  double far = 0.0;
  for (const ThesisPixel& p : skeleton) {
    bool clear = true;
    for (const ThesisPixel& c : t) {
      if (dist(p, c) <= r) {
        clear = false;
        break;
      }
    }
    const double d = (p.cast<double>() - mid).norm();
    if (clear && d > far) {
      far = d;
      t4 = p;
    }
  }
  if (!t4) {
    return std::nullopt;
  }
  for (std::size_t k = 0; k < 3; ++k) {
    if (line_distance(t[k], t[(k + 1) % 3], *t4) <= options.triangle_line_px) {
      return t;
    }
  }
  return std::nullopt;
}

Result<std::vector<ThesisObject>> thesis_locate(const cv::Mat& image,
                                                const ThesisOptions& options,
                                                ThesisReport* report) {
  if (image.empty() || image.type() != CV_8UC1) {
    return invalid("the thesis pipeline needs a non-empty 8-bit grey image");
  }
  CELL_TRY(options.validate());
  ThesisReport local;
  ThesisReport& rep = report != nullptr ? *report : local;
  rep = ThesisReport{};
  const std::vector<ThesisPixel> pixels = thesis_object_pixels(image, options);
  rep.object_pixels = static_cast<int>(pixels.size());
  const auto groups = thesis_group(pixels, options, &rep.dropped_pixels);
  rep.partial_groups = static_cast<int>(groups.size());
  std::vector<std::vector<ThesisPixel>> skeletons;
  skeletons.reserve(groups.size());
  for (const auto& g : groups) {
    skeletons.push_back(thesis_skeleton(g));
  }
  const auto objects = thesis_merge(std::move(skeletons), options, &rep);
  std::vector<ThesisObject> out;
  const Eigen::Vector2i& c0 = options.centre_px;
  const double h = options.part_height_mm;
  const double dct = options.camera_height_mm;
  for (const auto& skel : objects) {
    ThesisObject o;
    o.skeleton_px = static_cast<int>(skel.size());
    o.box_min = Eigen::Vector2i(image.cols, image.rows);
    o.box_max = Eigen::Vector2i(0, 0);
    for (const ThesisPixel& p : skel) {
      o.box_min = o.box_min.cwiseMin(p);
      o.box_max = o.box_max.cwiseMax(p);
    }
    o.box_centre =
        Eigen::Vector2i((o.box_min.x() + o.box_max.x()) / 2, (o.box_min.y() + o.box_max.y()) / 2);
    if (options.shape_tests) {
      if (auto tri = thesis_triangle(skel, o.box_min, o.box_max, options)) {
        o.shape = ShapeKind::kTriangle;
        Eigen::Vector2i sum = Eigen::Vector2i::Zero();
        Eigen::Vector2i sum_raw = Eigen::Vector2i::Zero();
        for (const ThesisPixel& c : *tri) {
          o.corners_raw.push_back(c);
          const ThesisPixel corrected = thesis_parallax_int(c, c0, h, dct);
          o.corners.push_back(corrected);
          sum += corrected;
          sum_raw += c;
        }
        o.centre = sum / 3;
        o.centre_raw = sum_raw / 3;
        out.push_back(std::move(o));
        continue;
      }
    }
    const auto found = thesis_farthest_points(skel, o.box_centre, 4, options.corner_exclusion_px);
    if (found.size() < 4) {
      ++rep.not_rectangles;
      continue;
    }
    const auto raw = thesis_order_corners(found);
    // The code corrects, then orders; the order only depends on the positions, which the
    // correction barely moves, so we order the raw corners and correct each in place (the
    // raw and corrected lists stay in the same slots).
    std::array<ThesisPixel, 4> corrected;
    Eigen::Vector2i sum = Eigen::Vector2i::Zero();
    Eigen::Vector2i sum_raw = Eigen::Vector2i::Zero();
    for (std::size_t k = 0; k < 4; ++k) {
      corrected[k] = thesis_parallax_int(raw[k], c0, h, dct);
      sum += corrected[k];
      sum_raw += raw[k];
    }
    o.corners_raw.assign(raw.begin(), raw.end());
    o.corners.assign(corrected.begin(), corrected.end());
    o.centre = sum / 4;  // eq. 2.11, integer division
    o.centre_raw = sum_raw / 4;
    const double l1 = dist(raw[0], raw[1]);
    const double l2 = dist(raw[2], raw[3]);
    const double w1 = dist(raw[0], raw[2]);
    const double w2 = dist(raw[1], raw[3]);
    if (options.shape_tests) {
      // Eq. 2.14: a fifth farthest sample, r = 1/3 of the width of the (external) rectangle;
      // five equal radii: a circle. Our addition: a circle's external rectangle is a square.
      // The skeleton holds only the row ends, so a rectangle near 0 degrees offers only its
      // short sides, whose points are all about as far from the centre as its corners and
      // would pass eq. 2.14 alone.
      const Eigen::Vector2i box = o.box_max - o.box_min;
      const double box_width = std::min(box.x(), box.y()) + 1.0;
      const bool square_box =
          std::abs(box.x() - box.y()) <= options.circle_spread * std::max(box.x(), box.y()) + 2;
      const auto fifth = thesis_farthest_points(skel, o.box_centre, 5, box_width / 3.0);
      if (square_box && fifth.size() == 5) {
        std::array<double, 5> radii{};
        for (std::size_t k = 0; k < 5; ++k) {
          radii[k] = dist(fifth[k], o.box_centre);
        }
        const auto [mn, mx] = std::minmax_element(radii.begin(), radii.end());
        double mean = 0.0;
        for (double r : radii) {
          mean += r / 5.0;
        }
        if (mean > 0.0 && (*mx - *mn) / mean < options.circle_spread) {
          o.shape = ShapeKind::kCircle;
          o.radius_px = mean;
          o.corners_raw.clear();
          o.corners.clear();
          o.centre_raw = o.box_centre;
          o.centre = thesis_parallax_int(o.box_centre, c0, h, dct);
          out.push_back(std::move(o));
          continue;
        }
      }
      // Eq. 2.13: opposite sides equal, else not a rectangle (dirt, §4.8).
      // "Approximately equal": within the tolerance of the longest side (a corner picked a
      // pixel or two off changes a 20 px short side by 10 %).
      const double longest = std::max({l1, l2, w1, w2});
      if (std::abs(l1 - l2) > options.rectangle_tolerance * longest ||
          std::abs(w1 - w2) > options.rectangle_tolerance * longest) {
        ++rep.not_rectangles;
        continue;
      }
      // Eq. 2.16: |1-2| ~ |1-3| is a square.
      if (std::abs(l1 - w1) <= options.square_tolerance * std::max(l1, w1)) {
        o.shape = ShapeKind::kSquare;
      }
    }
    o.alpha_deg =
        thesis_alpha_deg(corrected[0].cast<double>(), corrected[1].cast<double>(),
                         corrected[2].cast<double>(), corrected[3].cast<double>(), options.aspect);
    out.push_back(std::move(o));
  }
  return out;
}

}  // namespace cell::vision
