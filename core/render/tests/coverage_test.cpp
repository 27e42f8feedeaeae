// The exact-coverage rasteriser and the sensor noise (renderer internals).
#include <cmath>
#include <random>

#include <gtest/gtest.h>

#include "coverage.hpp"

namespace cell::render::detail {
namespace {

constexpr float kTol = 2e-5F;

/// Exact area of `poly` inside the unit pixel [i, i+1) x [j, j+1) by clipping.
double pixel_area(std::vector<RasterPoint> poly, int i, int j) {
  auto clip = [&](auto inside, auto cross) {
    std::vector<RasterPoint> out;
    for (std::size_t k = 0; k < poly.size(); ++k) {
      const RasterPoint a = poly[k];
      const RasterPoint b = poly[(k + 1) % poly.size()];
      if (inside(a)) {
        out.push_back(a);
      }
      if (inside(a) != inside(b)) {
        out.push_back(cross(a, b));
      }
    }
    poly = out;
  };
  auto at_x = [](double x) {
    return [x](RasterPoint a, RasterPoint b) {
      return RasterPoint{x, a.y + (b.y - a.y) * (x - a.x) / (b.x - a.x)};
    };
  };
  auto at_y = [](double y) {
    return [y](RasterPoint a, RasterPoint b) {
      return RasterPoint{a.x + (b.x - a.x) * (y - a.y) / (b.y - a.y), y};
    };
  };
  clip([&](RasterPoint p) { return p.x >= i; }, at_x(i));
  clip([&](RasterPoint p) { return p.x <= i + 1; }, at_x(i + 1));
  clip([&](RasterPoint p) { return p.y >= j; }, at_y(j));
  clip([&](RasterPoint p) { return p.y <= j + 1; }, at_y(j + 1));
  double a2 = 0.0;
  for (std::size_t k = 0; k < poly.size(); ++k) {
    const auto& a = poly[k];
    const auto& b = poly[(k + 1) % poly.size()];
    a2 += a.x * b.y - b.x * a.y;
  }
  return std::abs(a2) / 2.0;
}

/// Canvas of zeros, one polygon composited with grey 1: each pixel then holds its coverage.
std::vector<float> coverage_image(const std::vector<RasterPoint>& poly, int w, int h) {
  CoverageAccumulator acc;
  acc.reset(0, 0, w, h);
  acc.add_ring(poly.data(), static_cast<int>(poly.size()), 1.0F, 1.0F);
  std::vector<float> canvas(static_cast<std::size_t>(w * h), 0.0F);
  acc.composite_over(canvas.data(), w, h);
  return canvas;
}

TEST(Coverage, EveryPixelHoldsTheExactAreaOfASlantedPolygon) {
  const std::vector<RasterPoint> poly = {{2.3, 1.7}, {13.9, 4.1}, {11.2, 12.6}, {3.05, 9.45}};
  const auto img = coverage_image(poly, 16, 14);
  double total = 0.0;
  for (int j = 0; j < 14; ++j) {
    for (int i = 0; i < 16; ++i) {
      const float expected = static_cast<float>(pixel_area(poly, i, j));
      const std::size_t index = static_cast<std::size_t>(j) * 16 + static_cast<std::size_t>(i);
      EXPECT_NEAR(img[index], expected, kTol) << i << "," << j;
      total += img[index];
    }
  }
  double area2 = 0.0;
  for (std::size_t k = 0; k < poly.size(); ++k) {
    area2 += poly[k].x * poly[(k + 1) % poly.size()].y - poly[(k + 1) % poly.size()].x * poly[k].y;
  }
  EXPECT_NEAR(total, std::abs(area2) / 2.0, 1e-4);
}

TEST(Coverage, WindingDirectionDoesNotMatter) {
  std::vector<RasterPoint> poly = {{1.25, 1.5}, {6.5, 2.25}, {4.0, 7.75}};
  const auto a = coverage_image(poly, 9, 9);
  std::reverse(poly.begin(), poly.end());
  const auto b = coverage_image(poly, 9, 9);
  for (std::size_t k = 0; k < a.size(); ++k) {
    EXPECT_NEAR(a[k], b[k], 1e-6F);
    EXPECT_GE(a[k], 0.0F);
  }
}

TEST(Coverage, AdjacentFacesAccumulateWithoutASeam) {
  // Two triangles sharing a diagonal, accumulated together, cover their square exactly: no
  // pixel along the shared edge lets the background through.
  CoverageAccumulator acc;
  acc.reset(0, 0, 10, 10);
  const std::vector<RasterPoint> t1 = {{1.3, 1.3}, {8.7, 1.3}, {8.7, 8.7}};
  const std::vector<RasterPoint> t2 = {{1.3, 1.3}, {8.7, 8.7}, {1.3, 8.7}};
  acc.add_ring(t1.data(), 3, 1.0F, 0.0F);
  acc.add_ring(t2.data(), 3, 1.0F, 0.0F);
  std::vector<float> canvas(100, 1.0F);  // white background, black faces
  acc.composite_over(canvas.data(), 10, 10);
  for (int j = 2; j < 8; ++j) {
    for (int i = 2; i < 8; ++i) {
      EXPECT_NEAR(canvas[static_cast<std::size_t>(j * 10 + i)], 0.0F, 1e-6F) << i << "," << j;
    }
  }
  EXPECT_NEAR(canvas[1 * 10 + 1], 1.0F - 0.7F * 0.7F, 1e-6F);  // corner pixel: 0.49 covered
}

TEST(Coverage, PolygonsReachingOutsideTheCanvasAreClipped) {
  CoverageAccumulator acc;
  acc.reset(-5, 0, 20, 6);  // the window starts left of the canvas
  const std::vector<RasterPoint> poly = {{-4.5, 0.0}, {3.5, 0.0}, {3.5, 4.0}, {-4.5, 4.0}};
  acc.add_ring(poly.data(), 4, 1.0F, 1.0F);
  std::vector<float> canvas(std::size_t{8} * 6, 0.0F);
  acc.composite_over(canvas.data(), 8, 6);
  EXPECT_NEAR(canvas[0], 1.0F, 1e-6F);
  EXPECT_NEAR(canvas[3], 0.5F, 1e-6F);
  EXPECT_NEAR(canvas[4], 0.0F, 1e-6F);
  EXPECT_NEAR(canvas[5 * 8 + 0], 0.0F, 1e-6F);
}

TEST(SensorNoise, IsSeededAndHasTheRequestedSigma) {
  const std::vector<float> flat(200000, 100.0F);
  std::vector<std::uint8_t> a(flat.size());
  std::vector<std::uint8_t> b(flat.size());
  std::vector<std::uint8_t> c(flat.size());
  add_noise_and_quantise(flat.data(), flat.size(), 3.0, 42, a.data());
  add_noise_and_quantise(flat.data(), flat.size(), 3.0, 42, b.data());
  add_noise_and_quantise(flat.data(), flat.size(), 3.0, 43, c.data());
  EXPECT_EQ(a, b);
  EXPECT_NE(a, c);
  double mean = 0.0;
  double var = 0.0;
  for (const auto v : a) {
    mean += v;
  }
  mean /= static_cast<double>(a.size());
  for (const auto v : a) {
    var += (v - mean) * (v - mean);
  }
  const double sigma = std::sqrt(var / static_cast<double>(a.size()));
  EXPECT_NEAR(mean, 100.0, 0.05);
  // Rounding to integers adds 1/12 grey^2 of variance.
  EXPECT_NEAR(sigma, std::sqrt(9.0 + 1.0 / 12.0), 0.05);
  std::vector<std::uint8_t> quiet(flat.size());
  add_noise_and_quantise(flat.data(), flat.size(), 0.0, 42, quiet.data());
  EXPECT_EQ(quiet[0], 100);
}

}  // namespace
}  // namespace cell::render::detail
