// Accuracy of both pipelines on the world simulator's rendered scenes against their ground truth
// (issue 6, "Must hold"): core/world scatters the catalogue's real DIPs at random orientations,
// core/render draws them through the 7545 camera's TRUE model (lens, lighting gradient, leads,
// noise), vision locates them with a perfect calibration (the true camera) unless said otherwise.
// The tables printed here are the ones quoted in core/vision/README.md.
#include <fmt/format.h>
#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include <cstdio>
#include <numbers>

#include "cell/geometry/angles.hpp"
#include "cell/vision/locate.hpp"
#include "scenes.hpp"

namespace cell::vision {
namespace {

using testing::Cell;
using testing::Lights;
using testing::RenderedScene;
using testing::ScatterRequest;
using testing::Score;

using geometry::kDeg;
constexpr double kCentreRmsPx = 0.1;      // without leads
constexpr double kCentreRmsPinsPx = 0.3;  // with leads
constexpr double kAngleRmsDeg = 0.2;
constexpr int kSeeds = 3;

ScatterRequest request(int count, bool pins, Lights lights, std::uint64_t seed) {
  ScatterRequest r;
  r.count = count;
  r.pins = pins;
  r.lights = lights;
  r.seed = seed;
  if (count > 15) {
    // 40 ICs only fit the 144 x 138 mm window as the smaller packages, 3 mm apart.
    r.classes = {"dip8", "dip14", "ic_6x19", "dip16"};
    r.min_separation_mm = 3.0;
  }
  return r;
}

void print_row(const std::string& label, const Score& s) {
  std::printf("| %-34s | %4d | %4d | %3d | %3d | %6.3f | %6.3f | %6.3f | %6.3f | %6.3f |\n",
              label.c_str(), s.parts, s.found, s.false_parts, s.wrong_class, s.centre_rms_px(),
              s.max_centre_px, s.angle_rms_deg(), s.max_angle_rad / kDeg, s.world_rms_mm());
}

void print_header(const char* title) {
  std::printf("\n%s\n| %-34s | %4s | %4s | %3s | %3s | %6s | %6s | %6s | %6s | %6s |\n", title,
              "scene", "parts", "found", "false", "class", "c rms", "c max", "a rms", "a max",
              "w rms");
  std::printf("|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|\n");
}

Score run(Locator& locator,
          const RenderedScene& frame,
          const calibration::CameraCalibration* c,
          bool compare_class) {
  const Cell& cell = Cell::get();
  const PixelMapper mapper = c != nullptr ? cell.mapper(*c, frame.joints) : PixelMapper();
  auto result = locator.locate(frame.image, mapper);
  EXPECT_TRUE(result) << result.error().message;
  if (!result) {
    return {};
  }
  const Eigen::Isometry3d b = cell.world_T_base();
  return testing::score(result->detections, frame, compare_class, &b);
}

// The issue's table: 1, 5, 15 and 40 ICs at random orientations, with and without leads, under
// both lighting set-ups, three seeded scenes each: every part found, none invented, the right
// class, centre RMS <= 0.1 px (0.3 px with leads), angle RMS <= 0.2 deg.
TEST(FastPipelineAccuracy, EveryIcFoundWithinTheIssuesBoundsOnScatteredScenes) {
  const Cell& cell = Cell::get();
  auto locator = Locator::create(LocateOptions{});
  ASSERT_TRUE(locator) << locator.error().message;
  print_header("fast pipeline, true calibration (px, deg; world mm)");
  for (int count : {1, 5, 15, 40}) {
    for (bool pins : {false, true}) {
      for (Lights lights : {Lights::kTubes, Lights::kTubesAndLamp}) {
        Score total;
        for (std::uint64_t seed = 1; seed <= kSeeds; ++seed) {
          const RenderedScene frame = cell.scatter(request(count, pins, lights, seed));
          ASSERT_EQ(static_cast<int>(frame.truth.size()), count) << frame.name;
          total.add(run(*locator, frame, &cell.true_calibration(), true));
        }
        const std::string label = fmt::format("{} ICs, {}, {}", count, pins ? "leads" : "no leads",
                                              testing::to_string(lights));
        print_row(label, total);
        EXPECT_EQ(total.found, total.parts) << label << ::testing::PrintToString(total.notes);
        EXPECT_EQ(total.false_parts, 0) << label << ::testing::PrintToString(total.notes);
        EXPECT_EQ(total.wrong_class, 0) << label << ::testing::PrintToString(total.notes);
        EXPECT_LE(total.centre_rms_px(), pins ? kCentreRmsPinsPx : kCentreRmsPx) << label;
        EXPECT_LE(total.angle_rms_deg(), kAngleRmsDeg) << label;
        EXPECT_LE(total.world_rms_mm(), 0.05) << label;  // a perfect calibration: ~0.015 mm
      }
    }
  }
}

// The thesis's own scene (config/scenes/table_ics.yaml at the grab pose): 15 ICs in a grid.
TEST(FastPipelineAccuracy, TheThesisTableOfFifteenIcs) {
  const Cell& cell = Cell::get();
  auto locator = Locator::create(LocateOptions{});
  ASSERT_TRUE(locator);
  print_header("fast pipeline, config/scenes/table_ics.yaml at the grab pose");
  for (bool pins : {false, true}) {
    for (Lights lights : {Lights::kTubes, Lights::kTubesAndLamp}) {
      const RenderedScene frame = cell.table_ics(pins, lights);
      ASSERT_EQ(frame.truth.size(), 15U);
      const Score s = run(*locator, frame, &cell.true_calibration(), true);
      print_row(frame.name, s);
      EXPECT_EQ(s.found, 15) << ::testing::PrintToString(s.notes);
      EXPECT_EQ(s.false_parts, 0);
      EXPECT_EQ(s.wrong_class, 0) << ::testing::PrintToString(s.notes);
      EXPECT_LE(s.centre_rms_px(), pins ? kCentreRmsPinsPx : kCentreRmsPx);
      EXPECT_LE(s.angle_rms_deg(), kAngleRmsDeg);
    }
  }
}

// Flat shapes of the catalogue (Chapter 2's classes): rectangle, square, disc, triangle, and
// an IC, at several orientations.
TEST(FastPipelineAccuracy, RectanglesSquaresDiscsAndTriangles) {
  const Cell& cell = Cell::get();
  auto locator = Locator::create(LocateOptions{});
  ASSERT_TRUE(locator);
  const auto box = cell.window(24.0);
  const double x0 = box.min().x();
  const double x1 = box.max().x();
  const double y0 = box.min().y();
  const double y1 = box.max().y();
  Score total;
  for (int k = 0; k < 6; ++k) {
    std::vector<render::Part> parts;
    parts.push_back(cell.part("r", "rectangle", x0 + 5, y0 + 5, 0.3 + k, false));
    parts.push_back(cell.part("s", "square", x1 - 5, y0 + 5, 0.2 + 0.9 * k, false));
    parts.push_back(cell.part("d", "disc", x0 + 5, y1 - 5, 0.0, false));
    parts.push_back(cell.part("t", "triangle", x1 - 5, y1 - 5, 0.7 * k, false));
    parts.push_back(cell.part("i", "ic_7x30", 0.5 * (x0 + x1), 0.5 * (y0 + y1), 0.4 * k, true));
    const RenderedScene frame =
        cell.render(fmt::format("shapes {}", k), parts, cell.aligned_joints(),
                    k % 2 == 0 ? Lights::kTubes : Lights::kTubesAndLamp, 40 + k);
    ASSERT_EQ(frame.truth.size(), 5U);
    total.add(run(*locator, frame, &cell.true_calibration(), true));
  }
  print_header("fast pipeline, flat shapes (6 frames)");
  print_row("rectangle, square, disc, triangle, IC", total);
  EXPECT_EQ(total.found, total.parts) << ::testing::PrintToString(total.notes);
  EXPECT_EQ(total.false_parts, 0);
  EXPECT_EQ(total.wrong_class, 0) << ::testing::PrintToString(total.notes);
  EXPECT_LE(total.centre_rms_px(), kCentreRmsPx);
  EXPECT_LE(total.angle_rms_deg(), kAngleRmsDeg);
}

// The fixed threshold of the thesis (grey < 150) instead of the adaptive one: the same results
// here, since the sub-pixel outline does not depend on where the threshold cut.
TEST(FastPipelineAccuracy, TheThesissFixedThresholdGivesTheSameAccuracy) {
  const Cell& cell = Cell::get();
  LocateOptions options;
  options.segmentation.mode = ThresholdMode::kFixed;
  auto locator = Locator::create(options);
  ASSERT_TRUE(locator);
  Score total;
  for (Lights lights : {Lights::kTubes, Lights::kTubesAndLamp}) {
    total.add(
        run(*locator, cell.scatter(request(15, true, lights, 7)), &cell.true_calibration(), true));
  }
  EXPECT_EQ(total.found, total.parts) << ::testing::PrintToString(total.notes);
  EXPECT_EQ(total.false_parts, 0);
  EXPECT_LE(total.centre_rms_px(), kCentreRmsPinsPx);
  EXPECT_LE(total.angle_rms_deg(), kAngleRmsDeg);
}

// Before any calibration was published the service maps with the camera file's NOMINAL
// parameters: every part is still found and located in the image, but sizes are a little off
// (dip16 and dip14 differ by 0.25 mm) and robot poses are off by the mount's real offset
// (about 10 mm here): what calibration is for.
TEST(FastPipelineAccuracy, WithTheNominalCalibrationPartsAreFoundButPosesAreOff) {
  const Cell& cell = Cell::get();
  auto locator = Locator::create(LocateOptions{});
  ASSERT_TRUE(locator);
  Score total;
  for (std::uint64_t seed = 1; seed <= kSeeds; ++seed) {
    total.add(run(*locator, cell.scatter(request(15, true, Lights::kTubes, seed)),
                  &cell.nominal_calibration(), false));
  }
  print_header("fast pipeline, NOMINAL calibration (15 ICs with leads, tubes, 3 scenes)");
  print_row("nominal calibration", total);
  EXPECT_EQ(total.found, total.parts);
  EXPECT_EQ(total.false_parts, 0);
  EXPECT_LE(total.centre_rms_px(), kCentreRmsPinsPx);  // no lens model: ~0.12 px
  EXPECT_GT(total.world_rms_mm(), 3.0);                // the mount really is elsewhere
  EXPECT_LT(total.world_rms_mm(), 20.0);
}

// Without any calibration vision works in pixels: no lens, no parallax, no classes, no robot
// pose; still every part, to a fraction of a pixel.
TEST(FastPipelineAccuracy, WithoutCalibrationItLocatesInPixels) {
  const Cell& cell = Cell::get();
  auto locator = Locator::create(LocateOptions{});
  ASSERT_TRUE(locator);
  Score total;
  for (std::uint64_t seed = 1; seed <= kSeeds; ++seed) {
    total.add(run(*locator, cell.scatter(request(15, true, Lights::kTubes, seed)), nullptr, false));
  }
  print_header("fast pipeline, no calibration (15 ICs with leads, tubes, 3 scenes)");
  print_row("pixels only", total);
  EXPECT_EQ(total.found, total.parts);
  EXPECT_EQ(total.false_parts, 0);
  EXPECT_LE(total.centre_rms_px(), 1.0);  // walls and lens uncorrected: ~0.6 px
  EXPECT_LE(total.angle_rms_deg(), kAngleRmsDeg);
  EXPECT_EQ(total.world_compared, 0);
}

TEST(FastPipelineAccuracy, AFrameWithNoPartsGivesAnEmptyList) {
  const Cell& cell = Cell::get();
  auto locator = Locator::create(LocateOptions{});
  ASSERT_TRUE(locator);
  for (Lights lights : {Lights::kTubes, Lights::kTubesAndLamp}) {
    const RenderedScene frame = cell.render("empty", {}, cell.aligned_joints(), lights, 9);
    for (Pipeline p : {Pipeline::kFast, Pipeline::kThesis}) {
      const auto result =
          locator->locate(frame.image, cell.mapper(cell.true_calibration(), frame.joints), p);
      ASSERT_TRUE(result);
      EXPECT_TRUE(result->detections.empty()) << to_string(p);
    }
  }
}

TEST(FastPipelineAccuracy, PartsCutByTheImageBorderAreLeftOutAndCounted) {
  const Cell& cell = Cell::get();
  auto locator = Locator::create(LocateOptions{});
  ASSERT_TRUE(locator);
  const auto box = cell.window(0.0);
  std::vector<render::Part> parts{
      cell.part("cut", "ic_7x30", box.min().x(), 0.5 * (box.min().y() + box.max().y()), 0.3, true),
      cell.part("whole", "dip14", 0.5 * (box.min().x() + box.max().x()),
                0.5 * (box.min().y() + box.max().y()), 1.0, true)};
  const RenderedScene frame =
      cell.render("border", parts, cell.aligned_joints(), Lights::kTubes, 4);
  const auto result =
      locator->locate(frame.image, cell.mapper(cell.true_calibration(), frame.joints));
  ASSERT_TRUE(result);
  ASSERT_EQ(result->detections.size(), 1U);
  EXPECT_EQ(result->detections[0].class_name, "dip14");
  EXPECT_EQ(result->report.at_border, 1);
}

// ---- the thesis's pipeline ----

/// The digest's case 16 (digest 000 §9.2): "a 7 x 30 mm rectangle at 3.5 px/mm, any angle ->
/// centre within 0.25 mm and angle within 1.5 deg". Rendered as the thesis assumed its scene:
/// a flat black part near the window's centre, a camera without lens distortion (the thesis
/// had no lens model), the parallax of its face taken as 0. Every 7.5 degrees at two places:
/// the angle always within 1.5 deg, the centre within 0.25 mm RMS. Its worst single centre is
/// 0.46 mm (at 7.5 deg): near the rows, the farthest skeleton point from the centre is
/// ambiguous along a short side (the distance changes by 0.2 px per px along it), so a corner
/// lands 3-4 px off, and the integer mean adds its -0.375 px.
TEST(ThesisPipelineAccuracy, MeetsItsClaimsOnTheDigestsCase16) {
  const Cell& cell = Cell::get();
  LocateOptions options;
  options.pipeline = Pipeline::kThesis;
  options.thesis.part_height_mm = 0.0;
  auto locator = Locator::create(options);
  ASSERT_TRUE(locator);
  const auto box = cell.window(25.0);
  const Eigen::Vector2d c = box.center();
  double worst_mm = 0.0;
  double worst_deg = 0.0;
  double sum2_mm = 0.0;
  int within = 0;
  int n = 0;
  for (double yaw_deg = 0.0; yaw_deg < 180.0; yaw_deg += 7.5) {
    for (const Eigen::Vector2d& at : {c, Eigen::Vector2d(c + Eigen::Vector2d(18, 9))}) {
      render::Part p = cell.part("r", "rectangle", at.x(), at.y(), yaw_deg * kDeg, false);
      p.length_mm = 30.0;
      p.width_mm = 7.0;
      p.height_mm = 0.0;  // a flat sticker: the thesis's "flat objects"
      const RenderedScene frame = cell.render(fmt::format("7x30 at {} deg", yaw_deg), {p},
                                              cell.aligned_joints(), Lights::kTubes, 11 + n, true);
      const PixelMapper mapper = cell.mapper(cell.ideal_calibration(), frame.joints);
      const auto result = locator->locate(frame.image, mapper);
      ASSERT_TRUE(result);
      ASSERT_EQ(result->detections.size(), 1U) << frame.name;
      const Detection& d = result->detections[0];
      ASSERT_TRUE(d.has_base_pose);
      const Eigen::Vector3d truth =
          cell.world_T_base().inverse() * frame.scene.parts[0].world_T_part.translation();
      const double e_mm = std::hypot(d.base_pose.x_mm - truth.x(), d.base_pose.y_mm - truth.y());
      const double e_deg = angle_error(d.angle_rad, frame.truth[0].angle_rad, 2) / kDeg;
      worst_mm = std::max(worst_mm, e_mm);
      worst_deg = std::max(worst_deg, e_deg);
      sum2_mm += e_mm * e_mm;
      within += e_mm <= 0.25 ? 1 : 0;
      EXPECT_LE(e_mm, 0.5) << frame.name;
      EXPECT_LE(e_deg, 1.5) << frame.name;
      ++n;
    }
  }
  const double rms_mm = std::sqrt(sum2_mm / n);
  std::printf(
      "\nthesis pipeline, digest 000 case 16 (%d frames): centre RMS %.3f mm, worst %.3f "
      "mm, %d within 0.25 mm; worst angle %.3f deg\n",
      n, rms_mm, worst_mm, within, worst_deg);
  EXPECT_LE(rms_mm, 0.25);
  EXPECT_GE(within, n * 9 / 10);
}

/// Case 16's second half: leads on one long side at 0 deg bias the external rectangle; the
/// centre stays within 0.5 mm.
TEST(ThesisPipelineAccuracy, LeadsOnOneSideAtZeroDegreesStayWithinHalfAMillimetre) {
  const Cell& cell = Cell::get();
  LocateOptions options;
  options.pipeline = Pipeline::kThesis;
  options.thesis.part_height_mm = 0.0;
  options.thesis.lookback_px = 200;  // the text's: a 107 px row needs more than the code's 66
  auto locator = Locator::create(options);
  ASSERT_TRUE(locator);
  const Eigen::Vector2d c = cell.window(25.0).center();
  // A flat 7 x 30 body with a row of 2.54 mm leads 1 mm long along one side (a comb of thin
  // flat rectangles).
  render::Part body = cell.part("r", "rectangle", c.x(), c.y(), 0.0, false);
  body.length_mm = 30.0;
  body.width_mm = 7.0;
  body.height_mm = 0.0;
  std::vector<render::Part> parts{body};
  for (int k = 0; k < 11; ++k) {
    render::Part lead = cell.part(fmt::format("l{}", k), "rectangle", c.x() - 12.7 + 2.54 * k,
                                  c.y() + 3.5 + 0.5, 0.0, false);
    lead.length_mm = 1.5;
    lead.width_mm = 1.0;
    lead.height_mm = 0.0;
    parts.push_back(lead);
  }
  const RenderedScene frame =
      cell.render("leads on one side", parts, cell.aligned_joints(), Lights::kTubes, 5, true);
  const auto result =
      locator->locate(frame.image, cell.mapper(cell.ideal_calibration(), frame.joints));
  ASSERT_TRUE(result);
  ASSERT_EQ(result->detections.size(), 1U);
  const Detection& d = result->detections[0];
  ASSERT_TRUE(d.has_base_pose);
  const Eigen::Vector3d truth = cell.world_T_base().inverse() * body.world_T_part.translation();
  EXPECT_LE(std::hypot(d.base_pose.x_mm - truth.x(), d.base_pose.y_mm - truth.y()), 0.5);
}

/// On the rendered scenes (real DIP heights, the lens, leads, 1 to 15 ICs 7 mm apart, more than
/// its 20 px grouping distance): the thesis's pipeline stays near its claims. Measured (see the
/// table): centre 0.25-0.31 mm RMS, 0.55 mm worst; angle 0.5-1.0 deg RMS, worst 1.5-3.5 deg.
/// Two things it does not model cost it the rest: its centre is an integer division (-0.375 px
/// per axis on average, 0.15 mm) and its parallax correction treats every corner as a top
/// corner, while the corners facing the camera's nadir are the walls' bottom corners.
TEST(ThesisPipelineAccuracy, OnRenderedScenesItStaysNearItsClaims) {
  const Cell& cell = Cell::get();
  LocateOptions options;
  options.pipeline = Pipeline::kThesis;
  options.thesis.lookback_px = 200;
  auto locator = Locator::create(options);
  ASSERT_TRUE(locator);
  print_header("thesis pipeline (text's 200 px look-back), true calibration, ICs 7 mm apart");
  for (int count : {1, 5, 15}) {
    for (bool pins : {false, true}) {
      for (Lights lights : {Lights::kTubes, Lights::kTubesAndLamp}) {
        Score total;
        for (std::uint64_t seed = 1; seed <= kSeeds; ++seed) {
          ScatterRequest r = request(count, pins, lights, seed);
          r.min_separation_mm = 7.0;
          total.add(run(*locator, cell.scatter(r), &cell.true_calibration(), false));
        }
        const std::string label = fmt::format("{} ICs, {}, {}", count, pins ? "leads" : "no leads",
                                              testing::to_string(lights));
        print_row(label, total);
        EXPECT_GE(total.found, total.parts * 9 / 10) << label;
        EXPECT_LE(total.world_rms_mm(), 0.35) << label;
        EXPECT_LE(total.angle_rms_deg(), 1.5) << label;
      }
    }
  }
}

/// The printed code's look-back of 66 pixels: a row longer than about 86 px (a 30 mm IC lying
/// within ~35 degrees of the rows) is more than 20 px from every recent pixel when the next
/// row starts, so each row opens a partial group; past the 30 groups the code overflowed. We
/// count those pixels instead (ThesisReport::dropped_pixels) and the text's 200 px avoids it.
TEST(ThesisPipelineAccuracy, TheCodesShortLookBackOverflowsOnLongRowsAsTheThesisWould) {
  const Cell& cell = Cell::get();
  const Eigen::Vector2d c = cell.window(25.0).center();
  std::vector<render::Part> parts;
  parts.reserve(3);
  for (int k = 0; k < 3; ++k) {
    parts.push_back(cell.part(fmt::format("ic{}", k), "ic_7x30", c.x() - 40 + 40 * k, c.y(), 0.02,
                              false));  // long sides along the rows
  }
  const RenderedScene frame =
      cell.render("long rows", parts, cell.aligned_joints(), Lights::kTubes, 6);
  ThesisOptions code;
  ThesisReport code_report;
  ASSERT_TRUE(thesis_locate(frame.image, code, &code_report));
  EXPECT_EQ(code_report.partial_groups, code.max_groups);
  EXPECT_GT(code_report.dropped_pixels, 0);
  ThesisOptions text = code;
  text.lookback_px = 200;
  ThesisReport text_report;
  const auto objects = thesis_locate(frame.image, text, &text_report);
  ASSERT_TRUE(objects);
  EXPECT_EQ(text_report.dropped_pixels, 0);
  EXPECT_EQ(objects->size(), 3U);
}

}  // namespace
}  // namespace cell::vision
