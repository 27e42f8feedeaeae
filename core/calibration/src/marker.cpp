#include "cell/calibration/marker.hpp"

#include <algorithm>
#include <cmath>

#include <fmt/format.h>
#include <opencv2/imgproc.hpp>

namespace cell::calibration {

Status MarkerOptions::validate() const {
  if (threshold < -1 || threshold > 255) {
    return Error{Errc::kInvalidArgument,
                 fmt::format("marker options: threshold must be -1 (Otsu) or 0..255, got {}",
                             threshold)};
  }
  if (background_px < 0 || background_px == 1 || (background_px > 0 && background_px % 2 == 0)) {
    return Error{Errc::kInvalidArgument,
                 fmt::format("marker options: background_px must be 0 (off) or an odd side >= 3, "
                             "got {}",
                             background_px)};
  }
  if (!(min_area_px >= 0.0) || !(max_area_px > min_area_px)) {
    return Error{Errc::kInvalidArgument, "marker options: need 0 <= min_area_px < max_area_px"};
  }
  return ok_status();
}

Result<std::vector<Marker>> locate_markers(const cv::Mat& image, const MarkerOptions& options) {
  CELL_TRY(options.validate());
  if (image.empty() || image.type() != CV_8UC1) {
    return Error{Errc::kInvalidArgument, "marker search needs an 8-bit grey image"};
  }
  try {
    const cv::Rect all(0, 0, image.cols, image.rows);
    const cv::Rect region = options.region.area() > 0 ? (options.region & all) : all;
    const cv::Mat roi = image(region);
    cv::Mat binary;
    if (options.background_px > 0) {
      // The marker's contrast to its local background (a top-hat): large uniform areas of any
      // level (belt, table) go to 0, anything smaller than the square stands out.
      cv::Mat contrast;
      cv::morphologyEx(roi, contrast, options.bright ? cv::MORPH_TOPHAT : cv::MORPH_BLACKHAT,
                       cv::getStructuringElement(
                           cv::MORPH_RECT, cv::Size(options.background_px, options.background_px)));
      (void)(options.threshold >= 0
              ? cv::threshold(contrast, binary, options.threshold, 255, cv::THRESH_BINARY)
              : cv::threshold(contrast, binary, 0, 255, cv::THRESH_BINARY | cv::THRESH_OTSU));
    } else {
      const int type = options.bright ? cv::THRESH_BINARY : cv::THRESH_BINARY_INV;
      (void)(options.threshold >= 0
                 ? cv::threshold(roi, binary, options.threshold, 255, type)
                 : cv::threshold(roi, binary, 0, 255, type | cv::THRESH_OTSU));
    }
    cv::Mat labels;
    cv::Mat stats;
    cv::Mat centroids;
    const int n = cv::connectedComponentsWithStats(binary, labels, stats, centroids, 8, CV_32S);
    std::vector<Marker> out;
    for (int l = 1; l < n; ++l) {
      const double area = stats.at<int>(l, cv::CC_STAT_AREA);
      if (area < options.min_area_px || area > options.max_area_px) {
        continue;
      }
      const cv::Rect box(stats.at<int>(l, cv::CC_STAT_LEFT), stats.at<int>(l, cv::CC_STAT_TOP),
                         stats.at<int>(l, cv::CC_STAT_WIDTH), stats.at<int>(l, cv::CC_STAT_HEIGHT));
      Marker m;
      m.area_px = area;
      m.bounds = cv::Rect(box.x + region.x, box.y + region.y, box.width, box.height);
      m.touches_border = box.x <= 0 || box.y <= 0 || box.x + box.width >= roi.cols ||
                         box.y + box.height >= roi.rows;
      // Contrast-weighted centroid over the blob grown by 2 px: an edge pixel half covered
      // counts half, so the centroid follows the exact coverage of the part. The background
      // level comes from a ring 4 px and more outside the blob, the blob's from its interior.
      const cv::Rect grown = (cv::Rect(box.x - 8, box.y - 8, box.width + 16, box.height + 16)) &
                             cv::Rect(0, 0, roi.cols, roi.rows);
      const cv::Mat blob = (labels(grown) == l);
      cv::Mat mask;
      cv::Mat far;
      cv::Mat core;
      cv::dilate(blob, mask, cv::getStructuringElement(cv::MORPH_RECT, cv::Size(5, 5)));
      cv::dilate(blob, far, cv::getStructuringElement(cv::MORPH_RECT, cv::Size(9, 9)));
      cv::erode(blob, core, cv::getStructuringElement(cv::MORPH_RECT, cv::Size(3, 3)));
      const cv::Mat patch = roi(grown);
      const double inside =
          cv::mean(patch, cv::countNonZero(core) > 0 ? core : blob)[0];
      cv::Mat ring;
      cv::bitwise_not(far, ring);
      if (cv::countNonZero(ring) == 0) {
        continue;  // no background around it: a blob filling the region is not a marker
      }
      const double outside = cv::mean(patch, ring)[0];
      if (std::abs(inside - outside) < 1.0) {
        continue;
      }
      double sw = 0.0;
      double su = 0.0;
      double sv = 0.0;
      for (int y = 0; y < grown.height; ++y) {
        for (int x = 0; x < grown.width; ++x) {
          if (mask.at<std::uint8_t>(y, x) == 0) {
            continue;
          }
          const double g = patch.at<std::uint8_t>(y, x);
          const double w = std::clamp((g - outside) / (inside - outside), 0.0, 1.0);
          sw += w;
          su += w * (x + grown.x + region.x);
          sv += w * (y + grown.y + region.y);
        }
      }
      if (sw <= 0.0) {
        continue;
      }
      m.centroid_px = Eigen::Vector2d(su / sw, sv / sw);
      out.push_back(m);
    }
    std::sort(out.begin(), out.end(),
              [](const Marker& a, const Marker& b) { return a.area_px > b.area_px; });
    return out;
  } catch (const cv::Exception& e) {
    return Error{Errc::kInvalidArgument, fmt::format("marker search: {}", e.what())};
  }
}

}  // namespace cell::calibration
