#pragma once

#include <cstdint>
#include <opencv2/core.hpp>
#include <vector>

#include "cell/common/result.hpp"
#include "cell/vision/locate.hpp"

/// The fast pipeline's segmentation (internal): a per-block table level, thresholds, dark runs
/// per row and their 8-connected components (union-find over runs).
namespace cell::vision::detail {

/// One run of dark pixels on a row: columns x0..x1 inclusive.
struct Run {
  std::int32_t y = 0;
  std::int32_t x0 = 0;
  std::int32_t x1 = 0;
  std::int32_t label = 0;
};

/// One 8-connected component of dark pixels.
struct Blob {
  int first_run = 0;  ///< into Segmenter::runs(), which are grouped by blob
  int run_count = 0;
  int area = 0;
  int x_min = 0;
  int x_max = 0;
  int y_min = 0;
  int y_max = 0;
  bool border = false;  ///< touches the image border
};

class Segmenter {
 public:
  /// Segments `image` (CV_8UC1). Keeps references to nothing: the image must stay alive while
  /// the accessors are used. Blobs below min_area_px are counted in dirt().
  void segment(const cv::Mat& image, const SegmentationOptions& options);

  /// Table level (bright) at a pixel, interpolated between block centres.
  double background(double x, double y) const noexcept;
  /// The dark threshold of the block holding pixel (x, y): dark is grey < threshold.
  int threshold(int x, int y) const noexcept {
    return thresholds_[block_index(x >> shift_, y >> shift_)];
  }

  const std::vector<Run>& runs() const noexcept { return runs_; }
  const std::vector<Blob>& blobs() const noexcept { return blobs_; }
  int dirt() const noexcept { return dirt_; }

 private:
  void estimate_background(const cv::Mat& image, const SegmentationOptions& options);
  /// Index of block (bx, by) in the per-block tables (row by row, blocks_x_ to a row).
  std::size_t block_index(int bx, int by) const noexcept {
    return static_cast<std::size_t>(by) * static_cast<std::size_t>(blocks_x_) +
           static_cast<std::size_t>(bx);
  }

  int width_ = 0;
  int height_ = 0;
  int block_ = 32;
  int shift_ = 5;  // log2(block_): block_px is a power of two
  int blocks_x_ = 0;
  int blocks_y_ = 0;
  std::vector<float> levels_;      // per block, after the 3 x 3 max
  std::vector<float> raw_levels_;  // scratch
  std::vector<int> thresholds_;    // per block
  std::vector<Run> scratch_runs_;
  std::vector<Run> runs_;
  std::vector<std::int32_t> parent_;
  std::vector<std::int32_t> compact_;
  std::vector<Blob> blobs_;
  std::vector<int> counts_;
  std::vector<std::uint8_t> samples_;
  std::vector<std::uint8_t> thr_vectors_;  // 16 copies of each block's biased threshold
  int dirt_ = 0;
};

}  // namespace cell::vision::detail
