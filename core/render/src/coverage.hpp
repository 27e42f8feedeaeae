#pragma once

#include <cstdint>
#include <vector>

/// Exact area coverage of polygons by signed-area accumulation (the technique of font
/// rasterisers such as font-rs and stb_truetype's v2 rasteriser): each edge adds, per pixel
/// row, the signed area it sweeps to its right into an accumulation buffer; a running sum
/// along the row then gives every pixel's covered fraction exactly (to float precision). The
/// accumulation is linear, so several polygons that do not overlap (the front faces of one
/// convex body), or one polygon at several instants with weights 1/n (motion blur), are
/// accumulated together and composited in one pass.
///
/// Raster coordinates: X = u + 0.5, Y = v + 0.5, so pixel (i, j) covers [i, i+1) x [j, j+1).
namespace cell::render::detail {

/// A 2-D point in raster coordinates.
struct RasterPoint {
  double x;
  double y;
};

/// Accumulation window plus two buffers: coverage and shade (coverage times grey).
/// Not thread-safe; reused across bodies and frames (no allocation once grown).
class CoverageAccumulator {
 public:
  /// Starts a window of columns [x0, x0 + width) and rows [y0, y0 + height) (raster integer
  /// coordinates); zeroes it. Points added later must lie within x in [x0, x0 + width].
  void reset(int x0, int y0, int width, int height);

  /// Adds the closed ring pts[0..n) (n >= 3). Coverage counts with weight `coverage_weight`
  /// and shade with `shade_weight` (coverage_weight times the ring's grey value). The sign
  /// of the ring's orientation is taken care of here: either winding gives positive coverage.
  void add_ring(const RasterPoint* pts, int n, float coverage_weight, float shade_weight);

  /// Composites the window over `canvas` (row-major floats, canvas_width x canvas_height):
  /// pixel = pixel * (1 - coverage) + shade.
  void composite_over(float* canvas, int canvas_width, int canvas_height) const;

  /// Composites a surface lit like the table under it: pixel = pixel * (1 - coverage + shade),
  /// where shade accumulated coverage times (reflectance / table reflectance).
  void composite_modulate(float* canvas, int canvas_width, int canvas_height) const;

  int x0() const noexcept { return x0_; }
  int y0() const noexcept { return y0_; }
  int width() const noexcept { return width_; }
  int height() const noexcept { return height_; }

 private:
  void line(double xa, double ya, double xb, double yb, float wc, float ws);
  template <typename Blend>
  void composite(float* canvas, int canvas_width, int canvas_height, Blend blend) const;

  int x0_ = 0;
  int y0_ = 0;
  int width_ = 0;
  int height_ = 0;
  int stride_ = 0;
  std::vector<float> coverage_;
  std::vector<float> shade_;
};

/// Adds seeded Gaussian noise of standard deviation `sigma` (grey levels) to `canvas` and
/// rounds into `out` (0..255). Deterministic in (canvas, sigma, seed). sigma == 0: rounding only.
void add_noise_and_quantise(const float* canvas, std::size_t count, double sigma,
                            std::uint64_t seed, std::uint8_t* out);

}  // namespace cell::render::detail
