// Reading vision's options from YAML: strict, every error with file:line:col.
#include "cell/vision/options.hpp"

#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include <numbers>

#include "cell/testing/matchers.hpp"

namespace cell::vision {
namespace {

using ::cell::testing::IsErrWith;
using ::testing::HasSubstr;

Result<LocateOptions> parse(const std::string& yaml) {
  auto doc = config::load_string(yaml, "vision.yaml");
  if (!doc) {
    return doc.error();
  }
  LocateOptions out;
  config::MapReader root(*doc, doc->root, "");
  config::MapReader locate = root.child("locate");
  read_locate_options(locate, out);
  CELL_TRY(locate.finish());
  return out;
}

TEST(VisionOptions, ReadsEverySection) {
  const auto o = parse(R"(locate:
  pipeline: thesis
  segmentation: {mode: fixed, fixed_threshold: 140, block_px: 16}
  thesis: {epsilon_px: 18, lookback_px: 200, centre_px: [256, 240], part_height_mm: 8.5}
  class_tolerance_mm: 0.5
  classes:
    - {name: washer, shape: circle, length_mm: 12, top_mm: 1.5}
  grasps:
    - class: dip14
      finger_width_mm: 3
      finger_height_mm: 8
      outside_view: clear
      styles:
        - {name: across, rz_off_deg: 90, part_width_mm: 9}
        - {name: ends, part_width_mm: 21}
)");
  ASSERT_TRUE(o) << o.error().message;
  EXPECT_EQ(o->pipeline, Pipeline::kThesis);
  EXPECT_EQ(o->segmentation.mode, ThresholdMode::kFixed);
  EXPECT_EQ(o->segmentation.fixed_threshold, 140);
  EXPECT_EQ(o->segmentation.block_px, 16);
  EXPECT_EQ(o->thesis.epsilon_px, 18.0);
  EXPECT_EQ(o->thesis.centre_px, Eigen::Vector2i(256, 240));
  EXPECT_EQ(o->thesis.part_height_mm, 8.5);
  EXPECT_EQ(o->class_tolerance_mm, 0.5);
  ASSERT_NE(o->classes.find("washer"), nullptr);
  EXPECT_EQ(o->classes.find("washer")->width_mm, 12.0);
  ASSERT_NE(o->classes.find("dip14"), nullptr);  // the built-in ones stay
  ASSERT_EQ(o->grasps.size(), 1U);
  EXPECT_EQ(o->grasps[0].outside, OutsideView::kClear);
  ASSERT_EQ(o->grasps[0].styles.size(), 2U);
  EXPECT_NEAR(o->grasps[0].styles[0].rz_off_rad, std::numbers::pi / 2, 1e-12);
  EXPECT_EQ(o->grasps[0].styles[1].name, "ends");
}

TEST(VisionOptions, ReportsEveryErrorWithItsLocation) {
  const auto o = parse(R"(locate:
  pipeline: quick
  segmentation: {mode: otsu, block_px: 4}
  edge_windw_px: 3
  grasps:
    - class: dip99
      finger_width_mm: 3
      finger_height_mm: 8
      styles: [{part_width_mm: 9}]
)");
  ASSERT_FALSE(o);
  EXPECT_EQ(o.error().code, Errc::kConfig);
  const std::string& m = o.error().message;
  EXPECT_THAT(m, HasSubstr("vision.yaml:2:13: key 'locate.pipeline': unknown pipeline 'quick'"));
  EXPECT_THAT(m,
              HasSubstr("key 'locate.segmentation.mode': must be fixed or adaptive, got 'otsu'"));
  EXPECT_THAT(m, HasSubstr("segmentation.block_px must be a power of two in 8..512, got 4"));
  EXPECT_THAT(m, HasSubstr("vision.yaml:4:3: unknown key 'locate.edge_windw_px'"));
  EXPECT_THAT(m, HasSubstr("unknown class 'dip99'"));
}

TEST(VisionOptions, LoadsTheShippedConfig) {
  const char* home = std::getenv("CELL_SOURCE_DIR");
  ASSERT_NE(home, nullptr);
  const auto o = load_locate_options(std::string(home) + "/config/vision.yaml");
  ASSERT_TRUE(o) << o.error().message;
  EXPECT_FALSE(o->grasps.empty());
  EXPECT_THAT(load_locate_options("/nonexistent/vision.yaml"),
              IsErrWith(Errc::kConfig, "cannot open"));
}

}  // namespace
}  // namespace cell::vision
