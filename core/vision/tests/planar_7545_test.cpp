// The thesis's planar camera-to-robot model against the digest's cases (digest 000 §9.2).
#include "cell/vision/planar_7545.hpp"

#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include <cmath>
#include <numbers>

#include "cell/geometry/angles.hpp"
#include "cell/testing/matchers.hpp"
#include "cell/vision/pixel_mapper.hpp"
#include "cell/vision/thesis.hpp"

namespace cell::vision {
namespace {

using ::cell::testing::IsErr;

using geometry::kDeg;
constexpr double kDigestTolMm = 0.02;  // the digest prints two decimals

/// The code's defaults (digest 000 §4): c_x 3.56, c_y 3.48 px/mm, Ref_Point (3, 457), centre
/// (255, 241), d_t_c 81.8 mm, b_angl 137.7 deg, angl_err 1.8 deg, links 400 / 250, D 420.
calibration::PlanarParameters thesis_planar() {
  calibration::PlanarParameters p;
  p.c_x_px_per_mm = 3.56;
  p.c_y_px_per_mm = 3.48;
  p.ref_u_px = 3.0;
  p.ref_v_px = 457.0;
  p.center_u_px = 255.0;
  p.center_v_px = 241.0;
  p.d_t_c_mm = 81.8;
  p.b_angl_rad = 137.7 * kDeg;
  p.angl_err_rad = 1.8 * kDeg;
  p.link1_mm = 400.0;
  p.link2_mm = 250.0;
  p.camera_height_mm = 420.0;
  return p;
}

// The grab pose as the code reads it: jt1 = counts / 872.2222, jt2 = counts / 444.444.
constexpr double kJ1 = 39249.0 / 872.2222 * kDeg;
constexpr double kJ2 = 46662.0 / 444.444 * kDeg;

// Digest 000 §9.2 case 8: the Ref_Point pixel is d_t_c from the tool: (41.51, 485.81) mm.
TEST(Planar7545, RefPointMapsToTheDigestsCase8) {
  const auto xy = planar_pixel_to_base(thesis_planar(), kJ1, kJ2, {3.0, 457.0});
  ASSERT_TRUE(xy) << xy.error().message;
  EXPECT_NEAR(xy->x(), 41.51, kDigestTolMm);
  EXPECT_NEAR(xy->y(), 485.81, kDigestTolMm);
}

// Case 9: the centre pixel (255, 241) -> (134.39, 501.25) mm; cases 10: two more pixels.
TEST(Planar7545, PixelsMapToTheDigestsCases9And10) {
  struct Case {
    Eigen::Vector2d px;
    Eigen::Vector2d mm;
  };
  for (const Case& c : {Case{{255, 241}, {134.39, 501.25}}, Case{{100, 400}, {73.30, 485.37}},
                        Case{{400, 100}, {190.35, 514.21}}}) {
    const auto xy = planar_pixel_to_base(thesis_planar(), kJ1, kJ2, c.px);
    ASSERT_TRUE(xy) << xy.error().message;
    EXPECT_NEAR(xy->x(), c.mm.x(), kDigestTolMm) << c.px.transpose();
    EXPECT_NEAR(xy->y(), c.mm.y(), kDigestTolMm) << c.px.transpose();
  }
}

TEST(Planar7545, InverseRoundTripsOverTheModelsQuadrant) {
  const auto p = thesis_planar();
  for (double u = 40; u <= 500; u += 46) {
    for (double v = 10; v <= 420; v += 41) {
      const auto xy = planar_pixel_to_base(p, kJ1, kJ2, {u, v});
      ASSERT_TRUE(xy);
      const auto px = planar_base_to_pixel(p, kJ1, kJ2, *xy);
      ASSERT_TRUE(px) << px.error().message;
      EXPECT_NEAR(px->x(), u, 1e-6);
      EXPECT_NEAR(px->y(), v, 1e-6);
    }
  }
}

TEST(Planar7545, RejectsNonPositiveScales) {
  auto p = thesis_planar();
  p.c_x_px_per_mm = 0.0;
  const auto xy = planar_pixel_to_base(p, kJ1, kJ2, {10, 10});
  EXPECT_THAT(xy, IsErr(Errc::kInvalidArgument));
  EXPECT_THAT(xy.error().message, ::testing::HasSubstr("c_x and c_y must be > 0"));
}

// Case 12: parallax with h = 8.5, D = 420: (j, i) = (0, 0) -> (5, 5); (480, 511) -> (475, 506).
TEST(Planar7545, ParallaxCorrectionMatchesTheDigestsCase12) {
  const Eigen::Vector2i centre(255, 241);
  EXPECT_EQ(thesis_parallax_int({0, 0}, centre, 8.5, 420.0), Eigen::Vector2i(5, 5));
  EXPECT_EQ(thesis_parallax_int({511, 480}, centre, 8.5, 420.0), Eigen::Vector2i(506, 475));
  // Zero at the centre, and the real-valued form agrees before rounding.
  EXPECT_EQ(thesis_parallax_int(centre, centre, 8.5, 420.0), centre);
  const Eigen::Vector2d p = thesis_parallax({0.0, 0.0}, {255.0, 241.0}, 8.5, 420.0);
  EXPECT_NEAR(p.x(), 255.0 * 8.5 / 420.0, 1e-12);
  EXPECT_NEAR(p.y(), 241.0 * 8.5 / 420.0, 1e-12);
}

// Case 11: an IC along the j axis -> O_r = -58.19 deg, R = -13241; along i -> +31.82, 7240.
// (The digest rounds O_r to 0.01 deg before converting; the code truncates the unrounded
// value, which can differ by one count.)
TEST(Planar7545, OrientationMatchesTheDigestsCase11) {
  const double aspect = 3.56 / 3.48;
  // The digest lists the corners (j, i); ThesisPixel is (i, j). Ordered by eq. 4.16 first.
  auto alpha = [&](const std::vector<ThesisPixel>& corners) {
    const auto o = thesis_order_corners(corners);
    return thesis_alpha_deg(o[0].cast<double>(), o[1].cast<double>(), o[2].cast<double>(),
                            o[3].cast<double>(), aspect);
  };
  const double vertical = alpha({{250, 300}, {250, 200}, {275, 300}, {275, 200}});
  EXPECT_NEAR(vertical, 0.0, 1e-12);
  const double roll_v = thesis_roll_deg(vertical, kJ1, kJ2, 1.8 * kDeg);
  EXPECT_NEAR(roll_v, -58.19, 0.01);
  EXPECT_EQ(thesis_roll_counts(roll_v), -13241);
  const double horizontal = alpha({{300, 250}, {200, 250}, {300, 275}, {200, 275}});
  EXPECT_NEAR(horizontal, 89.9943, 1e-3);  // dy = 0 is replaced by 0.01
  const double roll_h = thesis_roll_deg(horizontal, kJ1, kJ2, 1.8 * kDeg);
  EXPECT_NEAR(roll_h, 31.82, 0.01);
  EXPECT_NEAR(static_cast<double>(thesis_roll_counts(roll_h)), 7240.0, 1.0);
}

TEST(Planar7545, LongSidesNearHorizontalGiveNinetyDegrees) {
  // The two atan values straddle +-90: they differ by more than 150 degrees.
  const double a = thesis_alpha_deg({300, 251}, {200, 250}, {300, 275}, {200, 276}, 1.0);
  EXPECT_EQ(a, 90.0);
}

calibration::CameraCalibration planar_calibration() {
  calibration::CameraCalibration c;
  c.camera_id = "ibm7545_eye";
  c.model = calibration::ModelType::kPlanar7545;
  c.mounting = calibration::Mounting::kEyeInHand;
  c.mount_frame = render::MountFrame::kLink2;
  c.robot_id = "ibm7545";
  c.width_px = 512;
  c.height_px = 484;
  c.planar = thesis_planar();
  c.version = "thesis";
  return c;
}

// The mapper with a planar_7545 calibration: table-level pixels follow the thesis's formulas;
// a surface h above the table is corrected by eq. 2.21 first.
TEST(PixelMapperPlanar, MapsThroughTheThesisFormulasWithParallax) {
  const std::vector<double> joints{kJ1, kJ2, 0.0, 0.0};
  const auto m = PixelMapper::create(planar_calibration(), nullptr, joints);
  ASSERT_TRUE(m) << m.error().message;
  EXPECT_TRUE(m->metric());
  EXPECT_TRUE(m->world());
  const auto q = m->to_plane({255.0, 241.0}, 0.0);
  ASSERT_TRUE(q);
  const auto base = m->to_base(*q, 0.0);
  ASSERT_TRUE(base);
  EXPECT_NEAR(base->x_mm, 134.39, kDigestTolMm);
  EXPECT_NEAR(base->y_mm, 501.25, kDigestTolMm);
  // A top face 8.5 mm up seen at (0, 0) lies over the table pixel (5, 5) (case 12).
  const auto top = m->to_plane({0.0, 0.0}, 8.5);
  const auto table = m->to_plane({255.0 * 8.5 / 420.0, 241.0 * 8.5 / 420.0}, 0.0);
  ASSERT_TRUE(top && table);
  EXPECT_NEAR((*top - *table).norm(), 0.0, 1e-9);
  const auto back = m->to_pixel(*top, 8.5);
  ASSERT_TRUE(back);
  EXPECT_NEAR(back->norm(), 0.0, 1e-9);
  EXPECT_NEAR(m->camera_height_mm(), 420.0, 1e-12);
}

TEST(PixelMapperPlanar, WithoutJointsItIsImageOnlyAndSaysSo) {
  const auto m = PixelMapper::create(planar_calibration(), nullptr, {});
  ASSERT_TRUE(m);
  EXPECT_TRUE(m->metric());
  EXPECT_FALSE(m->world());
  EXPECT_THAT(m->describe(), ::testing::HasSubstr("no joints"));
  EXPECT_THAT(m->to_base({0, 0}, 0.0), IsErr(Errc::kNotReady));
}

}  // namespace
}  // namespace cell::vision
