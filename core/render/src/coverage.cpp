#include "coverage.hpp"

#include <algorithm>
#include <array>
#include <cmath>

namespace cell::render::detail {

void CoverageAccumulator::reset(int x0, int y0, int width, int height) {
  x0_ = x0;
  y0_ = y0;
  width_ = std::max(width, 0);
  height_ = std::max(height, 0);
  // Two spare columns: an edge at x = width writes column width (and width + 1 in the
  // single-column case), beyond what the composite reads.
  stride_ = width_ + 2;
  const std::size_t n = static_cast<std::size_t>(stride_) * static_cast<std::size_t>(height_);
  if (coverage_.size() < n) {
    coverage_.resize(n);
    shade_.resize(n);
  }
  std::fill_n(coverage_.begin(), n, 0.0F);
  std::fill_n(shade_.begin(), n, 0.0F);
}

void CoverageAccumulator::add_ring(const RasterPoint* pts, int n, float coverage_weight,
                                   float shade_weight) {
  if (n < 3 || height_ == 0) {
    return;
  }
  // Shoelace area in raster coordinates (y down). With the accumulation below a ring of
  // positive shoelace area yields negative running sums, so flip its weights.
  double area2 = 0.0;
  for (int i = 0, j = n - 1; i < n; j = i++) {
    area2 += pts[j].x * pts[i].y - pts[i].x * pts[j].y;
  }
  if (area2 == 0.0) {
    return;
  }
  const float sign = area2 > 0.0 ? -1.0F : 1.0F;
  const float wc = coverage_weight * sign;
  const float ws = shade_weight * sign;
  for (int i = 0, j = n - 1; i < n; j = i++) {
    line(pts[j].x - x0_, pts[j].y - y0_, pts[i].x - x0_, pts[i].y - y0_, wc, ws);
  }
}

// The signed area between the segment and the window's right side, per row, added to the
// column where it starts; the running sum along a row is then the exact covered fraction.
// Port of font-rs's accumulate rasteriser (Raph Levien, Apache-2.0 / MIT), in double.
void CoverageAccumulator::line(double xa, double ya, double xb, double yb, float wc, float ws) {
  if (ya == yb) {
    return;
  }
  double dir = 1.0;
  if (ya > yb) {
    std::swap(xa, xb);
    std::swap(ya, yb);
    dir = -1.0;
  }
  const double dxdy = (xb - xa) / (yb - ya);
  const double y_start = std::max(ya, 0.0);
  const double y_end = std::min(yb, static_cast<double>(height_));
  if (y_start >= y_end) {
    return;
  }
  double x = xa + (y_start - ya) * dxdy;
  const double max_x = static_cast<double>(width_);
  auto add = [&](float* rc, float* rs, int xi, double amount) {
    rc[xi] += static_cast<float>(amount) * wc;
    rs[xi] += static_cast<float>(amount) * ws;
  };
  for (int yi = static_cast<int>(std::floor(y_start)); yi < height_ && yi < y_end; ++yi) {
    const double dy = std::min(static_cast<double>(yi + 1), y_end) -
                      std::max(static_cast<double>(yi), y_start);
    const double x_next = x + dxdy * dy;
    const double d = dy * dir;
    // Clamp into the window (points are inside by contract; this guards rounding).
    const double x_lo = std::clamp(std::min(x, x_next), 0.0, max_x);
    const double x_hi = std::clamp(std::max(x, x_next), 0.0, max_x);
    float* rc = coverage_.data() + static_cast<std::ptrdiff_t>(yi) * stride_;
    float* rs = shade_.data() + static_cast<std::ptrdiff_t>(yi) * stride_;
    const double x_lo_floor = std::floor(x_lo);
    const int x_lo_i = static_cast<int>(x_lo_floor);
    const double x_hi_ceil = std::ceil(x_hi);
    const int x_hi_i = static_cast<int>(x_hi_ceil);
    if (x_hi_i <= x_lo_i + 1) {
      // Within one pixel column: the part right of the mean x.
      const double xmf = 0.5 * (x_lo + x_hi) - x_lo_floor;
      add(rc, rs, x_lo_i, d - d * xmf);
      add(rc, rs, x_lo_i + 1, d * xmf);
    } else {
      const double s = 1.0 / (x_hi - x_lo);
      const double x_lo_f = x_lo - x_lo_floor;
      const double a0 = 0.5 * s * (1.0 - x_lo_f) * (1.0 - x_lo_f);
      const double x_hi_f = x_hi - x_hi_ceil + 1.0;
      const double am = 0.5 * s * x_hi_f * x_hi_f;
      add(rc, rs, x_lo_i, d * a0);
      if (x_hi_i == x_lo_i + 2) {
        add(rc, rs, x_lo_i + 1, d * (1.0 - a0 - am));
      } else {
        const double a1 = s * (1.5 - x_lo_f);
        add(rc, rs, x_lo_i + 1, d * (a1 - a0));
        for (int xi = x_lo_i + 2; xi < x_hi_i - 1; ++xi) {
          add(rc, rs, xi, d * s);
        }
        const double a2 = a1 + (x_hi_i - x_lo_i - 3) * s;
        add(rc, rs, x_hi_i - 1, d * (1.0 - a2 - am));
      }
      add(rc, rs, x_hi_i, d * am);
    }
    x = x_next;
  }
}

template <typename Blend>
void CoverageAccumulator::composite(float* canvas, int canvas_width, int canvas_height,
                                    Blend blend) const {
  const int col_begin = std::max(0, -x0_);
  const int col_end = std::min(width_, canvas_width - x0_);
  for (int r = 0; r < height_; ++r) {
    const int y = y0_ + r;
    if (y < 0 || y >= canvas_height) {
      continue;
    }
    const float* rc = coverage_.data() + static_cast<std::ptrdiff_t>(r) * stride_;
    const float* rs = shade_.data() + static_cast<std::ptrdiff_t>(r) * stride_;
    float* row = canvas + static_cast<std::ptrdiff_t>(y) * canvas_width + x0_;
    float acc_c = 0.0F;
    float acc_s = 0.0F;
    // Columns left of the canvas still feed the running sums.
    for (int c = 0; c < col_begin; ++c) {
      acc_c += rc[c];
      acc_s += rs[c];
    }
    for (int c = col_begin; c < col_end; ++c) {
      acc_c += rc[c];
      acc_s += rs[c];
      if (acc_c > 1e-7F || acc_c < -1e-7F) {
        row[c] = blend(row[c], std::clamp(acc_c, 0.0F, 1.0F), acc_s);
      }
    }
  }
}

void CoverageAccumulator::composite_over(float* canvas, int canvas_width,
                                         int canvas_height) const {
  composite(canvas, canvas_width, canvas_height,
            [](float p, float c, float s) { return p * (1.0F - c) + s; });
}

void CoverageAccumulator::composite_modulate(float* canvas, int canvas_width,
                                             int canvas_height) const {
  composite(canvas, canvas_width, canvas_height,
            [](float p, float c, float s) { return p * (1.0F - c + s); });
}

namespace {

constexpr int kNoiseBits = 12;
constexpr int kNoiseLevels = 1 << kNoiseBits;

/// Standard normal quantiles at (i + 0.5) / 4096, rescaled to unit variance. Built once.
const std::array<float, kNoiseLevels>& gaussian_table() {
  static const std::array<float, kNoiseLevels> table = [] {
    std::array<double, kNoiseLevels> q{};
    for (int i = 0; i < kNoiseLevels; ++i) {
      const double p = (i + 0.5) / kNoiseLevels;
      double lo = -10.0;
      double hi = 10.0;
      for (int it = 0; it < 80; ++it) {  // bisection on the normal CDF
        const double mid = 0.5 * (lo + hi);
        if (0.5 * std::erfc(-mid / std::sqrt(2.0)) < p) {
          lo = mid;
        } else {
          hi = mid;
        }
      }
      q[static_cast<std::size_t>(i)] = 0.5 * (lo + hi);
    }
    double var = 0.0;
    for (double v : q) {
      var += v * v;
    }
    const double scale = 1.0 / std::sqrt(var / kNoiseLevels);
    std::array<float, kNoiseLevels> t{};
    for (std::size_t i = 0; i < t.size(); ++i) {
      t[i] = static_cast<float>(q[i] * scale);
    }
    return t;
  }();
  return table;
}

std::uint64_t splitmix64(std::uint64_t& state) {
  std::uint64_t z = (state += 0x9E3779B97F4A7C15ULL);
  z = (z ^ (z >> 30U)) * 0xBF58476D1CE4E5B9ULL;
  z = (z ^ (z >> 27U)) * 0x94D049BB133111EBULL;
  return z ^ (z >> 31U);
}

/// xoshiro256** (Blackman & Vigna): fast, and the same sequence on every platform.
class Xoshiro256 {
 public:
  explicit Xoshiro256(std::uint64_t seed) {
    for (auto& word : s_) {
      word = splitmix64(seed);
    }
  }
  std::uint64_t next() {
    const std::uint64_t result = rotl(s_[1] * 5, 7) * 9;
    const std::uint64_t t = s_[1] << 17U;
    s_[2] ^= s_[0];
    s_[3] ^= s_[1];
    s_[1] ^= s_[2];
    s_[0] ^= s_[3];
    s_[2] ^= t;
    s_[3] = rotl(s_[3], 45);
    return result;
  }

 private:
  static std::uint64_t rotl(std::uint64_t x, int k) {
    return (x << static_cast<unsigned>(k)) | (x >> static_cast<unsigned>(64 - k));
  }
  std::array<std::uint64_t, 4> s_{};
};

inline std::uint8_t quantise(float v) {
  v = std::clamp(v, 0.0F, 255.0F);
  // Truncating v + 0.5 rounds half up, and is one grey level high only for v within one float
  // ulp below x.5; std::lround would make it a library call per pixel (2-3x this loop).
  return static_cast<std::uint8_t>(v + 0.5F);  // NOLINT(bugprone-incorrect-roundings)
}

}  // namespace

void add_noise_and_quantise(const float* canvas, std::size_t count, double sigma,
                            std::uint64_t seed, std::uint8_t* out) {
  if (!(sigma > 0.0)) {
    for (std::size_t i = 0; i < count; ++i) {
      out[i] = quantise(canvas[i]);
    }
    return;
  }
  const auto& table = gaussian_table();
  const float s = static_cast<float>(sigma);
  Xoshiro256 rng(seed);
  constexpr std::size_t kPerDraw = 64 / kNoiseBits;  // 5 samples of 12 bits per 64-bit draw
  constexpr std::uint64_t kMask = kNoiseLevels - 1;
  // In chunks: draw the noise (scalar: the generator and the table lookups), then add, clip
  // and round (a loop the compiler vectorises).
  constexpr std::size_t kChunk = 1280;  // a multiple of kPerDraw
  std::array<float, kChunk> noise;
  for (std::size_t base = 0; base < count; base += kChunk) {
    const std::size_t n = std::min(kChunk, count - base);
    for (std::size_t k = 0; k < n;) {
      std::uint64_t bits = rng.next();
      for (std::size_t j = 0; j < kPerDraw && k < n; ++j, ++k) {
        noise[k] = table[bits & kMask];
        bits >>= kNoiseBits;
      }
    }
    const float* in = canvas + base;
    std::uint8_t* o = out + base;
    for (std::size_t k = 0; k < n; ++k) {
      const float v = std::clamp(in[k] + s * noise[k], 0.0F, 255.0F);  // as quantise() rounds
      o[k] = static_cast<std::uint8_t>(v + 0.5F);  // NOLINT(bugprone-incorrect-roundings)
    }
  }
}

}  // namespace cell::render::detail
