#pragma once

#include <optional>
#include <vector>

#include <Eigen/Core>
#include <opencv2/core.hpp>

#include "cell/common/result.hpp"

/// A plain marker located in an image: a blob darker (or brighter) than what surrounds it, as
/// a part on a belt is. The belt calibration and the fixed camera's marker procedure use it;
/// vision proper (class, grasp) is services/vision's. Pixels: u right, v down, (0, 0) at the
/// centre of the top-left pixel.
namespace cell::calibration {

struct MarkerOptions {
  bool bright = false;          ///< true: a blob brighter than its background
  int threshold = -1;           ///< grey threshold; -1: Otsu's over the region
  /// 0: threshold the grey image itself (the marker's background must be the region's only
  /// other level). > 0: threshold the marker's contrast to its local background instead, the
  /// background estimated by a grey closing (dark markers) or opening (bright ones) with a
  /// square of this side [px], which must exceed the markers' size. Needed when the region
  /// holds more than two levels: dark parts on a grey belt between white table tops, where a
  /// global threshold splits table from belt and the parts merge into the belt. `threshold`
  /// is then a contrast in grey levels (-1: Otsu's over the contrast image).
  int background_px = 0;
  double min_area_px = 50.0;    ///< smaller blobs are noise
  double max_area_px = 1e7;
  /// Search only here (empty: the whole image).
  cv::Rect region;
  Status validate() const;
};

struct Marker {
  Eigen::Vector2d centroid_px = Eigen::Vector2d::Zero();  ///< grey-weighted, sub-pixel
  double area_px = 0.0;
  cv::Rect bounds;
  bool touches_border = false;  ///< cut by the image (or region) edge: its centroid is biased
};

/// Every blob of the wanted polarity, largest first. The centroid weighs each pixel of the
/// blob (dilated by 2 px so the anti-aliased edge counts) by its contrast between the blob's
/// interior and the ring around it, which makes it sub-pixel. Errors: kInvalidArgument for an empty or non-8-bit image or bad
/// options. Thread-safe.
Result<std::vector<Marker>> locate_markers(const cv::Mat& image, const MarkerOptions& options = {});

}  // namespace cell::calibration
