#include "segmentation.hpp"

#include <algorithm>
#include <array>
#include <bit>
#include <cmath>
#include <cstring>

#if defined(__SSE2__)
#include <emmintrin.h>
#endif

namespace cell::vision::detail {
namespace {

std::int32_t find_root(std::vector<std::int32_t>& parent, std::int32_t i) {
  while (parent[static_cast<std::size_t>(i)] != i) {
    auto& p = parent[static_cast<std::size_t>(i)];
    p = parent[static_cast<std::size_t>(p)];  // path halving
    i = p;
  }
  return i;
}

void unite(std::vector<std::int32_t>& parent, std::int32_t a, std::int32_t b) {
  a = find_root(parent, a);
  b = find_root(parent, b);
  if (a == b) {
    return;
  }
  if (a < b) {
    parent[static_cast<std::size_t>(b)] = a;
  } else {
    parent[static_cast<std::size_t>(a)] = b;
  }
}

}  // namespace

void Segmenter::estimate_background(const cv::Mat& image, const SegmentationOptions& options) {
  block_ = options.block_px;
  shift_ = std::countr_zero(static_cast<unsigned>(block_));
  blocks_x_ = (width_ + block_ - 1) / block_;
  blocks_y_ = (height_ + block_ - 1) / block_;
  const std::size_t n = static_cast<std::size_t>(blocks_x_) * static_cast<std::size_t>(blocks_y_);
  raw_levels_.assign(n, 0.0F);
  levels_.assign(n, 0.0F);
  thresholds_.assign(n, options.fixed_threshold);
  // Sparse sample of each block (4 x 4 points); its upper quartile is the table level unless
  // most of the block is covered by parts, which the 3 x 3 maximum below then repairs.
  constexpr int kGrid = 4;
  for (int by = 0; by < blocks_y_; ++by) {
    const int y0 = by * block_;
    const int bh = std::min(block_, height_ - y0);
    for (int bx = 0; bx < blocks_x_; ++bx) {
      const int x0 = bx * block_;
      const int bw = std::min(block_, width_ - x0);
      samples_.clear();
      for (int j = 0; j < kGrid; ++j) {
        const int y = y0 + (2 * j + 1) * bh / (2 * kGrid);
        const std::uint8_t* row = image.ptr<std::uint8_t>(y);
        for (int i = 0; i < kGrid; ++i) {
          samples_.push_back(row[x0 + (2 * i + 1) * bw / (2 * kGrid)]);
        }
      }
      // The upper quartile of 16: the 5th largest (a running top 5, no sort).
      std::array<int, 5> top{-1, -1, -1, -1, -1};
      for (const std::uint8_t v : samples_) {
        int value = v;
        for (int& t : top) {  // branch-free insertion: max stays, min moves on
          const int hi = std::max(t, value);
          value = std::min(t, value);
          t = hi;
        }
      }
      raw_levels_[block_index(bx, by)] = static_cast<float>(top[4]);
    }
  }
  for (int by = 0; by < blocks_y_; ++by) {
    for (int bx = 0; bx < blocks_x_; ++bx) {
      float m = 0.0F;
      for (int dy = -1; dy <= 1; ++dy) {
        for (int dx = -1; dx <= 1; ++dx) {
          const int x = bx + dx;
          const int y = by + dy;
          if (x >= 0 && y >= 0 && x < blocks_x_ && y < blocks_y_) {
            m = std::max(m, raw_levels_[block_index(x, y)]);
          }
        }
      }
      const std::size_t i = block_index(bx, by);
      levels_[i] = m;
      if (options.mode == ThresholdMode::kAdaptive) {
        thresholds_[i] =
            std::clamp(static_cast<int>(std::lround(options.adaptive_ratio * m)), 1, 255);
      }
    }
  }
}

double Segmenter::background(double x, double y) const noexcept {
  // Block centres at ((b + 0.5) * block); clamp at the outer half blocks.
  const double gx = std::clamp(x / block_ - 0.5, 0.0, static_cast<double>(blocks_x_ - 1));
  const double gy = std::clamp(y / block_ - 0.5, 0.0, static_cast<double>(blocks_y_ - 1));
  const int x0 = std::min(static_cast<int>(gx), blocks_x_ - 1);
  const int y0 = std::min(static_cast<int>(gy), blocks_y_ - 1);
  const int x1 = std::min(x0 + 1, blocks_x_ - 1);
  const int y1 = std::min(y0 + 1, blocks_y_ - 1);
  const double tx = gx - x0;
  const double ty = gy - y0;
  auto at = [&](int bx, int by) { return static_cast<double>(levels_[block_index(bx, by)]); };
  return (1 - ty) * ((1 - tx) * at(x0, y0) + tx * at(x1, y0)) +
         ty * ((1 - tx) * at(x0, y1) + tx * at(x1, y1));
}

void Segmenter::segment(const cv::Mat& image, const SegmentationOptions& options) {
  width_ = image.cols;
  height_ = image.rows;
  estimate_background(image, options);
  scratch_runs_.clear();
  parent_.clear();
  int prev_begin = 0;
  int prev_end = 0;
  // Each row, 64 px at a time: the bit mask of its dark pixels (16 compared per SSE2
  // instruction, the block's threshold each), then its runs from the mask's rising and falling
  // bits: the bright table costs a few instructions per 64 px.
  const bool wide_blocks = block_ >= 16;
#if defined(__SSE2__)
  const __m128i bias = _mm_set1_epi8(static_cast<char>(0x80));
  thr_vectors_.resize(static_cast<std::size_t>(blocks_x_) * 16);
  int vector_row = -1;
#endif
  for (int y = 0; y < height_; ++y) {
    const std::uint8_t* row = image.ptr<std::uint8_t>(y);
    const int cur_begin = static_cast<int>(scratch_runs_.size());
    const int* thr_row = &thresholds_[block_index(0, y >> shift_)];
#if defined(__SSE2__)
    if ((y >> shift_) != vector_row) {  // the biased thresholds of this row of blocks
      vector_row = y >> shift_;
      for (int bx = 0; bx < blocks_x_; ++bx) {
        std::memset(&thr_vectors_[static_cast<std::size_t>(bx) * 16], thr_row[bx] ^ 0x80, 16);
      }
    }
#endif
    int start = -1;
    bool carry = false;  // the previous word's last bit
    for (int x0 = 0; x0 < width_; x0 += 64) {
      std::uint64_t bits = 0;
#if defined(__SSE2__)
      if (wide_blocks && x0 + 64 <= width_) {
        // The common case, unrolled: four 16-pixel compares, each against its block's threshold.
        const std::uint8_t* tv = thr_vectors_.data();
        auto mask16 = [&](int xs) {
          const __m128i t = _mm_loadu_si128(
              reinterpret_cast<const __m128i*>(tv + static_cast<std::size_t>(xs >> shift_) * 16));
          const __m128i v =
              _mm_xor_si128(_mm_loadu_si128(reinterpret_cast<const __m128i*>(row + xs)), bias);
          return static_cast<std::uint64_t>(
              static_cast<std::uint16_t>(_mm_movemask_epi8(_mm_cmplt_epi8(v, t))));
        };
        bits = mask16(x0) | (mask16(x0 + 16) << 16) | (mask16(x0 + 32) << 32) |
               (mask16(x0 + 48) << 48);
        if (bits == 0 && start < 0) {
          carry = false;
          continue;  // 64 px of table
        }
      } else
#endif
        for (int k = 0; k < 4; ++k) {
          const int xs = x0 + 16 * k;
          if (xs >= width_) {
            break;
          }
#if defined(__SSE2__)
          if (wide_blocks && xs + 16 <= width_) {
            // Unsigned v < t as signed (v ^ 0x80) < (t ^ 0x80).
            const __m128i tv = _mm_loadu_si128(reinterpret_cast<const __m128i*>(
                &thr_vectors_[static_cast<std::size_t>(xs >> shift_) * 16]));
            const __m128i v =
                _mm_xor_si128(_mm_loadu_si128(reinterpret_cast<const __m128i*>(row + xs)), bias);
            const __m128i lt = _mm_cmplt_epi8(v, tv);
            bits |= static_cast<std::uint64_t>(static_cast<std::uint16_t>(_mm_movemask_epi8(lt)))
                    << (16 * k);
            continue;
          }
#endif
          const int xe = std::min(xs + 16, width_);
          for (int x = xs; x < xe; ++x) {
            bits |= static_cast<std::uint64_t>(row[x] < thr_row[x >> shift_]) << (x - x0);
          }
        }
      // Bit i of `edges` is set where pixel x0 + i differs from the pixel before it.
      std::uint64_t edges = bits ^ ((bits << 1) | (carry ? 1U : 0U));
      carry = (bits >> 63) != 0;
      if (x0 + 64 > width_) {
        edges &= (std::uint64_t{1} << (width_ - x0)) - 1;  // past the row's end: nothing
      }
      while (edges != 0) {
        const int i = std::countr_zero(edges);
        edges &= edges - 1;
        const int x = x0 + i;
        if (((bits >> i) & 1U) != 0) {
          start = x;  // rises: dark from here
        } else {
          scratch_runs_.push_back({y, start, x - 1, 0});
          start = -1;
        }
      }
    }
    if (start >= 0) {
      scratch_runs_.push_back({y, start, width_ - 1, 0});
    }
    const int cur_end = static_cast<int>(scratch_runs_.size());
    for (int i = cur_begin; i < cur_end; ++i) {
      parent_.push_back(i);
    }
    // 8-connectivity with the previous row: runs overlap when they touch diagonally too.
    int j = prev_begin;
    for (int i = cur_begin; i < cur_end; ++i) {
      const Run& r = scratch_runs_[static_cast<std::size_t>(i)];
      while (j < prev_end && scratch_runs_[static_cast<std::size_t>(j)].x1 + 1 < r.x0) {
        ++j;
      }
      for (int k = j; k < prev_end && scratch_runs_[static_cast<std::size_t>(k)].x0 <= r.x1 + 1;
           ++k) {
        unite(parent_, i, k);
      }
    }
    prev_begin = cur_begin;
    prev_end = cur_end;
  }
  // Components: stats per root, drop dirt, then the runs grouped by component.
  const std::size_t n = scratch_runs_.size();
  compact_.assign(n, -1);
  blobs_.clear();
  std::vector<Blob>& blobs = blobs_;
  for (std::size_t i = 0; i < n; ++i) {
    const auto root = static_cast<std::size_t>(find_root(parent_, static_cast<std::int32_t>(i)));
    if (compact_[root] < 0) {
      compact_[root] = static_cast<std::int32_t>(blobs.size());
      Blob b;
      b.x_min = width_;
      b.y_min = height_;
      b.x_max = -1;
      b.y_max = -1;
      blobs.push_back(b);
    }
    const int id = compact_[root];
    Run& r = scratch_runs_[i];
    r.label = id;
    Blob& b = blobs[static_cast<std::size_t>(id)];
    b.area += r.x1 - r.x0 + 1;
    b.run_count += 1;
    b.x_min = std::min(b.x_min, r.x0);
    b.x_max = std::max(b.x_max, r.x1);
    b.y_min = std::min(b.y_min, r.y);
    b.y_max = std::max(b.y_max, r.y);
  }
  // Keep the blobs of min_area_px and more, renumbered in raster order of their first run.
  std::vector<int> renumber(blobs.size(), -1);
  std::vector<Blob> kept;
  dirt_ = 0;
  for (std::size_t i = 0; i < blobs.size(); ++i) {
    Blob b = blobs[i];
    if (b.area < options.min_area_px) {
      ++dirt_;
      continue;
    }
    b.border = b.x_min == 0 || b.y_min == 0 || b.x_max == width_ - 1 || b.y_max == height_ - 1;
    renumber[i] = static_cast<int>(kept.size());
    kept.push_back(b);
  }
  counts_.assign(kept.size() + 1, 0);
  for (const Run& r : scratch_runs_) {
    const int id = renumber[static_cast<std::size_t>(r.label)];
    if (id >= 0) {
      ++counts_[static_cast<std::size_t>(id) + 1];
    }
  }
  for (std::size_t i = 1; i < counts_.size(); ++i) {
    counts_[i] += counts_[i - 1];
  }
  for (std::size_t i = 0; i < kept.size(); ++i) {
    kept[i].first_run = counts_[i];
    kept[i].run_count = counts_[i + 1] - counts_[i];
  }
  runs_.resize(static_cast<std::size_t>(counts_.back()));
  for (const Run& r : scratch_runs_) {
    const int id = renumber[static_cast<std::size_t>(r.label)];
    if (id >= 0) {
      Run out = r;
      out.label = id;
      runs_[static_cast<std::size_t>(counts_[static_cast<std::size_t>(id)]++)] = out;
    }
  }
  blobs_ = std::move(kept);
}

}  // namespace cell::vision::detail
