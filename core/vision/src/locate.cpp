#include "cell/vision/locate.hpp"

#include <fmt/format.h>

#include <algorithm>
#include <cmath>
#include <numbers>
#include <opencv2/imgproc.hpp>
#include <optional>

#include "cell/geometry/angles.hpp"
#include "cell/vision/planar_7545.hpp"
#include "fit.hpp"
#include "segmentation.hpp"
#include "support.hpp"

namespace cell::vision {
namespace detail {

/// A sub-pixel crossing of a blob's outline, found along a row (dir 0: bright to the left, 1:
/// bright to the right) or a column (2: bright above, 3: bright below). In detail rather than
/// in the anonymous namespace: Locator::Impl holds them.
struct Sample {
  Eigen::Vector2d px;
  std::uint8_t dir = 0;
};

}  // namespace detail

namespace {

using detail::Blob;
using detail::Circle2;
using detail::invalid;
using detail::Line2;
using detail::perp;
using detail::Run;
using detail::Sample;
using geometry::kPi;

/// A crossing along a row (column) is used for a side whose normal is within 55 degrees of
/// the row (column): beyond, the edge's spread across one pixel strip exceeds the window.
constexpr double kScanCos = 0.5736;  // cos 55 deg

Eigen::Vector2d scan_outward(std::uint8_t dir) {
  switch (dir) {
    case 0:
      return {-1.0, 0.0};
    case 1:
      return {1.0, 0.0};
    case 2:
      return {0.0, -1.0};
    default:
      return {0.0, 1.0};
  }
}

/// Whether a crossing of scan direction `dir` can measure a side of outward normal `n` (pixel).
bool scan_fits(std::uint8_t dir, const Eigen::Vector2d& n) {
  const Eigen::Vector2d s = scan_outward(dir);
  return s.dot(n) >= kScanCos;
}

struct Heights {
  double top = 0.0;
  double base = 0.0;
};

/// The pixels of one part candidate: a whole blob or a piece split from one.
struct Region {
  std::vector<cv::Point2f> outline;  ///< run ends (pixel edges), sorted by (y, x)
  std::vector<cv::Point2f> hull;     ///< their convex hull (set by prepare())
  cv::RotatedRect rect;              ///< the hull's minimum-area rectangle
  double area_px = 0.0;
  Eigen::Vector2d centroid = Eigen::Vector2d::Zero();
  std::vector<int> samples;  ///< indices into the blob's samples
  int label = 0;             ///< id in the frame's label image (grip test)
};

/// A fitted model, before it becomes a Detection.
struct Fit {
  ShapeKind shape = ShapeKind::kRectangle;
  std::vector<Eigen::Vector2d> corners_plane;  ///< top-face corners (rect 4, triangle 3)
  Eigen::Vector2d centre_plane = Eigen::Vector2d::Zero();
  double angle_plane = 0.0;  ///< major axis (rect), first side (triangle), 0 (circle)
  double length = 0.0;       ///< plane units
  double width = 0.0;
  double radius = 0.0;
  Heights heights;
  double rms_px = 0.0;
  double coverage = 0.0;
  double area_ratio = 1.0;
  int inliers = 0;
  const PartSpec* spec = nullptr;
  double class_score = 1.0;
  bool matched = false;
};

/// Andrew's monotone chain on points already sorted by (y, x) (a blob's run ends are): O(n).
void hull_of_sorted(const std::vector<cv::Point2f>& pts, std::vector<cv::Point2f>& hull) {
  hull.clear();
  if (pts.size() < 3) {
    hull = pts;
    return;
  }
  auto cross = [](const cv::Point2f& o, const cv::Point2f& a, const cv::Point2f& b) {
    return static_cast<double>(a.x - o.x) * (b.y - o.y) -
           static_cast<double>(a.y - o.y) * (b.x - o.x);
  };
  hull.resize(2 * pts.size());
  std::size_t k = 0;
  for (std::size_t i = 0; i < pts.size(); ++i) {
    while (k >= 2 && cross(hull[k - 2], hull[k - 1], pts[i]) <= 0) {
      --k;
    }
    hull[k++] = pts[i];
  }
  for (std::size_t i = pts.size() - 1, t = k + 1; i-- > 0;) {
    while (k >= t && cross(hull[k - 2], hull[k - 1], pts[i]) <= 0) {
      --k;
    }
    hull[k++] = pts[i];
  }
  hull.resize(k - 1);
}

/// Hull and its minimum-area rectangle; false when the region is degenerate.
bool prepare(Region& region) {
  if (region.outline.size() < 3) {
    return false;
  }
  hull_of_sorted(region.outline, region.hull);
  if (region.hull.size() < 3) {
    return false;
  }
  region.rect = cv::minAreaRect(region.hull);
  return region.rect.size.width > 0.0F && region.rect.size.height > 0.0F;
}

double quad_area(const std::vector<Eigen::Vector2d>& polygon) {
  return std::abs(detail::signed_area(polygon));
}

}  // namespace

// ---------------------------------------------------------------------------------------------
// Names, options, angles.

std::string_view to_string(Pipeline pipeline) noexcept {
  return pipeline == Pipeline::kFast ? "fast" : "thesis";
}

Result<Pipeline> pipeline_from_string(std::string_view text) {
  if (text == "fast") {
    return Pipeline::kFast;
  }
  if (text == "thesis") {
    return Pipeline::kThesis;
  }
  return invalid(fmt::format("unknown pipeline '{}' (fast or thesis)", text));
}

std::string_view to_string(ThresholdMode mode) noexcept {
  return mode == ThresholdMode::kFixed ? "fixed" : "adaptive";
}

Status SegmentationOptions::validate() const {
  if (fixed_threshold < 1 || fixed_threshold > 255) {
    return invalid(
        fmt::format("segmentation.fixed_threshold must be in 1..255, got {}", fixed_threshold));
  }
  if (!(adaptive_ratio > 0.05 && adaptive_ratio < 0.95)) {
    return invalid(
        fmt::format("segmentation.adaptive_ratio must be in (0.05, 0.95), got {}", adaptive_ratio));
  }
  if (block_px < 8 || block_px > 512 || (block_px & (block_px - 1)) != 0) {
    return invalid(
        fmt::format("segmentation.block_px must be a power of two in 8..512, got {}", block_px));
  }
  if (min_area_px < 4) {
    return invalid(fmt::format("segmentation.min_area_px must be >= 4, got {}", min_area_px));
  }
  return ok_status();
}

Status LocateOptions::validate() const {
  CELL_TRY(segmentation.validate());
  CELL_TRY(thesis.validate());
  if (!(class_tolerance_mm >= 0.0) || !(class_tolerance_rel >= 0.0) ||
      !(class_tolerance_mm + class_tolerance_rel > 0.0)) {
    return invalid(
        fmt::format("class_tolerance_mm and class_tolerance_rel must be >= 0 and not "
                    "both 0, got {} and {}",
                    class_tolerance_mm, class_tolerance_rel));
  }
  if (!(default_top_mm > 0.0) || !(default_base_mm >= 0.0) || !(default_base_mm < default_top_mm)) {
    return invalid(fmt::format("default_top_mm must be > default_base_mm >= 0, got {} and {}",
                               default_top_mm, default_base_mm));
  }
  if (edge_window_px < 2 || edge_window_px > 8) {
    return invalid(fmt::format("edge_window_px must be in 2..8, got {}", edge_window_px));
  }
  if (crossing_stride < 1 || crossing_stride > 4) {
    return invalid(fmt::format("crossing_stride must be in 1..4, got {}", crossing_stride));
  }
  if (!(max_fit_rms_px > 0.0)) {
    return invalid(fmt::format("max_fit_rms_px must be > 0, got {}", max_fit_rms_px));
  }
  for (const GraspModel& g : grasps) {
    CELL_TRY(g.validate());
  }
  return ok_status();
}

double fold_angle(double angle_rad, int order) noexcept {
  if (order == 0) {
    return 0.0;
  }
  if (order == 1) {
    double a = std::remainder(angle_rad, 2.0 * kPi);
    return a <= -kPi ? a + 2.0 * kPi : a;
  }
  const double period = 2.0 * kPi / order;
  double a = std::fmod(angle_rad, period);
  if (a < 0.0) {
    a += period;
  }
  return a >= period ? a - period : a;
}

double fold_angle_centred(double angle_rad, int order) noexcept {
  if (order == 0) {
    return 0.0;
  }
  if (order == 1) {
    return fold_angle(angle_rad, 1);
  }
  const double period = 2.0 * kPi / order;
  double a = fold_angle(angle_rad, order);
  if (a > period / 2.0) {
    a -= period;
  }
  return a;
}

double angle_error(double a_rad, double b_rad, int order) noexcept {
  if (order == 0) {
    return 0.0;
  }
  const double period = order == 1 ? 2.0 * kPi : 2.0 * kPi / order;
  double d = std::fmod(std::abs(a_rad - b_rad), period);
  return std::min(d, period - d);
}

// ---------------------------------------------------------------------------------------------
// The locator.

struct Locator::Impl {
  LocateOptions options;
  detail::Segmenter seg;
  std::vector<Sample> samples;
  /// Each sample's plane point as a function of the height it is seen at (PixelMapper::
  /// plane_line): mapped once per blob, evaluated at the top or the walls' base per side.
  std::vector<PixelMapper::PlaneLine> sample_lines;
  std::vector<unsigned char> sample_mapped;
  std::vector<double> scratch;
  std::vector<int> row_first;          // per blob row: index of its first run
  cv::Mat labels;                      // CV_32SC1, frame ids for the grip test
  std::vector<int> blob_of_detection;  // per detection of the frame (fast pipeline)

  // Per frame.
  const cv::Mat* image = nullptr;
  const PixelMapper* mapper = nullptr;
  Eigen::Vector2d nadir_px = Eigen::Vector2d::Zero();
  bool have_nadir = false;
  int next_label = 1;

  Result<LocateResult> run(const cv::Mat& img, const PixelMapper& m, Pipeline pipeline);
  void run_fast(LocateResult& result);
  void run_thesis(LocateResult& result);

  int grey(int x, int y) const { return image->ptr<std::uint8_t>(y)[x]; }
  double dark_level(const Run* runs, int count);
  void collect_samples(const Run* runs, int count, double dark, int stride);
  void map_samples();
  void process_blob(const Blob& blob, LocateResult& result, std::vector<int>& owners);

  std::optional<Fit> fit_quad_model(const Region& region, const Heights& h);
  std::optional<Fit> fit_circle_model(const Region& region, const Heights& h);
  std::optional<Fit> fit_triangle_model(const Region& region, const Heights& h);
  std::optional<Fit> fit_region(Region& region);
  bool explained(const Fit& fit) const;
  void classify(Fit& fit) const;
  Detection to_detection(const Fit& fit) const;
  Detection unknown_detection(const Region& region) const;
  std::vector<Region> split(const Blob& blob, double dark);
  bool has_seam(const Blob& blob, double dark) const;
  void test_grips(LocateResult& result, const std::vector<int>& owners);

  std::optional<Eigen::Vector2d> plane(const Eigen::Vector2d& px, double h) const {
    auto p = mapper->to_plane(px, h);
    return p ? std::optional<Eigen::Vector2d>(*p) : std::nullopt;
  }
  std::optional<Eigen::Vector2d> pixel(const Eigen::Vector2d& q, double h) const {
    auto p = mapper->to_pixel(q, h);
    return p ? std::optional<Eigen::Vector2d>(*p) : std::nullopt;
  }
  /// Whether the wall behind a side (outward normal n_px at point p_px, pixels) faces the camera.
  bool wall_visible(const Eigen::Vector2d& p_px, const Eigen::Vector2d& n_px) const {
    return have_nadir && (nadir_px - p_px).dot(n_px) > 0.0;
  }
};

Result<Locator> Locator::create(LocateOptions options) {
  CELL_TRY(options.validate());
  auto impl = std::make_unique<Impl>();
  impl->options = std::move(options);
  return Locator(std::move(impl));
}

Locator::Locator(std::unique_ptr<Impl> impl) : impl_(std::move(impl)) {}
Locator::Locator(Locator&&) noexcept = default;
Locator& Locator::operator=(Locator&&) noexcept = default;
Locator::~Locator() = default;

const LocateOptions& Locator::options() const noexcept { return impl_->options; }

Result<LocateResult> Locator::locate(const cv::Mat& image, const PixelMapper& mapper) {
  return impl_->run(image, mapper, impl_->options.pipeline);
}

Result<LocateResult> Locator::locate(const cv::Mat& image,
                                     const PixelMapper& mapper,
                                     Pipeline pipeline) {
  return impl_->run(image, mapper, pipeline);
}

Result<LocateResult> Locator::Impl::run(const cv::Mat& img,
                                        const PixelMapper& m,
                                        Pipeline pipeline) {
  if (img.empty() || img.type() != CV_8UC1) {
    return invalid(fmt::format("vision needs a non-empty 8-bit grey image, got {} x {} of type {}",
                               img.cols, img.rows, img.type()));
  }
  if (m.width_px() > 0 && (img.cols != m.width_px() || img.rows != m.height_px())) {
    const std::string camera =
        m.calibration() ? m.calibration()->camera_id : std::string("this camera");
    return invalid(fmt::format("image is {} x {} px but the calibration of '{}' is for {} x {}",
                               img.cols, img.rows, camera, m.width_px(), m.height_px()));
  }
  image = &img;
  mapper = &m;
  have_nadir = false;
  if (m.metric()) {
    if (auto n = m.to_pixel(m.nadir(), 0.0)) {
      nadir_px = *n;
      have_nadir = true;
    }
  }
  LocateResult result;
  result.report.pipeline = pipeline;
  result.report.mapping = m.describe();
  if (pipeline == Pipeline::kThesis) {
    run_thesis(result);
  } else {
    run_fast(result);
  }
  image = nullptr;
  mapper = nullptr;
  return result;
}

// ---------------------------------------------------------------------------------------------
// Fast pipeline.

double Locator::Impl::dark_level(const Run* runs, int count) {
  // The body's grey: the mean of the middle of the long runs (well inside the part, where the
  // top face is one uniform grey); short blobs: the darkest fifth of their pixels.
  const int w = options.edge_window_px;
  double sum = 0.0;
  int n = 0;
  for (int i = 0; i < count; ++i) {
    const Run& r = runs[i];
    if (r.x1 - r.x0 + 1 >= 2 * w + 3) {
      const std::uint8_t* row = image->ptr<std::uint8_t>(r.y);
      const int mid = (r.x0 + r.x1) / 2;
      sum += row[mid - 1] + row[mid] + row[mid + 1];
      n += 3;
    }
  }
  if (n >= 9) {
    return sum / n;
  }
  scratch.clear();
  for (int i = 0; i < count; ++i) {
    const std::uint8_t* row = image->ptr<std::uint8_t>(runs[i].y);
    for (int x = runs[i].x0; x <= runs[i].x1; ++x) {
      scratch.push_back(row[x]);
    }
  }
  const auto q = scratch.begin() + static_cast<std::ptrdiff_t>(scratch.size() / 5);
  std::nth_element(scratch.begin(), q, scratch.end());
  return *q;
}

void Locator::Impl::map_samples() {
  sample_lines.resize(samples.size());
  sample_mapped.resize(samples.size());
  for (std::size_t i = 0; i < samples.size(); ++i) {
    auto line = mapper->plane_line(samples[i].px);
    sample_mapped[i] = line ? 1 : 0;
    if (line) {
      sample_lines[i] = *line;
    }
  }
}

void Locator::Impl::collect_samples(const Run* runs, int count, double dark, int stride) {
  // A crossing is kept only with clean table outside (its outer pixels at the local table
  // level) and part body inside (as dark as the body): crossings through IC leads, their
  // glints, or a neighbour's edge fail one of the two and are left out. Only the outline's
  // pixels are visited: run ends along the rows, and along the columns the pixels of a run
  // that no run of the row above (below) covers.
  samples.clear();
  if (count == 0) {
    return;
  }
  const int w = options.edge_window_px;
  const int width = image->cols;
  const int height = image->rows;
  // The table level over the blob: bilinear between its box corners (the lighting varies by a
  // few percent across the whole image, smoothly).
  int x_min = width;
  int x_max = 0;
  const int y_min = runs[0].y;
  const int y_max = runs[count - 1].y;
  for (int i = 0; i < count; ++i) {
    x_min = std::min(x_min, runs[i].x0);
    x_max = std::max(x_max, runs[i].x1);
  }
  const double b00 = seg.background(x_min, y_min);
  const double b10 = seg.background(x_max, y_min);
  const double b01 = seg.background(x_min, y_max);
  const double b11 = seg.background(x_max, y_max);
  const double sx = x_max > x_min ? 1.0 / (x_max - x_min) : 0.0;
  const double sy = y_max > y_min ? 1.0 / (y_max - y_min) : 0.0;
  auto table_at = [&](double x, double y) {
    const double tx = std::clamp((x - x_min) * sx, 0.0, 1.0);
    const double ty = std::clamp((y - y_min) * sy, 0.0, 1.0);
    return (1 - ty) * ((1 - tx) * b00 + tx * b10) + ty * ((1 - tx) * b01 + tx * b11);
  };
  // pos = first - sign * 0.5 + sign * (bright length in the window); false when not clean.
  auto measure = [&](auto&& at, int first, int sign, double b_model, double& pos) {
    const double contrast = b_model - dark;
    if (!(contrast > 20.0)) {
      return false;
    }
    const double b_loc = 0.5 * (at(0) + at(1));
    if (std::abs(b_loc - b_model) > std::max(6.0, 0.07 * contrast)) {
      return false;
    }
    const double dark_max = dark + 0.25 * contrast;
    for (int k = w + 1; k < 2 * w; ++k) {
      if (at(k) > dark_max) {
        return false;
      }
    }
    double sum = 0.0;
    for (int k = 0; k < 2 * w; ++k) {
      sum += at(k);
    }
    const double bright = (sum - 2 * w * dark) / (b_loc - dark);
    pos = first - sign * 0.5 + sign * bright;
    return true;
  };
  // Runs of each row of the blob (they come in raster order).
  row_first.assign(static_cast<std::size_t>(y_max - y_min) + 2, 0);
  for (int i = 0, y = y_min; i <= count; ++i) {
    const int ry = i < count ? runs[i].y : y_max + 1;
    while (y <= ry && y <= y_max + 1) {
      row_first[static_cast<std::size_t>(y - y_min)] = i;
      ++y;
    }
  }
  auto row_runs = [&](int y, int& begin, int& end) {
    if (y < y_min || y > y_max) {
      begin = end = 0;
      return;
    }
    begin = row_first[static_cast<std::size_t>(y - y_min)];
    end = row_first[static_cast<std::size_t>(y - y_min) + 1];
  };
  auto column_crossing = [&](int x, int y, int sign) {
    // sign -1: bright above (a top crossing), window rows y - w .. y + w - 1, outermost y - w.
    const int first = sign < 0 ? y - w : y + w;
    if (first < 0 || first >= height || y - sign * (w - 1) < 0 || y - sign * (w - 1) >= height) {
      return;
    }
    for (int k = 0; k < w - 1; ++k) {
      const int yy = first - sign * k;
      if (grey(x, yy) < seg.threshold(x, yy)) {
        return;
      }
    }
    double pos = 0.0;
    if (measure([&](int k) { return static_cast<double>(grey(x, first - sign * k)); }, first, -sign,
                table_at(x, first), pos)) {
      samples.push_back({Eigen::Vector2d(x, pos), static_cast<std::uint8_t>(sign < 0 ? 2 : 3)});
    }
  };
  for (int i = 0; i < count; ++i) {
    const Run& r = runs[i];
    const std::uint8_t* row = image->ptr<std::uint8_t>(r.y);
    const bool row_sampled = r.y % stride == 0;
    // Along the row: left end, window x0 - w .. x0 + w - 1.
    if (row_sampled && r.x0 - w >= 0 && r.x1 - r.x0 + 1 >= w) {
      const int first = r.x0 - w;
      bool bright_ok = true;
      for (int k = 0; k < w - 1 && bright_ok; ++k) {
        bright_ok = row[first + k] >= seg.threshold(first + k, r.y);
      }
      double pos = 0.0;
      if (bright_ok && measure([&](int k) { return static_cast<double>(row[first + k]); }, first, 1,
                               table_at(first, r.y), pos)) {
        samples.push_back({Eigen::Vector2d(pos, r.y), 0});
      }
    }
    // Right end, window x1 - w + 1 .. x1 + w (outermost x1 + w).
    if (row_sampled && r.x1 + w < width && r.x1 - r.x0 + 1 >= w) {
      const int first = r.x1 + w;
      bool bright_ok = true;
      for (int k = 0; k < w - 1 && bright_ok; ++k) {
        bright_ok = row[first - k] >= seg.threshold(first - k, r.y);
      }
      double pos = 0.0;
      if (bright_ok && measure([&](int k) { return static_cast<double>(row[first - k]); }, first,
                               -1, table_at(first, r.y), pos)) {
        samples.push_back({Eigen::Vector2d(pos, r.y), 1});
      }
    }
    // Along the columns: the run's pixels not covered by a run of the row above (below).
    for (const int sign : {-1, 1}) {
      int begin = 0;
      int end = 0;
      row_runs(r.y + sign, begin, end);
      int x = r.x0;
      for (int k = begin; k <= end && x <= r.x1; ++k) {
        const int cover0 = k < end ? runs[k].x0 : r.x1 + 1;
        const int cover1 = k < end ? runs[k].x1 : r.x1 + 1;
        const int stop = std::min(r.x1, cover0 - 1);
        for (int xs = x + (stride - x % stride) % stride; xs <= stop; xs += stride) {
          column_crossing(xs, r.y, sign);  // every stride-th column
        }
        x = std::max(stop + 1, cover1 + 1);
      }
    }
  }
}

void Locator::Impl::classify(Fit& fit) const {
  fit.spec = nullptr;
  fit.matched = false;
  if (!mapper->metric() || options.classes.empty()) {
    return;
  }
  double length = fit.length;
  double width = fit.width;
  if (fit.shape == ShapeKind::kCircle) {
    length = width = 2.0 * fit.radius;
  }
  const auto match = options.classes.classify(fit.shape, length, width, options.class_tolerance_mm,
                                              options.class_tolerance_rel);
  if (match) {
    fit.spec = match->spec;
    fit.class_score = match->score;
    fit.matched = true;
  }
}

bool Locator::Impl::explained(const Fit& fit) const {
  if (!(fit.rms_px <= options.max_fit_rms_px)) {
    return false;
  }
  if (!(fit.area_ratio > 0.8 && fit.area_ratio < 1.3)) {
    return false;
  }
  // With sizes in mm and a catalogue, a part must be one of its classes.
  return fit.matched || !mapper->metric() || options.classes.empty();
}

namespace {

/// Enough crossings on the four sides for a quadrilateral: at least two on each side and six on
/// one pair of opposite sides (which share a direction). On a coarse camera (the belt's 2
/// px/mm) a DIP's short sides keep only two or three clean crossings each, and its long sides,
/// between the leads, a few more: the long pair gives the direction (with the short pair, which
/// is square to it for a rectangle), and each short side's two fix its offset.
bool enough_crossings(const std::array<std::vector<Eigen::Vector2d>, 4>& sides) {
  for (const auto& side : sides) {
    if (side.size() < 2) {
      return false;
    }
  }
  return sides[0].size() + sides[2].size() >= 6 || sides[1].size() + sides[3].size() >= 6;
}

}  // namespace

std::optional<Fit> Locator::Impl::fit_quad_model(const Region& region, const Heights& h) {
  if (region.hull.size() < 3) {
    return std::nullopt;
  }
  const int w = options.edge_window_px;
  const double margin = w + 1.5;
  const cv::RotatedRect& rr = region.rect;
  std::array<cv::Point2f, 4> pts;
  rr.points(pts.data());
  std::array<Eigen::Vector2d, 4> p;
  for (std::size_t k = 0; k < 4; ++k) {
    p[k] = Eigen::Vector2d(pts[k].x, pts[k].y);
  }
  if ((p[1] - p[0]).norm() < (p[2] - p[1]).norm()) {
    std::rotate(p.begin(), p.begin() + 1, p.end());  // side 0 (p0 -> p1) is a long side
  }
  // Pixel segments of the outline's four sides (first guess: the rotated bounding box).
  std::array<Eigen::Vector2d, 4> a;
  std::array<Eigen::Vector2d, 4> b;
  for (std::size_t k = 0; k < 4; ++k) {
    a[k] = p[k];
    b[k] = p[(k + 1) % 4];
  }
  Eigen::Vector2d centre_px(rr.center.x, rr.center.y);
  Fit fit;
  fit.shape = ShapeKind::kRectangle;
  fit.heights = h;
  std::array<std::vector<Eigen::Vector2d>, 4> pts_plane;
  std::array<bool, 4> visible{};
  std::optional<std::array<Line2, 4>> lines;
  const bool metric = mapper->metric();
  for (int iteration = 0; iteration < 2; ++iteration) {
    const double tol_assign = iteration == 0 ? 4.5 : 1.5;
    std::array<Eigen::Vector2d, 4> n_px;
    std::array<Eigen::Vector2d, 4> dir_px;
    std::array<double, 4> len_px{};
    for (std::size_t k = 0; k < 4; ++k) {
      dir_px[k] = (b[k] - a[k]).normalized();
      len_px[k] = (b[k] - a[k]).norm();
      n_px[k] = perp(dir_px[k]);
      if (n_px[k].dot(0.5 * (a[k] + b[k]) - centre_px) < 0.0) {
        n_px[k] = -n_px[k];
      }
      visible[k] = metric && wall_visible(0.5 * (a[k] + b[k]), n_px[k]);
      pts_plane[k].clear();
    }
    // The sides each scan direction can measure (at most two of the four).
    std::array<std::array<int, 4>, 4> sides_for{};
    std::array<int, 4> side_count{};
    for (std::uint8_t dir = 0; dir < 4; ++dir) {
      for (std::size_t k = 0; k < 4; ++k) {
        if (scan_fits(dir, n_px[k])) {
          sides_for[dir][static_cast<std::size_t>(side_count[dir]++)] = static_cast<int>(k);
        }
      }
    }
    for (int index : region.samples) {
      const Sample& s = samples[static_cast<std::size_t>(index)];
      if (sample_mapped[static_cast<std::size_t>(index)] == 0) {
        continue;
      }
      int best = -1;
      double best_d = tol_assign;
      for (int c = 0; c < side_count[s.dir]; ++c) {
        const auto k = static_cast<std::size_t>(sides_for[s.dir][static_cast<std::size_t>(c)]);
        const Eigen::Vector2d rel = s.px - a[k];
        const double t = rel.dot(dir_px[k]);
        if (t < margin || t > len_px[k] - margin) {
          continue;
        }
        const double d = std::abs(rel.dot(n_px[k]));
        if (d < best_d) {
          best_d = d;
          best = static_cast<int>(k);
        }
      }
      if (best >= 0) {
        const auto k = static_cast<std::size_t>(best);
        pts_plane[k].push_back(
            sample_lines[static_cast<std::size_t>(index)].at(visible[k] ? h.base : h.top));
      }
    }
    // Outward directions in the plane, for the lines' orientation.
    const auto centre_plane = plane(centre_px, h.top);
    if (!centre_plane) {
      return std::nullopt;
    }
    std::array<Eigen::Vector2d, 4> outward;
    for (std::size_t k = 0; k < 4; ++k) {
      const auto mid = plane(0.5 * (a[k] + b[k]), h.top);
      if (!mid) {
        return std::nullopt;
      }
      outward[k] = *mid - *centre_plane;
    }
    if (!enough_crossings(pts_plane)) {
      return std::nullopt;
    }
    const double scale = mapper->scale_at(centre_px, h.top);  // plane units per px
    // Trimmed least squares: fit all, keep the crossings within 1 px, refit, keep those within
    // three times the RMS (at least 0.2 px), refit. (The crossings were chosen clean, so this
    // only removes the few that a lead's corner or a speck still spoiled.)
    std::array<std::vector<Eigen::Vector2d>, 4> kept = pts_plane;
    double limit = 1.0;
    for (int pass = 0; pass < 2; ++pass) {
      lines = detail::fit_quad(kept, outward, metric);
      if (!lines) {
        return std::nullopt;
      }
      double sum2 = 0.0;
      int n = 0;
      for (std::size_t k = 0; k < 4; ++k) {
        kept[k].clear();
        for (const auto& q : pts_plane[k]) {
          const double r = (*lines)[k].distance(q) / scale;
          if (std::abs(r) <= limit) {
            kept[k].push_back(q);
            sum2 += r * r;
            ++n;
          }
        }
      }
      if (!enough_crossings(kept)) {
        return std::nullopt;
      }
      limit = std::clamp(3.0 * std::sqrt(sum2 / std::max(1, n)), 0.2, 1.0);
    }
    lines = detail::fit_quad(kept, outward, metric);
    if (!lines) {
      return std::nullopt;
    }
    // Corner k joins side k and side k + 1.
    std::array<Eigen::Vector2d, 4> corner;
    for (std::size_t k = 0; k < 4; ++k) {
      const auto c = detail::intersect((*lines)[k], (*lines)[(k + 1) % 4]);
      if (!c) {
        return std::nullopt;
      }
      corner[k] = *c;
    }
    // Statistics of the final pass.
    double sum2 = 0.0;
    int n = 0;
    double expected = 0.0;
    for (std::size_t k = 0; k < 4; ++k) {
      for (const auto& q : kept[k]) {
        const double r = (*lines)[k].distance(q) / scale;
        sum2 += r * r;
        ++n;
      }
      const double usable = std::max(1.0, len_px[k] - 2.0 * margin);
      const double families = (std::abs(n_px[k].x()) >= kScanCos ? std::abs(n_px[k].x()) : 0.0) +
                              (std::abs(n_px[k].y()) >= kScanCos ? std::abs(n_px[k].y()) : 0.0);
      expected += usable * families / options.crossing_stride;
    }
    fit.rms_px = n > 0 ? std::sqrt(sum2 / n) : 0.0;
    fit.inliers = n;
    fit.coverage = expected > 0.0 ? std::min(1.0, n / expected) : 0.0;
    fit.corners_plane.assign(corner.begin(), corner.end());
    // The next pass assigns crossings to the outline this fit predicts in the image.
    bool mapped = true;
    for (std::size_t k = 0; k < 4 && mapped; ++k) {
      const double hk = visible[k] ? h.base : h.top;
      const auto pa = pixel(corner[(k + 3) % 4], hk);
      const auto pb = pixel(corner[k], hk);
      mapped = pa && pb;
      if (mapped) {
        a[k] = *pa;
        b[k] = *pb;
      }
    }
    if (!mapped) {
      return std::nullopt;
    }
    const auto c0 =
        detail::intersect(Line2{perp((corner[2] - corner[0]).normalized()),
                                perp((corner[2] - corner[0]).normalized()).dot(corner[0])},
                          Line2{perp((corner[3] - corner[1]).normalized()),
                                perp((corner[3] - corner[1]).normalized()).dot(corner[1])});
    fit.centre_plane = c0 ? *c0 : 0.25 * (corner[0] + corner[1] + corner[2] + corner[3]);
    if (auto cp = pixel(fit.centre_plane, h.top)) {
      centre_px = *cp;
    }
  }
  // Sizes: side 0 and 2 are the long pair as guessed; the larger extent decides.
  const auto& l = *lines;
  const double extent02 = std::abs(l[0].d + l[2].d);  // n2 = -n0: distance between the lines
  const double extent13 = std::abs(l[1].d + l[3].d);
  const Eigen::Vector2d along02 = perp(l[0].n);
  if (extent13 >= extent02) {
    fit.length = extent13;  // the short sides are extent13 apart: the length
    fit.width = extent02;
    fit.angle_plane = std::atan2(along02.y(), along02.x());
  } else {
    fit.length = extent02;
    fit.width = extent13;
    const Eigen::Vector2d along13 = perp(l[1].n);
    fit.angle_plane = std::atan2(along13.y(), along13.x());
  }
  if (!metric) {
    // A parallelogram in pixels: the sides' own distances.
    fit.length = std::max(extent02, extent13);
    fit.width = std::min(extent02, extent13);
  }
  fit.shape =
      fit.width > 0.0 && fit.length / fit.width < 1.08 ? ShapeKind::kSquare : ShapeKind::kRectangle;
  // Area of the top face in the image against the blob's.
  std::vector<Eigen::Vector2d> corners_px;
  for (const auto& c : fit.corners_plane) {
    if (auto q = pixel(c, h.top)) {
      corners_px.push_back(*q);
    }
  }
  const double a_px = corners_px.size() == 4 ? quad_area(corners_px) : 0.0;
  fit.area_ratio = a_px > 0.0 ? region.area_px / a_px : 0.0;
  return fit;
}

std::optional<Fit> Locator::Impl::fit_circle_model(const Region& region, const Heights& h) {
  if (region.samples.size() < 8) {
    return std::nullopt;
  }
  Eigen::Vector2d centre_px = region.centroid;
  double radius_px = std::sqrt(region.area_px / kPi);
  Fit fit;
  fit.shape = ShapeKind::kCircle;
  fit.heights = h;
  std::optional<Circle2> circle;
  std::vector<Eigen::Vector2d> pts;
  std::vector<Eigen::Vector2d> kept;
  for (int iteration = 0; iteration < 3; ++iteration) {
    pts.clear();
    for (int index : region.samples) {
      const Sample& s = samples[static_cast<std::size_t>(index)];
      const Eigen::Vector2d d = s.px - centre_px;
      const double r = d.norm();
      if (r < 1.0 || std::abs(r - radius_px) > (iteration == 0 ? 4.0 : 1.5)) {
        continue;
      }
      const Eigen::Vector2d n = d / r;
      if (!scan_fits(s.dir, n)) {
        continue;
      }
      const bool vis = mapper->metric() && wall_visible(s.px, n);
      if (sample_mapped[static_cast<std::size_t>(index)] != 0) {
        pts.push_back(sample_lines[static_cast<std::size_t>(index)].at(vis ? h.base : h.top));
      }
    }
    const double scale = mapper->scale_at(centre_px, h.top);
    kept = pts;
    for (int pass = 0; pass < 4; ++pass) {
      circle = detail::fit_circle(kept);
      if (!circle) {
        return std::nullopt;
      }
      scratch.clear();
      for (const auto& q : pts) {
        scratch.push_back(((q - circle->c).norm() - circle->r) / scale);
      }
      const double sigma = 1.4826 * detail::median_abs(scratch);
      const double limit = std::clamp(3.5 * sigma, 0.2, 1.5);
      kept.clear();
      for (const auto& q : pts) {
        if (std::abs(((q - circle->c).norm() - circle->r) / scale) <= limit) {
          kept.push_back(q);
        }
      }
      if (kept.size() < 8) {
        return std::nullopt;
      }
    }
    circle = detail::fit_circle(kept);
    if (!circle) {
      return std::nullopt;
    }
    double sum2 = 0.0;
    for (const auto& q : kept) {
      const double r = ((q - circle->c).norm() - circle->r) / scale;
      sum2 += r * r;
    }
    fit.rms_px = std::sqrt(sum2 / static_cast<double>(kept.size()));
    fit.inliers = static_cast<int>(kept.size());
    auto cp = pixel(circle->c, h.top);
    if (!cp) {
      return std::nullopt;
    }
    centre_px = *cp;
    radius_px = circle->r / scale;
  }
  fit.centre_plane = circle->c;
  fit.radius = circle->r;
  fit.length = fit.width = 2.0 * circle->r;
  // Crossings per unit of circumference: both families cover about 2 * (|cos| + |sin|) ~ 2.5
  // samples per pixel of circumference where they are valid.
  const double circumference = 2.0 * kPi * radius_px;
  fit.coverage = std::min(1.0, fit.inliers * options.crossing_stride / (1.1 * circumference));
  fit.area_ratio = region.area_px / (kPi * radius_px * radius_px);
  return fit;
}

std::optional<Fit> Locator::Impl::fit_triangle_model(const Region& region, const Heights& h) {
  if (region.hull.size() < 3) {
    return std::nullopt;
  }
  std::vector<cv::Point2f> tri;
  try {
    cv::minEnclosingTriangle(region.hull, tri);
  } catch (const cv::Exception&) {
    return std::nullopt;
  }
  if (tri.size() != 3) {
    return std::nullopt;
  }
  const int w = options.edge_window_px;
  const double margin = w + 1.5;
  std::array<Eigen::Vector2d, 3> a;
  std::array<Eigen::Vector2d, 3> b;
  for (std::size_t k = 0; k < 3; ++k) {
    a[k] = Eigen::Vector2d(tri[k].x, tri[k].y);
    b[k] = Eigen::Vector2d(tri[(k + 1) % 3].x, tri[(k + 1) % 3].y);
  }
  Eigen::Vector2d centre_px = (a[0] + a[1] + a[2]) / 3.0;
  Fit fit;
  fit.shape = ShapeKind::kTriangle;
  fit.heights = h;
  std::array<Line2, 3> lines;
  std::array<Eigen::Vector2d, 3> corner;
  std::array<bool, 3> visible{};
  for (int iteration = 0; iteration < 3; ++iteration) {
    const double tol_assign = iteration == 0 ? 4.5 : 1.5;
    std::array<Eigen::Vector2d, 3> n_px;
    std::array<Eigen::Vector2d, 3> dir_px;
    std::array<double, 3> len_px{};
    std::array<std::vector<Eigen::Vector2d>, 3> pts;
    for (std::size_t k = 0; k < 3; ++k) {
      dir_px[k] = (b[k] - a[k]).normalized();
      len_px[k] = (b[k] - a[k]).norm();
      n_px[k] = perp(dir_px[k]);
      if (n_px[k].dot(0.5 * (a[k] + b[k]) - centre_px) < 0.0) {
        n_px[k] = -n_px[k];
      }
      visible[k] = mapper->metric() && wall_visible(0.5 * (a[k] + b[k]), n_px[k]);
    }
    for (int index : region.samples) {
      const Sample& s = samples[static_cast<std::size_t>(index)];
      int best = -1;
      double best_d = tol_assign;
      for (std::size_t k = 0; k < 3; ++k) {
        if (!scan_fits(s.dir, n_px[k])) {
          continue;
        }
        // Corners of a triangle are sharp: the windows reach the next side sooner.
        const double t = (s.px - a[k]).dot(dir_px[k]);
        if (t < 1.6 * margin || t > len_px[k] - 1.6 * margin) {
          continue;
        }
        const double d = std::abs((s.px - a[k]).dot(n_px[k]));
        if (d < best_d) {
          best_d = d;
          best = static_cast<int>(k);
        }
      }
      if (best >= 0) {
        const auto k = static_cast<std::size_t>(best);
        if (sample_mapped[static_cast<std::size_t>(index)] != 0) {
          pts[k].push_back(
              sample_lines[static_cast<std::size_t>(index)].at(visible[k] ? h.base : h.top));
        }
      }
    }
    const auto centre_plane = plane(centre_px, h.top);
    if (!centre_plane) {
      return std::nullopt;
    }
    const double scale = mapper->scale_at(centre_px, h.top);
    double sum2 = 0.0;
    int n = 0;
    for (std::size_t k = 0; k < 3; ++k) {
      const auto mid = plane(0.5 * (a[k] + b[k]), h.top);
      if (!mid || pts[k].size() < 4) {
        return std::nullopt;
      }
      const Eigen::Vector2d outward = *mid - *centre_plane;
      std::vector<Eigen::Vector2d> kept = pts[k];
      std::optional<Line2> line;
      for (int pass = 0; pass < 4; ++pass) {
        line = detail::fit_line(kept, outward);
        if (!line) {
          return std::nullopt;
        }
        scratch.clear();
        for (const auto& q : pts[k]) {
          scratch.push_back(line->distance(q) / scale);
        }
        const double sigma = 1.4826 * detail::median_abs(scratch);
        const double limit = std::clamp(3.5 * sigma, 0.2, 1.5);
        kept.clear();
        for (const auto& q : pts[k]) {
          if (std::abs(line->distance(q) / scale) <= limit) {
            kept.push_back(q);
          }
        }
        if (kept.size() < 3) {
          return std::nullopt;
        }
      }
      line = detail::fit_line(kept, outward);
      if (!line) {
        return std::nullopt;
      }
      lines[k] = *line;
      for (const auto& q : kept) {
        const double r = line->distance(q) / scale;
        sum2 += r * r;
        ++n;
      }
    }
    for (std::size_t k = 0; k < 3; ++k) {
      const auto c = detail::intersect(lines[k], lines[(k + 1) % 3]);
      if (!c) {
        return std::nullopt;
      }
      corner[k] = *c;  // side k and side k + 1
    }
    fit.rms_px = n > 0 ? std::sqrt(sum2 / n) : 0.0;
    fit.inliers = n;
    double perimeter = 0.0;
    for (std::size_t k = 0; k < 3; ++k) {
      const double hk = visible[k] ? h.base : h.top;
      const auto pa = pixel(corner[(k + 2) % 3], hk);
      const auto pb = pixel(corner[k], hk);
      if (!pa || !pb) {
        return std::nullopt;
      }
      a[k] = *pa;
      b[k] = *pb;
      perimeter += (*pb - *pa).norm();
    }
    fit.coverage = std::min(1.0, n * options.crossing_stride / std::max(1.0, 0.9 * perimeter));
    fit.centre_plane = (corner[0] + corner[1] + corner[2]) / 3.0;
    if (auto cp = pixel(fit.centre_plane, h.top)) {
      centre_px = *cp;
    }
  }
  // Corners counter-clockwise seen from above (the plane's handedness says which sign).
  std::vector<Eigen::Vector2d> c(corner.begin(), corner.end());
  const double area = detail::signed_area(c);
  const bool ccw = mapper->plane_right_handed() ? area > 0.0 : area < 0.0;
  if (!ccw) {
    std::swap(c[1], c[2]);
  }
  fit.corners_plane = c;
  const Eigen::Vector2d side = c[1] - c[0];
  fit.angle_plane = std::atan2(side.y(), side.x());
  const double s = ((c[1] - c[0]).norm() + (c[2] - c[1]).norm() + (c[0] - c[2]).norm()) / 3.0;
  fit.length = s;
  fit.width = s * std::sqrt(3.0) / 2.0;
  std::vector<Eigen::Vector2d> corners_px;
  for (const auto& q : c) {
    if (auto p = pixel(q, h.top)) {
      corners_px.push_back(*p);
    }
  }
  const double a_px = corners_px.size() == 3 ? std::abs(detail::signed_area(corners_px)) : 0.0;
  fit.area_ratio = a_px > 0.0 ? region.area_px / a_px : 0.0;
  return fit;
}

std::optional<Fit> Locator::Impl::fit_region(Region& region) {
  if (region.area_px < 4.0 || !prepare(region)) {
    return std::nullopt;
  }
  // First guess of the shape from how the blob fills its smallest enclosing rectangle: ~1
  // for rectangles (less the IC leads' gaps), pi/4 for circles, 1/2 for triangles.
  const cv::RotatedRect& rr = region.rect;
  const double box = static_cast<double>(rr.size.width) * rr.size.height;
  const double fill = box > 0.0 ? region.area_px / box : 0.0;
  const double aspect = std::max(rr.size.width, rr.size.height) /
                        std::max(1e-9f, std::min(rr.size.width, rr.size.height));
  std::vector<ShapeKind> order;
  if (fill < 0.64) {
    order = {ShapeKind::kTriangle, ShapeKind::kRectangle, ShapeKind::kCircle};
  } else if (fill < 0.86 && aspect < 1.2) {
    order = {ShapeKind::kCircle, ShapeKind::kRectangle, ShapeKind::kTriangle};
  } else {
    order = {ShapeKind::kRectangle, ShapeKind::kCircle, ShapeKind::kTriangle};
  }
  const Heights defaults{options.default_top_mm, options.default_base_mm};
  std::optional<Fit> best;
  for (ShapeKind shape : order) {
    auto fit_with = [&](const Heights& h) -> std::optional<Fit> {
      switch (shape) {
        case ShapeKind::kCircle:
          return fit_circle_model(region, h);
        case ShapeKind::kTriangle:
          return fit_triangle_model(region, h);
        default:
          return fit_quad_model(region, h);
      }
    };
    auto fit = fit_with(defaults);
    if (!fit) {
      continue;
    }
    classify(*fit);
    if (fit->matched && mapper->metric()) {
      // Refit with the class's heights (the parallax of its top face and walls).
      const Heights h{fit->spec->top_mm, fit->spec->base_mm};
      if (std::abs(h.top - defaults.top) > 1e-9 || std::abs(h.base - defaults.base) > 1e-9) {
        auto refit = fit_with(h);
        if (refit) {
          classify(*refit);
          if (refit->matched) {
            fit = refit;
          }
        }
      }
    }
    const bool good = explained(*fit);
    if (good && (!best || !explained(*best) || fit->rms_px < best->rms_px)) {
      best = fit;
      if (shape == order.front()) {
        break;  // the expected model explains the blob: no need to try the others
      }
    } else if (!best || (!explained(*best) && fit->rms_px < best->rms_px)) {
      best = fit;
    }
  }
  return best;
}

Detection Locator::Impl::to_detection(const Fit& fit) const {
  Detection d;
  d.shape = fit.shape;
  if (fit.spec != nullptr) {
    d.class_name = fit.spec->name;
    d.shape = fit.spec->shape;  // a square class decides square vs rectangle
  } else {
    d.class_name = std::string(to_string(fit.shape));
  }
  const int order = symmetry_order(d.shape);
  const double top = fit.heights.top;
  d.metric = mapper->metric();
  d.center_plane = fit.centre_plane;
  d.angle_plane_rad = fold_angle(fit.angle_plane, order);
  if (auto c = pixel(fit.centre_plane, top)) {
    d.center_px = *c;
  }
  for (const auto& q : fit.corners_plane) {
    if (auto c = pixel(q, top)) {
      d.corners_px.push_back(*c);
    }
  }
  if (fit.shape == ShapeKind::kCircle) {
    const double scale = mapper->scale_at(d.center_px, top);
    d.length_px = d.width_px = 2.0 * fit.radius / scale;
    d.angle_rad = 0.0;
  } else {
    // The image angle: the plane direction projected at the centre.
    const double unit = d.metric ? 1.0 : 10.0;
    const Eigen::Vector2d dir(std::cos(fit.angle_plane), std::sin(fit.angle_plane));
    if (auto tip = pixel(fit.centre_plane + unit * dir, top)) {
      const Eigen::Vector2d v = *tip - d.center_px;
      d.angle_rad = fold_angle(std::atan2(v.y(), v.x()), order);
    }
    if (d.corners_px.size() == 4) {
      // Corners k join sides k and k + 1; order them as render::PartTruth does, from the
      // (-L/2, -W/2) corner counter-clockwise seen from above (up to the 180 deg symmetry).
      const auto& c = d.corners_px;
      const double s01 = (c[1] - c[0]).norm() + (c[3] - c[2]).norm();
      const double s12 = (c[2] - c[1]).norm() + (c[0] - c[3]).norm();
      d.length_px = 0.5 * std::max(s01, s12);
      d.width_px = 0.5 * std::min(s01, s12);
      std::vector<Eigen::Vector2d> ordered(c.begin(), c.end());
      if (s12 > s01) {  // make c0 -> c1 run along the length
        std::rotate(ordered.begin(), ordered.begin() + 1, ordered.end());
      }
      // Seen from above counter-clockwise is clockwise on a screen whose v runs down.
      if (detail::signed_area(ordered) > 0.0) {
        std::reverse(ordered.begin(), ordered.end());
        std::rotate(ordered.begin(), ordered.begin() + 3, ordered.end());
      }
      d.corners_px = ordered;
    } else if (d.corners_px.size() == 3) {
      const auto& c = d.corners_px;
      d.length_px = ((c[1] - c[0]).norm() + (c[2] - c[1]).norm() + (c[0] - c[2]).norm()) / 3.0;
      d.width_px = d.length_px * std::sqrt(3.0) / 2.0;
      const Eigen::Vector2d side = c[1] - c[0];
      d.angle_rad = fold_angle(std::atan2(side.y(), side.x()), order);
    }
  }
  if (d.metric) {
    d.length_mm = fit.length;
    d.width_mm = fit.width;
  }
  if (mapper->world()) {
    if (auto base = mapper->to_base(fit.centre_plane, fit.angle_plane)) {
      d.has_base_pose = true;
      d.base_pose = *base;
      d.base_pose.rz_rad = fold_angle_centred(base->rz_rad, order);
    }
  }
  d.fit_rms_px = fit.rms_px;
  d.edge_samples = fit.inliers;
  // Quality: how much of the outline was measured, how well it fits, how well the size matches
  // a class (0.8 when sizes cannot be compared).
  const double q_cov = std::sqrt(std::clamp(fit.coverage / 0.5, 0.0, 1.0));
  const double q_fit = 1.0 / (1.0 + std::pow(fit.rms_px / 0.2, 2.0));
  const double q_cls = fit.matched ? 1.0 - 0.5 * fit.class_score
                                   : (d.metric && !options.classes.empty() ? 0.4 : 0.8);
  d.quality = std::clamp(q_cov * q_fit * q_cls, 0.0, 1.0);
  return d;
}

Detection Locator::Impl::unknown_detection(const Region& region) const {
  Detection d;
  d.class_name = "unknown";
  d.shape = ShapeKind::kUnknown;
  d.touching = true;
  d.quality = 0.0;
  d.center_px = region.centroid;
  if (region.hull.size() >= 3 || region.outline.size() >= 3) {
    const cv::RotatedRect rr =
        region.hull.size() >= 3 ? region.rect : cv::minAreaRect(region.outline);
    std::array<cv::Point2f, 4> pts;
    rr.points(pts.data());
    for (const auto& p : pts) {
      d.corners_px.emplace_back(p.x, p.y);
    }
    d.length_px = std::max(rr.size.width, rr.size.height);
    d.width_px = std::min(rr.size.width, rr.size.height);
    const double a = (rr.size.width >= rr.size.height ? rr.angle : rr.angle + 90.0) * kPi / 180.0;
    d.angle_rad = fold_angle(a, 2);
  }
  d.metric = mapper->metric();
  if (auto c = plane(d.center_px, options.default_top_mm)) {
    d.center_plane = *c;
    if (mapper->world()) {
      if (auto base = mapper->to_base(*c, 0.0)) {
        d.has_base_pose = true;
        d.base_pose = *base;
      }
    }
  }
  return d;
}

std::vector<Region> Locator::Impl::split(const Blob& blob, double dark) {
  // The blob's mask in its box (one pixel of margin).
  const int x0 = blob.x_min - 1;
  const int y0 = blob.y_min - 1;
  cv::Mat mask = cv::Mat::zeros(blob.y_max - blob.y_min + 3, blob.x_max - blob.x_min + 3, CV_8UC1);
  const Run* runs = &seg.runs()[static_cast<std::size_t>(blob.first_run)];
  for (int i = 0; i < blob.run_count; ++i) {
    std::uint8_t* row = mask.ptr<std::uint8_t>(runs[i].y - y0);
    std::fill(row + (runs[i].x0 - x0), row + (runs[i].x1 - x0) + 1, std::uint8_t{255});
  }
  const double bg =
      seg.background(0.5 * (blob.x_min + blob.x_max), 0.5 * (blob.y_min + blob.y_max));
  const int min_area = std::max(options.segmentation.min_area_px, blob.area / 20);
  cv::Mat piece_labels;
  cv::Mat stats;
  cv::Mat centroids;
  std::vector<int> pieces;
  auto components = [&](const cv::Mat& m, int connectivity) {
    pieces.clear();
    const int n =
        cv::connectedComponentsWithStats(m, piece_labels, stats, centroids, connectivity, CV_32S);
    for (int i = 1; i < n; ++i) {
      if (stats.at<int>(i, cv::CC_STAT_AREA) >= min_area) {
        pieces.push_back(i);
      }
    }
    return pieces.size() >= 2;
  };
  // 1. Nearly touching parts: the bridge between them is grey (partly covered pixels); a
  // threshold near the body's own level, 4-connected, cuts it.
  bool found = false;
  for (const double fraction : {0.3, 0.18, 0.1}) {
    cv::Mat strict = mask.clone();
    const int level = static_cast<int>(dark + fraction * (bg - dark));
    for (int y = 0; y < strict.rows; ++y) {
      std::uint8_t* m = strict.ptr<std::uint8_t>(y);
      const int iy = y + y0;
      if (iy < 0 || iy >= image->rows) {
        continue;
      }
      const std::uint8_t* src = image->ptr<std::uint8_t>(iy);
      for (int x = 0; x < strict.cols; ++x) {
        const int ix = x + x0;
        if (m[x] != 0 && (ix < 0 || ix >= image->cols || src[ix] >= level)) {
          m[x] = 0;
        }
      }
    }
    if (components(strict, 4)) {
      found = true;
      break;
    }
  }
  // 2. Touching parts: erode until the blob falls apart at its necks.
  if (!found) {
    cv::Mat eroded = mask.clone();
    const cv::Mat kernel = cv::getStructuringElement(cv::MORPH_RECT, cv::Size(3, 3));
    for (int k = 0; k < 10 && !found; ++k) {
      cv::erode(eroded, eroded, kernel);
      if (cv::countNonZero(eroded) == 0) {
        break;
      }
      found = components(eroded, 8);
    }
  }
  if (!found) {
    return {};
  }
  // Each pixel of the box goes to its nearest piece.
  cv::Mat seeds = cv::Mat::ones(mask.size(), CV_8UC1) * 255;
  for (int y = 0; y < mask.rows; ++y) {
    const int* l = piece_labels.ptr<int>(y);
    std::uint8_t* s = seeds.ptr<std::uint8_t>(y);
    for (int x = 0; x < mask.cols; ++x) {
      if (std::find(pieces.begin(), pieces.end(), l[x]) != pieces.end()) {
        s[x] = 0;
      }
    }
  }
  cv::Mat dist;
  cv::Mat nearest;
  cv::distanceTransform(seeds, dist, nearest, cv::DIST_L2, 3, cv::DIST_LABEL_PIXEL);
  // distanceTransform numbers every seed pixel (DIST_LABEL_PIXEL: pieces that touch
  // diagonally stay apart): map those numbers to our pieces.
  std::vector<int> piece_of_label(static_cast<std::size_t>(mask.rows * mask.cols + 2), -1);
  for (int y = 0; y < mask.rows; ++y) {
    const int* l = piece_labels.ptr<int>(y);
    const int* nl = nearest.ptr<int>(y);
    const std::uint8_t* s = seeds.ptr<std::uint8_t>(y);
    for (int x = 0; x < mask.cols; ++x) {
      if (s[x] == 0) {
        const auto it = std::find(pieces.begin(), pieces.end(), l[x]);
        piece_of_label[static_cast<std::size_t>(nl[x])] = static_cast<int>(it - pieces.begin());
      }
    }
  }
  std::vector<Region> regions(pieces.size());
  auto piece_at = [&](int ix, int iy) {
    const int x = std::clamp(ix - x0, 0, mask.cols - 1);
    const int y = std::clamp(iy - y0, 0, mask.rows - 1);
    return piece_of_label[static_cast<std::size_t>(nearest.at<int>(y, x))];
  };
  // Outline points and area of each piece from the blob's runs, cut where the owner changes.
  std::vector<Eigen::Vector2d> sums(pieces.size(), Eigen::Vector2d::Zero());
  for (int i = 0; i < blob.run_count; ++i) {
    const Run& r = runs[i];
    int start = r.x0;
    int owner = piece_at(r.x0, r.y);
    for (int x = r.x0; x <= r.x1 + 1; ++x) {
      const int o = x <= r.x1 ? piece_at(x, r.y) : -2;
      if (o != owner) {
        if (owner >= 0) {
          Region& g = regions[static_cast<std::size_t>(owner)];
          g.outline.emplace_back(static_cast<float>(start - 0.5), static_cast<float>(r.y));
          g.outline.emplace_back(static_cast<float>(x - 0.5), static_cast<float>(r.y));
          const double len = x - start;
          g.area_px += len;
          sums[static_cast<std::size_t>(owner)] +=
              Eigen::Vector2d(len * 0.5 * (start + x - 1), len * r.y);
        }
        owner = o;
        start = x;
      }
    }
  }
  for (std::size_t i = 0; i < samples.size(); ++i) {
    const Eigen::Vector2d& p = samples[i].px;
    const int owner =
        piece_at(static_cast<int>(std::lround(p.x())), static_cast<int>(std::lround(p.y())));
    if (owner >= 0) {
      regions[static_cast<std::size_t>(owner)].samples.push_back(static_cast<int>(i));
    }
  }
  for (std::size_t k = 0; k < regions.size(); ++k) {
    if (regions[k].area_px > 0.0) {
      regions[k].centroid = sums[k] / regions[k].area_px;
    }
  }
  return regions;
}

bool Locator::Impl::has_seam(const Blob& blob, double dark) const {
  // Two parts a pixel or less apart join into one blob through the grey of the pixels that
  // straddle the gap: inside the blob (dark above and below, away from the runs' ends where
  // the outline and the IC leads are), pixels much brighter than the body.
  const Run* runs = &seg.runs()[static_cast<std::size_t>(blob.first_run)];
  const double bg =
      seg.background(0.5 * (blob.x_min + blob.x_max), 0.5 * (blob.y_min + blob.y_max));
  const int level = static_cast<int>(dark + 0.35 * (bg - dark));
  constexpr int kEndMargin = 4;
  int seam = 0;
  for (int i = 0; i < blob.run_count; ++i) {
    const Run& r = runs[i];
    if (r.y <= 0 || r.y + 1 >= image->rows || r.x1 - r.x0 < 2 * kEndMargin) {
      continue;
    }
    const std::uint8_t* row = image->ptr<std::uint8_t>(r.y);
    int bright = 0;  // the common case: nothing bright inside the run
    for (int x = r.x0 + kEndMargin; x <= r.x1 - kEndMargin; ++x) {
      bright += row[x] >= level ? 1 : 0;
    }
    if (bright == 0) {
      continue;
    }
    const std::uint8_t* up = image->ptr<std::uint8_t>(r.y - 1);
    const std::uint8_t* down = image->ptr<std::uint8_t>(r.y + 1);
    for (int x = r.x0 + kEndMargin; x <= r.x1 - kEndMargin; ++x) {
      if (row[x] >= level && up[x] < seg.threshold(x, r.y - 1) &&
          down[x] < seg.threshold(x, r.y + 1)) {
        ++seam;
      }
    }
  }
  return seam >= 3;
}

void Locator::Impl::process_blob(const Blob& blob, LocateResult& result, std::vector<int>& owners) {
  const Run* runs = &seg.runs()[static_cast<std::size_t>(blob.first_run)];
  const double dark = dark_level(runs, blob.run_count);
  collect_samples(runs, blob.run_count, dark, options.crossing_stride);
  map_samples();
  Region whole;
  whole.area_px = blob.area;
  Eigen::Vector2d sum = Eigen::Vector2d::Zero();
  whole.outline.reserve(2 * static_cast<std::size_t>(blob.run_count));
  for (int i = 0; i < blob.run_count; ++i) {
    const Run& r = runs[i];
    whole.outline.emplace_back(static_cast<float>(r.x0 - 0.5), static_cast<float>(r.y));
    whole.outline.emplace_back(static_cast<float>(r.x1 + 0.5), static_cast<float>(r.y));
    const double len = r.x1 - r.x0 + 1;
    sum += Eigen::Vector2d(len * 0.5 * (r.x0 + r.x1), len * r.y);
  }
  whole.centroid = sum / std::max(1.0, whole.area_px);
  whole.samples.resize(samples.size());
  for (std::size_t i = 0; i < samples.size(); ++i) {
    whole.samples[i] = static_cast<int>(i);
  }
  whole.label = next_label++;
  const bool seam = has_seam(blob, dark);
  std::optional<Fit> fit;
  if (!seam) {
    fit = fit_region(whole);
    if ((!fit || !explained(*fit)) && options.crossing_stride > 1) {
      // A small part with leads on both long sides may keep too few clean crossings at every
      // other row: take them all before concluding.
      collect_samples(runs, blob.run_count, dark, 1);
      map_samples();
      whole.samples.resize(samples.size());
      for (std::size_t i = 0; i < samples.size(); ++i) {
        whole.samples[i] = static_cast<int>(i);
      }
      fit = fit_region(whole);
    }
    if (fit && explained(*fit)) {
      result.detections.push_back(to_detection(*fit));
      owners.push_back(whole.label);
      return;
    }
  }
  // Not one part: try to separate it. Each piece is fitted on its own; a piece whose outline
  // cannot be fitted (its side along the other part has no clean crossings) is still reported,
  // as an unknown touching part at its own place, so that nothing is merged.
  std::vector<Region> pieces = split(blob, dark);
  if (!pieces.empty()) {
    ++result.report.split;
    for (Region& piece : pieces) {
      piece.label = next_label++;
      auto f = fit_region(piece);
      Detection d;
      if (f && explained(*f)) {
        d = to_detection(*f);
        d.quality *= 0.7;
      } else {
        ++result.report.unresolved;
        d = unknown_detection(piece);
      }
      d.touching = true;
      result.detections.push_back(std::move(d));
      owners.push_back(piece.label);
    }
    return;
  }
  if (fit && fit->rms_px <= options.max_fit_rms_px && fit->area_ratio > 0.8 &&
      fit->area_ratio < 1.3 && (!mapper->metric() || options.classes.empty())) {
    // Without sizes to compare, one clean outline is one part, named by its shape. (With
    // sizes, a clean outline that no class has is as likely two parts side by side: it is
    // reported as unknown below, never as a part it may not be.)
    result.detections.push_back(to_detection(*fit));
    owners.push_back(whole.label);
    return;
  }
  ++result.report.unresolved;
  result.detections.push_back(unknown_detection(whole));
  owners.push_back(whole.label);
}

void Locator::Impl::run_fast(LocateResult& result) {
  seg.segment(*image, options.segmentation);
  result.report.dirt = seg.dirt();
  next_label = 1;
  std::vector<int> owners;  // label of each detection's pixels (grip test)
  blob_of_detection.clear();
  for (std::size_t b = 0; b < seg.blobs().size(); ++b) {
    const Blob& blob = seg.blobs()[b];
    if (blob.border && options.drop_border_parts) {
      ++result.report.at_border;
      continue;
    }
    ++result.report.blobs;
    try {
      process_blob(blob, result, owners);
    } catch (const cv::Exception& e) {
      // OpenCV refusing a degenerate geometry must not lose the frame: the blob is reported
      // as an unknown part (and the detections it had produced are kept).
      result.detections.resize(owners.size());
      ++result.report.unresolved;
      Detection d;
      d.class_name = "unknown";
      d.shape = ShapeKind::kUnknown;
      d.touching = true;
      d.center_px =
          Eigen::Vector2d(0.5 * (blob.x_min + blob.x_max), 0.5 * (blob.y_min + blob.y_max));
      result.detections.push_back(d);
      owners.push_back(next_label++);
    }
    blob_of_detection.resize(result.detections.size(), static_cast<int>(b));
  }
  if (!options.grasps.empty() && mapper->metric()) {
    test_grips(result, owners);
  }
}

// ---------------------------------------------------------------------------------------------
// Clear grip: windows in the plane, counted in the image.

void Locator::Impl::test_grips(LocateResult& result, const std::vector<int>& owners) {
  // Which part owns each dark pixel: a blob's runs belong to its detection; a blob split into
  // several detections gives each pixel to the nearest of their centres.
  if (labels.size() != image->size()) {
    labels.create(image->size(), CV_32SC1);
  }
  labels.setTo(0);
  std::vector<std::size_t> mine;
  for (std::size_t b = 0; b < seg.blobs().size(); ++b) {
    const Blob& blob = seg.blobs()[b];
    mine.clear();
    for (std::size_t i = 0; i < owners.size(); ++i) {
      if (blob_of_detection[i] == static_cast<int>(b)) {
        mine.push_back(i);
      }
    }
    const Run* runs = &seg.runs()[static_cast<std::size_t>(blob.first_run)];
    for (int i = 0; i < blob.run_count; ++i) {
      int* row = labels.ptr<int>(runs[i].y);
      for (int x = runs[i].x0; x <= runs[i].x1; ++x) {
        int best = -1;  // a part that is not a detection (at the border): still another part
        double best_d = 1e300;
        for (std::size_t k : mine) {
          const double d =
              (result.detections[k].center_px - Eigen::Vector2d(x, runs[i].y)).squaredNorm();
          if (d < best_d) {
            best_d = d;
            best = owners[k];
          }
        }
        row[x] = best;
      }
    }
  }
  const int width = image->cols;
  const int height = image->rows;
  for (std::size_t i = 0; i < result.detections.size(); ++i) {
    Detection& d = result.detections[i];
    const GraspModel* model = nullptr;
    for (const GraspModel& g : options.grasps) {
      if (g.class_name == d.class_name) {
        model = &g;
      }
    }
    if (model == nullptr || d.shape == ShapeKind::kUnknown) {
      continue;
    }
    const int own = owners[i];
    double top = options.default_top_mm;
    if (const PartSpec* spec = options.classes.find(d.class_name)) {
      top = spec->top_mm;
    }
    auto to_px = [&](const Eigen::Vector2d& q) -> std::optional<Eigen::Vector2d> {
      return pixel(q, top);
    };
    auto count = [&](const std::array<Eigen::Vector2d, 4>& quad) {
      WindowCount wc;
      double v_min = 1e300;
      double v_max = -1e300;
      for (const auto& q : quad) {
        v_min = std::min(v_min, q.y());
        v_max = std::max(v_max, q.y());
        if (q.x() < -0.5 || q.y() < -0.5 || q.x() > width - 0.5 || q.y() > height - 0.5) {
          wc.inside_image = false;
        }
      }
      // Pixel centres inside the convex quad, row by row.
      const int y_lo = static_cast<int>(std::ceil(v_min));
      const int y_hi = static_cast<int>(std::floor(v_max));
      for (int y = y_lo; y <= y_hi; ++y) {
        double x_lo = 1e300;
        double x_hi = -1e300;
        for (std::size_t k = 0; k < 4; ++k) {
          const Eigen::Vector2d& p = quad[k];
          const Eigen::Vector2d& q = quad[(k + 1) % 4];
          if ((p.y() <= y && q.y() >= y) || (q.y() <= y && p.y() >= y)) {
            if (std::abs(q.y() - p.y()) < 1e-12) {
              x_lo = std::min({x_lo, p.x(), q.x()});
              x_hi = std::max({x_hi, p.x(), q.x()});
            } else {
              const double x = p.x() + (y - p.y()) * (q.x() - p.x()) / (q.y() - p.y());
              x_lo = std::min(x_lo, x);
              x_hi = std::max(x_hi, x);
            }
          }
        }
        if (x_lo > x_hi) {
          continue;
        }
        for (int x = static_cast<int>(std::ceil(x_lo)); x <= static_cast<int>(std::floor(x_hi));
             ++x) {
          if (x < 0 || y < 0 || x >= width || y >= height) {
            continue;  // outside the image: neither counted nor free
          }
          wc.expected_px += 1.0;
          const int l = labels.at<int>(y, x);
          const bool taken =
              (l != 0 && l != own) || (l == 0 && grey(x, y) < seg.threshold(x, y));  // dirt too
          if (!taken) {
            wc.free_px += 1.0;
          }
        }
      }
      return wc;
    };
    d.grip = test_clear_grip(*model, d.center_plane, d.angle_plane_rad, to_px, count);
    // The clear grasps in the base frame, through the same mapping as the part's base_pose
    // (to_detection), but not folded: the tool's yaw is the picker's to fold.
    d.base_grasps.clear();
    if (d.has_base_pose && mapper->world()) {
      for (const ClearGrasp& g : d.grip.clear) {
        if (auto base = mapper->to_base(g.grasp, g.tool_yaw_rad)) {
          d.base_grasps.push_back(BaseGrasp{g.style, g.name, *base});
        }
      }
    }
  }
}

// ---------------------------------------------------------------------------------------------
// Thesis pipeline: its objects as Detections.

void Locator::Impl::run_thesis(LocateResult& result) {
  ThesisOptions t = options.thesis;
  // The thesis's constants describe its camera; with a calibration, take them from it: the
  // image point below the camera, its height, the aspect of its pixels.
  if (mapper->metric()) {
    if (have_nadir) {
      t.centre_px = Eigen::Vector2i(static_cast<int>(std::lround(nadir_px.x())),
                                    static_cast<int>(std::lround(nadir_px.y())));
    }
    t.camera_height_mm = mapper->camera_height_mm();
    const auto& c = mapper->calibration();
    if (c && c->model == calibration::ModelType::kPlanar7545) {
      t.aspect = c->planar.c_x_px_per_mm / c->planar.c_y_px_per_mm;
    } else if (c) {
      t.aspect = c->pinhole.fx_px / c->pinhole.fy_px;
    }
  }
  auto objects = thesis_locate(*image, t, &result.report.thesis);
  if (!objects) {
    return;  // validated options and a CV_8UC1 image: cannot happen
  }
  result.report.blobs = result.report.thesis.partial_groups;
  result.report.dirt = result.report.thesis.dirt_groups;
  const double top = t.part_height_mm;
  for (const ThesisObject& o : *objects) {
    Detection d;
    d.shape = o.shape;
    d.class_name = std::string(to_string(o.shape));
    d.metric = mapper->metric();
    const int order = symmetry_order(o.shape);
    d.center_px = o.centre_raw.cast<double>();
    for (const auto& c : o.corners_raw) {
      d.corners_px.push_back(c.cast<double>());
    }
    if (o.shape == ShapeKind::kCircle) {
      d.length_px = d.width_px = 2.0 * o.radius_px;
    } else if (o.corners_raw.size() == 4) {
      const auto& c = d.corners_px;  // slots 0-1 and 2-3 along the long sides
      d.length_px = 0.5 * ((c[0] - c[1]).norm() + (c[2] - c[3]).norm());
      d.width_px = 0.5 * ((c[0] - c[2]).norm() + (c[1] - c[3]).norm());
      // Eq. 2.12 in the image's own pixels (aspect 1): alpha from the j axis toward +i.
      const double alpha = thesis_alpha_deg(c[0], c[1], c[2], c[3], 1.0) * kPi / 180.0;
      d.angle_rad = fold_angle(kPi / 2.0 - alpha, order);
    } else if (o.corners_raw.size() == 3) {
      const auto& c = d.corners_px;
      d.length_px = ((c[1] - c[0]).norm() + (c[2] - c[1]).norm() + (c[0] - c[2]).norm()) / 3.0;
      d.width_px = d.length_px * std::sqrt(3.0) / 2.0;
      std::vector<Eigen::Vector2d> ordered(c.begin(), c.end());
      if (detail::signed_area(ordered) > 0.0) {
        std::swap(ordered[1], ordered[2]);
      }
      const Eigen::Vector2d side = ordered[1] - ordered[0];
      d.angle_rad = fold_angle(std::atan2(side.y(), side.x()), order);
      d.corners_px = ordered;
    }
    // Sizes and pose: the corrected corners are table-level pixels (eq. 2.21), mapped on the
    // working plane itself.
    if (d.metric) {
      std::vector<Eigen::Vector2d> plane_corners;
      for (const auto& c : o.corners) {
        if (auto q = plane(c.cast<double>(), 0.0)) {
          plane_corners.push_back(*q);
        }
      }
      auto centre = plane(o.centre.cast<double>(), 0.0);
      if (centre) {
        d.center_plane = *centre;
      }
      if (plane_corners.size() == 4) {
        const auto& c = plane_corners;
        d.length_mm = 0.5 * ((c[0] - c[1]).norm() + (c[2] - c[3]).norm());
        d.width_mm = 0.5 * ((c[0] - c[2]).norm() + (c[1] - c[3]).norm());
        const Eigen::Vector2d along = (c[0] - c[1]) + (c[2] - c[3]);
        d.angle_plane_rad = fold_angle(std::atan2(along.y(), along.x()), order);
      } else if (o.shape == ShapeKind::kCircle) {
        const double scale = mapper->scale_at(d.center_px, 0.0);
        d.length_mm = d.width_mm = 2.0 * o.radius_px * scale;
      }
      if (!options.classes.empty() && o.shape != ShapeKind::kTriangle) {
        if (auto m =
                options.classes.classify(o.shape, d.length_mm, d.width_mm,
                                         options.class_tolerance_mm, options.class_tolerance_rel)) {
          d.class_name = m->spec->name;
        }
      }
      if (centre && mapper->world()) {
        if (auto base = mapper->to_base(*centre, d.angle_plane_rad)) {
          d.has_base_pose = true;
          d.base_pose = *base;
          d.base_pose.rz_rad = fold_angle_centred(base->rz_rad, order);
        }
      }
    }
    (void)top;
    // The thesis has no quality figure; ours: how rectangular its corners are (eq. 2.13).
    if (o.corners_raw.size() == 4) {
      const auto& c = d.corners_px;
      const double l1 = (c[0] - c[1]).norm();
      const double l2 = (c[2] - c[3]).norm();
      const double w1 = (c[0] - c[2]).norm();
      const double w2 = (c[1] - c[3]).norm();
      const double mismatch =
          std::max(std::abs(l1 - l2) / std::max(l1, l2), std::abs(w1 - w2) / std::max(w1, w2));
      d.quality = std::clamp(1.0 - mismatch / options.thesis.rectangle_tolerance, 0.0, 1.0);
    } else {
      d.quality = 0.5;
    }
    result.detections.push_back(std::move(d));
  }
}

}  // namespace cell::vision
