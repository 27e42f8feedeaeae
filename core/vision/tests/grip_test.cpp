// The fingerprint clear-grip test (digest 002 §3), from its equations to a rendered neighbour.
#include "cell/vision/grip.hpp"

#include <fmt/format.h>
#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include <cmath>
#include <numbers>

#include "cell/geometry/angles.hpp"
#include "cell/vision/locate.hpp"
#include "scenes.hpp"

namespace cell::vision {
namespace {

using testing::Cell;
using testing::dip14_grasp_model;
using ::testing::HasSubstr;
using testing::Lights;

using geometry::kDeg;
constexpr double kPrintedMm = 1e-3;  // the digest prints three decimals

// T4: C = (200, 150), angle.aim = 30, alpha = 0, d.cg = 0, rz.off = 90, wd_LA = 40, wd_g = 10
// -> beta 30, G = C, grasp.angle 120, dg 25, cw1 (212.500, 128.349), cw2 (187.500, 171.651).
TEST(Fingerprints, OnAxisGraspMatchesTheDigestsT4) {
  const GraspStyle style{"t4", 0.0, 0.0, 90.0 * kDeg, 40.0};
  const auto f = place_fingerprints({200.0, 150.0}, 30.0 * kDeg, style, 10.0, 20.0);
  EXPECT_NEAR(f.beta_rad, 30.0 * kDeg, 1e-12);
  EXPECT_NEAR((f.grasp - Eigen::Vector2d(200.0, 150.0)).norm(), 0.0, 1e-12);
  EXPECT_NEAR(f.grasp_angle_rad, 120.0 * kDeg, 1e-12);
  EXPECT_NEAR(f.dg_mm, 25.0, 1e-12);
  EXPECT_NEAR(f.cw1.x(), 212.500, kPrintedMm);
  EXPECT_NEAR(f.cw1.y(), 128.349, kPrintedMm);
  EXPECT_NEAR(f.cw2.x(), 187.500, kPrintedMm);
  EXPECT_NEAR(f.cw2.y(), 171.651, kPrintedMm);
  // The windows are wd_g x ht_g rectangles about cw1, cw2, turned by grasp.angle.
  EXPECT_NEAR((f.window1[1] - f.window1[0]).norm(), 10.0, 1e-9);
  EXPECT_NEAR((f.window1[3] - f.window1[0]).norm(), 20.0, 1e-9);
  const Eigen::Vector2d centre1 =
      0.25 * (f.window1[0] + f.window1[1] + f.window1[2] + f.window1[3]);
  EXPECT_NEAR((centre1 - f.cw1).norm(), 0.0, 1e-9);
}

// T5: as T4 with alpha = 90, d.cg = 10 -> beta 120, G (205.000, 141.340), grasp.angle 210,
// cw1 (226.651, 153.840), cw2 (183.349, 128.840).
TEST(Fingerprints, OffCentreGraspMatchesTheDigestsT5) {
  const GraspStyle style{"t5", 10.0, 90.0 * kDeg, 90.0 * kDeg, 40.0};
  const auto f = place_fingerprints({200.0, 150.0}, 30.0 * kDeg, style, 10.0, 20.0);
  EXPECT_NEAR(f.beta_rad, 120.0 * kDeg, 1e-12);
  EXPECT_NEAR(f.grasp.x(), 205.000, kPrintedMm);
  EXPECT_NEAR(f.grasp.y(), 141.340, kPrintedMm);
  EXPECT_NEAR(f.grasp_angle_rad, 210.0 * kDeg, 1e-12);
  EXPECT_NEAR(f.cw1.x(), 226.651, kPrintedMm);
  EXPECT_NEAR(f.cw1.y(), 153.840, kPrintedMm);
  EXPECT_NEAR(f.cw2.x(), 183.349, kPrintedMm);
  EXPECT_NEAR(f.cw2.y(), 128.840, kPrintedMm);
}

// T6: wd_g 10, ht_g 20 mm at 1 mm/px -> 200 px; at 0.5 mm/px 800 px. err 5: (198, 200)
// authorised, (198, 150) refused.
TEST(Fingerprints, AreaAndDecisionMatchTheDigestsT6) {
  EXPECT_NEAR(fingerprint_area_px(10.0, 20.0, 1.0, 1.0), 200.0, 1e-12);
  EXPECT_NEAR(fingerprint_area_px(10.0, 20.0, 0.5, 0.5), 800.0, 1e-12);
  EXPECT_NEAR(fingerprint_area_px(10.0, 20.0, 0.5, 0.25), 1600.0, 1e-12);  // mm/px per axis
  EXPECT_TRUE(fingerprints_clear(198.0, 200.0, 200.0, 5.0));
  EXPECT_FALSE(fingerprints_clear(198.0, 150.0, 200.0, 5.0));
  EXPECT_FALSE(fingerprints_clear(150.0, 198.0, 200.0, 5.0));
}

// T6, k = 2: style 1 blocked, style 2 clear -> Gs_m_2; all blocked -> no grasp.
TEST(Fingerprints, TheFirstClearStyleWinsAndTheOthersSayWhy) {
  GraspModel model;
  model.class_name = "la";
  model.finger_width_mm = 10.0;
  model.finger_height_mm = 20.0;
  model.area_tolerance_px = 5.0;
  model.styles = {GraspStyle{"first", 0, 0, 90 * kDeg, 40}, GraspStyle{"second", 0, 0, 0, 80}};
  const auto identity = [](const Eigen::Vector2d& p) { return std::optional<Eigen::Vector2d>(p); };
  // Windows whose centre lies left of x = 200 are "taken" (another part there).
  auto counter = [](const std::array<Eigen::Vector2d, 4>& w) {
    const Eigen::Vector2d c = 0.25 * (w[0] + w[1] + w[2] + w[3]);
    return WindowCount{c.x() < 200.0 ? 150.0 : 200.0, 200.0, true};
  };
  // angle.aim 0: style "first" puts its windows at y +- 25 (x 200: free); style "second" at
  // x = 200 -+ 45: the left one is taken.
  auto r = test_clear_grip(model, {200.0, 150.0}, 0.0, identity, counter);
  EXPECT_EQ(r.verdict, GripVerdict::kClear);
  EXPECT_EQ(r.style, 0);
  EXPECT_EQ(r.style_name, "first");
  EXPECT_EQ(r.detail, "");
  // Turned by 90 degrees, the first style's windows go to x = 200 -+ 25: the left one taken.
  r = test_clear_grip(model, {200.0, 150.0}, 90.0 * kDeg, identity, counter);
  EXPECT_EQ(r.verdict, GripVerdict::kClear);
  EXPECT_EQ(r.style, 1);
  EXPECT_THAT(r.detail, HasSubstr("style 0 'first': fingerprint"));
  EXPECT_THAT(r.detail, HasSubstr("50 of 200 px taken by another part (tolerance 5)"));
  // Everything taken: blocked, every style named.
  auto all_taken = [](const std::array<Eigen::Vector2d, 4>&) {
    return WindowCount{100.0, 200.0, true};
  };
  r = test_clear_grip(model, {200.0, 150.0}, 0.0, identity, all_taken);
  EXPECT_EQ(r.verdict, GripVerdict::kBlocked);
  EXPECT_EQ(r.style, -1);
  EXPECT_THAT(r.detail, HasSubstr("style 0 'first'"));
  EXPECT_THAT(r.detail, HasSubstr("style 1 'second'"));
}

// Every clear style is listed, in style order, with G and the tool's yaw (fingers close along
// the tool's y axis: yaw = grasp.angle - 90 deg). By hand, C = (200, 150), angle.aim = 30 deg:
// "across" (rz.off 90) G = C, yaw 30; "ends" (rz.off 0) G = C, yaw 30 - 90 = -60;
// "offset" (d.cg 5, alpha 0, rz.off 90) G = C - 5 (cos 30, sin 30) = (195.670, 147.500), yaw 30.
TEST(Fingerprints, EveryClearStyleIsListedWithWhereTheToolGoes) {
  GraspModel model;
  model.class_name = "la";
  model.finger_width_mm = 3.0;
  model.finger_height_mm = 8.0;
  model.area_tolerance_px = 5.0;
  model.styles = {GraspStyle{"across", 0.0, 0.0, 90.0 * kDeg, 9.0},
                  GraspStyle{"ends", 0.0, 0.0, 0.0, 21.0},
                  GraspStyle{"offset", 5.0, 0.0, 90.0 * kDeg, 9.0}};
  const auto identity = [](const Eigen::Vector2d& p) { return std::optional<Eigen::Vector2d>(p); };
  const auto all_free = [](const std::array<Eigen::Vector2d, 4>&) {
    return WindowCount{24.0, 24.0, true};
  };
  auto r = test_clear_grip(model, {200.0, 150.0}, 30.0 * kDeg, identity, all_free);
  EXPECT_EQ(r.verdict, GripVerdict::kClear);
  EXPECT_EQ(r.style, 0);
  EXPECT_EQ(r.style_name, "across");
  EXPECT_EQ(r.detail, "");
  ASSERT_EQ(r.clear.size(), 3U);
  EXPECT_EQ(r.clear[0].style, 0);
  EXPECT_EQ(r.clear[0].name, "across");
  EXPECT_NEAR(r.clear[0].grasp.x(), 200.0, 1e-12);
  EXPECT_NEAR(r.clear[0].grasp.y(), 150.0, 1e-12);
  EXPECT_NEAR(r.clear[0].tool_yaw_rad, 30.0 * kDeg, 1e-12);  // the part's major axis
  EXPECT_EQ(r.clear[1].style, 1);
  EXPECT_EQ(r.clear[1].name, "ends");
  EXPECT_NEAR(r.clear[1].grasp.x(), 200.0, 1e-12);
  EXPECT_NEAR(r.clear[1].grasp.y(), 150.0, 1e-12);
  EXPECT_NEAR(r.clear[1].tool_yaw_rad, -60.0 * kDeg, 1e-12);  // the part's angle - 90 deg
  EXPECT_EQ(r.clear[2].style, 2);
  EXPECT_EQ(r.clear[2].name, "offset");
  EXPECT_NEAR(r.clear[2].grasp.x(), 195.670, kPrintedMm);  // 5 mm from C along -MIA
  EXPECT_NEAR(r.clear[2].grasp.y(), 147.500, kPrintedMm);
  EXPECT_NEAR((r.clear[2].grasp - Eigen::Vector2d(200.0, 150.0)).norm(), 5.0, 1e-12);
  EXPECT_NEAR(r.clear[2].tool_yaw_rad, 30.0 * kDeg, 1e-12);

  // angle.aim 0: "across" windows at (200, 144) and (200, 156); "ends" at (188, 150) and
  // (212, 150); "offset" (G = (195, 150)) at (195, 144) and (195, 156).
  auto taken_if = [](auto taken) {
    return [taken](const std::array<Eigen::Vector2d, 4>& w) {
      const Eigen::Vector2d c = 0.25 * (w[0] + w[1] + w[2] + w[3]);
      return WindowCount{taken(c) ? 12.0 : 24.0, 24.0, true};
    };
  };
  // A part near x = 195: only "offset" blocked. The first clear is still "across" with no
  // detail (a later style's failure is not explained), and "offset" is not listed.
  r = test_clear_grip(model, {200.0, 150.0}, 0.0, identity,
                      taken_if([](const Eigen::Vector2d& c) { return std::abs(c.x() - 195.0) < 2; }));
  EXPECT_EQ(r.verdict, GripVerdict::kClear);
  EXPECT_EQ(r.style, 0);
  EXPECT_EQ(r.style_name, "across");
  EXPECT_EQ(r.detail, "");
  ASSERT_EQ(r.clear.size(), 2U);
  EXPECT_EQ(r.clear[0].name, "across");
  EXPECT_EQ(r.clear[1].name, "ends");
  EXPECT_NEAR(r.clear[1].tool_yaw_rad, -90.0 * kDeg, 1e-12);
  // A part at y > 155: "across" and "offset" blocked, only "ends" listed; the detail explains
  // "across" only (the styles before the first clear one), as before.
  r = test_clear_grip(model, {200.0, 150.0}, 0.0, identity,
                      taken_if([](const Eigen::Vector2d& c) { return c.y() > 155.0; }));
  EXPECT_EQ(r.verdict, GripVerdict::kClear);
  EXPECT_EQ(r.style, 1);
  EXPECT_EQ(r.style_name, "ends");
  EXPECT_EQ(r.detail,
            "style 0 'across': fingerprint 2 has 12 of 24 px taken by another part (tolerance 5)");
  ASSERT_EQ(r.clear.size(), 1U);
  EXPECT_EQ(r.clear[0].style, 1);
  EXPECT_EQ(r.clear[0].name, "ends");
  EXPECT_NEAR((r.clear[0].grasp - Eigen::Vector2d(200.0, 150.0)).norm(), 0.0, 1e-12);
  EXPECT_NEAR(r.clear[0].tool_yaw_rad, -90.0 * kDeg, 1e-12);
  // Everything taken: blocked, nothing listed, every style explained.
  r = test_clear_grip(model, {200.0, 150.0}, 0.0, identity,
                      taken_if([](const Eigen::Vector2d&) { return true; }));
  EXPECT_EQ(r.verdict, GripVerdict::kBlocked);
  EXPECT_EQ(r.style, -1);
  EXPECT_TRUE(r.clear.empty());
  EXPECT_THAT(r.detail, HasSubstr("style 2 'offset'"));
}

TEST(Fingerprints, AFingerOutsideTheImageFollowsTheViewingPolicy) {
  GraspModel model;
  model.class_name = "la";
  model.finger_width_mm = 10.0;
  model.finger_height_mm = 20.0;
  model.styles = {GraspStyle{"only", 0, 0, 0, 40}};
  const auto identity = [](const Eigen::Vector2d& p) { return std::optional<Eigen::Vector2d>(p); };
  auto half_out = [](const std::array<Eigen::Vector2d, 4>&) {
    return WindowCount{100.0, 100.0, false};  // the visible part is free
  };
  model.outside = OutsideView::kBlocked;
  auto r = test_clear_grip(model, {0, 0}, 0.0, identity, half_out);
  EXPECT_EQ(r.verdict, GripVerdict::kBlocked);
  EXPECT_THAT(r.detail, HasSubstr("not wholly in the image"));
  model.outside = OutsideView::kClear;
  r = test_clear_grip(model, {0, 0}, 0.0, identity, half_out);
  EXPECT_EQ(r.verdict, GripVerdict::kClear);
}

TEST(Fingerprints, ModelsAreValidated) {
  GraspModel model;
  model.class_name = "dip14";
  model.finger_width_mm = 3.0;
  model.finger_height_mm = 0.0;
  model.styles = {GraspStyle{"a", 0, 0, 0, 9}};
  EXPECT_FALSE(model.validate());
  model.finger_height_mm = 8.0;
  EXPECT_TRUE(model.validate());
  model.styles.clear();
  const auto s = model.validate();
  ASSERT_FALSE(s);
  EXPECT_THAT(s.error().message, HasSubstr("at least one grasp style"));
}

/// The first detection of class `name` (nullptr when none).
const Detection* first_of_class(const LocateResult& result, const std::string& name) {
  for (const Detection& d : result.detections) {
    if (d.class_name == name) {
      return &d;
    }
  }
  return nullptr;
}

// Rendered: a dip14 with a dip8 beside its long side, inside the "across" style's second
// fingerprint: "across" is refused with the reason, "ends" is authorised. Then a third part at
// one end blocks "ends" too.
TEST(ClearGrip, ANeighbourInsideOneFingerprintMovesTheGraspToTheNextStyle) {
  const Cell& cell = Cell::get();
  LocateOptions options;
  options.grasps = {dip14_grasp_model()};
  auto locator = Locator::create(options);
  ASSERT_TRUE(locator) << locator.error().message;
  const Eigen::Vector2d c = cell.window(30.0).center();
  const double yaw = 25.0 * kDeg;
  const Eigen::Vector2d x_axis(std::cos(yaw), std::sin(yaw));
  const Eigen::Vector2d y_axis(-std::sin(yaw), std::cos(yaw));
  auto at = [&](double along, double across) { return c + along * x_axis + across * y_axis; };
  // The "across" windows are 6 mm either side of the axis, 3 x 8 mm; the dip8 (leads to 3.94 mm
  // from its axis) at 9.5 mm reaches into the +y one from 5.56 mm on, 2 mm clear of the dip14.
  const Eigen::Vector2d n1 = at(0.0, 9.5);
  const Eigen::Vector2d n2 = at(-16.0, 0.0);  // for the second frame: in the -x end window
  struct Case {
    std::vector<render::Part> parts;
    GripVerdict verdict;
    int style;
  };
  std::vector<Case> cases;
  cases.push_back({{cell.part("ic", "dip14", c.x(), c.y(), yaw, true)}, GripVerdict::kClear, 0});
  cases.push_back({{cell.part("ic", "dip14", c.x(), c.y(), yaw, true),
                    cell.part("n1", "dip8", n1.x(), n1.y(), yaw, true)},
                   GripVerdict::kClear,
                   1});
  cases.push_back({{cell.part("ic", "dip14", c.x(), c.y(), yaw, true),
                    cell.part("n1", "dip8", n1.x(), n1.y(), yaw, true),
                    cell.part("n2", "dip8", n2.x(), n2.y(), yaw + 90.0 * kDeg, true)},
                   GripVerdict::kBlocked,
                   -1});
  for (std::size_t k = 0; k < cases.size(); ++k) {
    const auto frame = cell.render(fmt::format("grip {}", k), cases[k].parts, cell.aligned_joints(),
                                   Lights::kTubes, 20 + k);
    const auto result =
        locator->locate(frame.image, cell.mapper(cell.true_calibration(), frame.joints));
    ASSERT_TRUE(result);
    const Detection* ic = first_of_class(*result, "dip14");
    ASSERT_NE(ic, nullptr) << frame.name;
    EXPECT_EQ(ic->grip.verdict, cases[k].verdict) << frame.name << ": " << ic->grip.detail;
    EXPECT_EQ(ic->grip.style, cases[k].style) << frame.name << ": " << ic->grip.detail;
    if (k >= 1) {
      EXPECT_THAT(ic->grip.detail, HasSubstr("style 0 'across': fingerprint"));
      EXPECT_THAT(ic->grip.detail, HasSubstr("taken by another part"));
    }
    if (k == 2) {
      EXPECT_THAT(ic->grip.detail, HasSubstr("style 1 'ends': fingerprint"));
    }
    // The neighbours have no grasp model: not tested.
    for (const Detection& d : result->detections) {
      if (d.class_name == "dip8") {
        EXPECT_EQ(d.grip.verdict, GripVerdict::kNotTested);
      }
    }
  }
}

// Rendered and located: a lone dip14 lists both styles, in the plane frame and in the robot's
// base frame; with a dip8 in the "across" fingerprint it lists only "ends". The base grasps go
// through the same mapping as base_pose: "across" (d.cg 0, tool x along the part) has its x, y
// and its yaw modulo 180 deg; "ends" is turned by -90 deg from it.
TEST(ClearGrip, EveryClearStyleIsListedInTheBaseFrame) {
  const Cell& cell = Cell::get();
  LocateOptions options;
  options.grasps = {dip14_grasp_model()};
  auto locator = Locator::create(options);
  ASSERT_TRUE(locator) << locator.error().message;
  const auto scenes = cell.clear_grasp_scenes();
  for (std::size_t k = 0; k < scenes.size(); ++k) {
    const std::vector<std::string>& expected = scenes[k].clear;
    const auto frame = cell.render(fmt::format("clear grasps {}", k), scenes[k].parts,
                                   cell.aligned_joints(), Lights::kTubes, 40 + k);
    const auto result =
        locator->locate(frame.image, cell.mapper(cell.true_calibration(), frame.joints));
    ASSERT_TRUE(result);
    const Detection* ic = first_of_class(*result, "dip14");
    ASSERT_NE(ic, nullptr) << frame.name;
    ASSERT_TRUE(ic->has_base_pose) << frame.name;
    EXPECT_EQ(ic->grip.verdict, GripVerdict::kClear) << frame.name << ": " << ic->grip.detail;
    EXPECT_EQ(ic->grip.style, k == 0 ? 0 : 1) << frame.name;
    EXPECT_EQ(ic->grip.style_name, expected[0]) << frame.name;
    ASSERT_EQ(ic->grip.clear.size(), expected.size()) << frame.name << ": " << ic->grip.detail;
    ASSERT_EQ(ic->base_grasps.size(), expected.size()) << frame.name;
    for (std::size_t i = 0; i < expected.size(); ++i) {
      const ClearGrasp& g = ic->grip.clear[i];
      const BaseGrasp& b = ic->base_grasps[i];
      EXPECT_EQ(g.name, expected[i]) << frame.name;
      EXPECT_EQ(b.name, g.name) << frame.name;
      EXPECT_EQ(b.style, g.style) << frame.name;
      EXPECT_EQ(g.style, g.name == "across" ? 0 : 1) << frame.name;
      // d.cg 0: G is the centroid; the tool along the part ("across") or across it ("ends").
      EXPECT_NEAR((g.grasp - ic->center_plane).norm(), 0.0, 1e-9) << frame.name;
      const double turn = g.name == "across" ? 0.0 : -90.0 * kDeg;
      EXPECT_NEAR(g.tool_yaw_rad, ic->angle_plane_rad + turn, 1e-12) << frame.name;
      EXPECT_NEAR(b.tool.x_mm, ic->base_pose.x_mm, 1e-9) << frame.name;
      EXPECT_NEAR(b.tool.y_mm, ic->base_pose.y_mm, 1e-9) << frame.name;
      EXPECT_NEAR(angle_error(b.tool.rz_rad, ic->base_pose.rz_rad + turn, 2), 0.0, 1e-9)
          << frame.name << ": " << b.name;
    }
    // The neighbour has no grasp model: nothing listed.
    for (const Detection& d : result->detections) {
      if (d.class_name == "dip8") {
        EXPECT_TRUE(d.grip.clear.empty());
        EXPECT_TRUE(d.base_grasps.empty());
      }
    }
  }
}

}  // namespace
}  // namespace cell::vision
