// Touching and nearly touching parts: separated, or reported as such; never silently merged.
#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include "cell/vision/locate.hpp"
#include "scenes.hpp"

namespace cell::vision {
namespace {

using testing::Cell;
using testing::Lights;

// Two IC bodies (no leads) side by side, 0.3 and 0.15 mm apart: about one pixel or less,
// which the adaptive threshold bridges with the grey of partly covered pixels. The grey seam
// inside the blob gives it away; a threshold near the body's own grey splits it, and each part
// is reported at its place, flagged as touching: located (its side along the seam has no clean
// crossing, so it is fitted when three sides suffice) or as an unknown part, never merged.
TEST(TouchingParts, NearlyTouchingBodiesAreSeparatedAndFlagged) {
  const Cell& cell = Cell::get();
  auto locator = Locator::create(LocateOptions{});
  ASSERT_TRUE(locator);
  const Eigen::Vector2d c = cell.window(30.0).center();
  for (double gap_mm : {0.3, 0.15}) {
    const double yaw = 0.3;
    const Eigen::Vector2d x_axis(std::cos(yaw), std::sin(yaw));
    const Eigen::Vector2d y_axis(-std::sin(yaw), std::cos(yaw));
    const Eigen::Vector2d b = c + (7.0 + gap_mm) * y_axis + 2.0 * x_axis;  // 7 mm wide bodies
    const std::vector<render::Part> parts{cell.part("a", "ic_7x30", c.x(), c.y(), yaw, false),
                                          cell.part("b", "ic_7x30", b.x(), b.y(), yaw, false)};
    const auto frame = cell.render("near", parts, cell.aligned_joints(), Lights::kTubes, 31);
    const auto result =
        locator->locate(frame.image, cell.mapper(cell.true_calibration(), frame.joints));
    ASSERT_TRUE(result);
    ASSERT_EQ(result->detections.size(), 2U) << gap_mm;
    EXPECT_EQ(result->report.split, 1) << gap_mm;
    for (const auto& t : frame.truth) {
      const Detection* nearest = nullptr;
      for (const Detection& d : result->detections) {
        if (nearest == nullptr ||
            (d.center_px - t.center_px).norm() < (nearest->center_px - t.center_px).norm()) {
          nearest = &d;
        }
      }
      EXPECT_TRUE(nearest->touching);
      if (nearest->class_name == "unknown") {
        EXPECT_LT((nearest->center_px - t.center_px).norm(), 3.0) << gap_mm;
      } else {
        EXPECT_EQ(nearest->class_name, "ic_7x30");
        EXPECT_LT((nearest->center_px - t.center_px).norm(), 0.3) << gap_mm;
      }
    }
  }
}

// Parts that really touch (an IC's end against another's side: a T) cannot be told apart by
// any threshold or erosion; vision reports the blob as one `unknown`, touching, quality 0, and
// never as a part of a known class.
TEST(TouchingParts, AReallyTouchingPairIsReportedAsUnknownNotMerged) {
  const Cell& cell = Cell::get();
  auto locator = Locator::create(LocateOptions{});
  ASSERT_TRUE(locator);
  const Eigen::Vector2d c = cell.window(30.0).center();
  const std::vector<render::Part> parts{
      cell.part("c", "dip14", c.x(), c.y(), 0.0, true),
      cell.part("d", "dip14", c.x() + 9.525 + 3.175, c.y(), 1.5708, false),
      cell.part("e", "ic_6x19", c.x() - 30.0, c.y() + 30.0, 0.7, true)};
  const auto frame = cell.render("T", parts, cell.aligned_joints(), Lights::kTubes, 32);
  const auto result =
      locator->locate(frame.image, cell.mapper(cell.true_calibration(), frame.joints));
  ASSERT_TRUE(result);
  ASSERT_EQ(result->detections.size(), 2U);
  int unknown = 0;
  for (const Detection& d : result->detections) {
    if (d.class_name == "unknown") {
      ++unknown;
      EXPECT_TRUE(d.touching);
      EXPECT_EQ(d.quality, 0.0);
      EXPECT_EQ(d.shape, ShapeKind::kUnknown);
    } else {
      EXPECT_EQ(d.class_name, "ic_6x19");  // the free part is unaffected
    }
  }
  EXPECT_EQ(unknown, 1);
  EXPECT_EQ(result->report.unresolved, 1);
}

}  // namespace
}  // namespace cell::vision
