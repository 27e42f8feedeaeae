// The part catalogue: every entry sane, DIP sizes from the JEDEC packages, the thesis's ICs,
// the RAPT blocks' meshes, and the errors of bad classes.
#include "cell/world/part_class.hpp"

#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include <cmath>
#include <limits>
#include <numbers>
#include <vector>

#include "cell/testing/matchers.hpp"
#include "cell/testing/tolerances.hpp"
#include "cell/world/footprint.hpp"

namespace cell::world {
namespace {

using ::cell::testing::IsErrWith;
using ::cell::testing::IsOk;
using ::testing::HasSubstr;

using ::cell::testing::kTolMm;

/// Signed area of a polygon (> 0 when counter-clockwise).
double signed_area(const std::vector<Eigen::Vector2d>& p) {
  double a = 0.0;
  for (std::size_t i = 0; i < p.size(); ++i) {
    const auto& u = p[i];
    const auto& v = p[(i + 1) % p.size()];
    a += u.x() * v.y() - v.x() * u.y();
  }
  return a / 2.0;
}

TEST(Catalogue, EveryBuiltInClassIsValidAndSane) {
  const Catalogue cat = Catalogue::standard();
  ASSERT_GE(cat.size(), 20U);
  for (const auto& name : cat.names()) {
    SCOPED_TRACE(name);
    const auto cls = cat.find(name);
    ASSERT_NE(cls, nullptr);
    EXPECT_THAT(cls->validate(), IsOk());
    EXPECT_EQ(cls->name, name);
    EXPECT_FALSE(cls->description.empty());
    EXPECT_GT(cls->length_mm, 0.0);
    EXPECT_GT(cls->width_mm, 0.0);
    EXPECT_GT(cls->height_mm, 0.0);
    EXPECT_LE(cls->height_mm, 200.0);
    EXPECT_GE(cls->reflectance, 0.0);
    EXPECT_LE(cls->reflectance, 1.0);
    // The footprint: counter-clockwise, around the part origin, about length x width.
    ASSERT_GE(cls->footprint.size(), 3U);
    EXPECT_GT(signed_area(cls->footprint), 0.0);
    Footprint f;
    f.points = cls->footprint;
    f.update_bounds();
    EXPECT_TRUE(contains(f, Eigen::Vector2d::Zero()));
    EXPECT_NEAR(f.max.x() - f.min.x(), cls->length_mm, 0.05 * cls->length_mm + 1e-6);
    EXPECT_GE(f.max.y() - f.min.y(), cls->width_mm * 0.99);
    // The default grasp: top centre, axes of the part.
    EXPECT_NEAR(cls->part_T_grasp.translation().z(), cls->height_mm, kTolMm);
    EXPECT_NEAR(cls->part_T_grasp.translation().head<2>().norm(), 0.0, kTolMm);
    EXPECT_TRUE(cls->part_T_grasp.linear().isIdentity(1e-12));
    // Hull points span the part's height.
    double zmin = std::numeric_limits<double>::infinity();
    double zmax = -std::numeric_limits<double>::infinity();
    for (const auto& p : cls->hull_points) {
      zmin = std::min(zmin, p.z());
      zmax = std::max(zmax, p.z());
    }
    EXPECT_NEAR(zmin, 0.0, kTolMm);
    EXPECT_NEAR(zmax, cls->height_mm, kTolMm);
  }
}

// JEDEC MS-001 (0.3") and MS-011 (0.6") nominal bodies; 2.54 mm pitch; black epoxy.
TEST(Catalogue, DipsHaveTheirPackageSizes) {
  const Catalogue cat = Catalogue::standard();
  struct Expect {
    const char* name;
    int pins;
    double length;
    double width;
    double rows;
  };
  for (const Expect& e :
       {Expect{"dip8", 8, 9.27, 6.35, 7.62}, Expect{"dip14", 14, 19.05, 6.35, 7.62},
        Expect{"dip16", 16, 19.30, 6.35, 7.62}, Expect{"dip20", 20, 26.16, 6.35, 7.62},
        Expect{"dip24", 24, 31.75, 13.72, 15.24}, Expect{"dip40", 40, 52.07, 13.72, 15.24}}) {
    SCOPED_TRACE(e.name);
    const auto c = cat.find(e.name);
    ASSERT_NE(c, nullptr);
    EXPECT_EQ(c->shape, Shape::kDip);
    EXPECT_EQ(c->dip.pins, e.pins);
    EXPECT_DOUBLE_EQ(c->length_mm, e.length);
    EXPECT_DOUBLE_EQ(c->width_mm, e.width);
    EXPECT_DOUBLE_EQ(c->dip.row_spacing_mm, e.rows);
    EXPECT_DOUBLE_EQ(c->dip.pitch_mm, 2.54);
    EXPECT_DOUBLE_EQ(c->reflectance, 0.1);
    EXPECT_EQ(c->yaw_symmetry, 2);
    // Seated height below JEDEC's 5.33 mm maximum.
    EXPECT_LT(c->height_mm, 5.33);
    EXPECT_NEAR(c->height_mm, c->dip.standoff_mm + c->dip.body_thickness_mm, kTolMm);
  }
}

// Digest 000 §3 and §7: the 14-pin 6 x 19 mm IC and the 7 x 30 mm ICs.
TEST(Catalogue, TheThesisIcsAreRepresentable) {
  const Catalogue cat = Catalogue::standard();
  const auto small = cat.find("ic_6x19");
  ASSERT_NE(small, nullptr);
  EXPECT_EQ(small->dip.pins, 14);
  EXPECT_DOUBLE_EQ(small->length_mm, 19.0);
  EXPECT_DOUBLE_EQ(small->width_mm, 6.0);
  const auto big = cat.find("ic_7x30");
  ASSERT_NE(big, nullptr);
  EXPECT_DOUBLE_EQ(big->length_mm, 30.0);
  EXPECT_DOUBLE_EQ(big->width_mm, 7.0);
}

TEST(DipPackage, PinsAreNumberedCounterClockwiseFromTheNotch) {
  const auto dip8 = Catalogue::standard().find("dip8");
  ASSERT_NE(dip8, nullptr);
  const DipPackage& d = dip8->dip;
  // 4 pins per row, 2.54 mm apart, centred: x = -3.81 .. 3.81; rows at y = -+3.81.
  EXPECT_TRUE(d.pin_centre(1).isApprox(Eigen::Vector2d(-3.81, -3.81)));
  EXPECT_TRUE(d.pin_centre(4).isApprox(Eigen::Vector2d(3.81, -3.81)));
  EXPECT_TRUE(d.pin_centre(5).isApprox(Eigen::Vector2d(3.81, 3.81)));
  EXPECT_TRUE(d.pin_centre(8).isApprox(Eigen::Vector2d(-3.81, 3.81)));
  EXPECT_NEAR((d.pin_centre(2) - d.pin_centre(1)).norm(), 2.54, kTolMm);
  EXPECT_TRUE(d.pin_centre(0).isZero());
  EXPECT_TRUE(d.pin_centre(9).isZero());
}

TEST(DipPackage, TheFootprintIncludesTheLeads) {
  const auto dip14 = Catalogue::standard().find("dip14");
  ASSERT_NE(dip14, nullptr);
  double ymax = 0.0;
  for (const auto& p : dip14->footprint) {
    ymax = std::max(ymax, p.y());
  }
  EXPECT_NEAR(ymax, (7.62 + 0.25) / 2.0, kTolMm);  // leads stick out of the 6.35 mm body
}

// Digest 003 App. V body b3: column 20 x 30 x 140 with an arm to x = 60 at z 50..90.
TEST(RaptBlocks, B3IsTheThesisBodyAndAClosedMesh) {
  const auto b3 = Catalogue::standard().find("rapt_b3");
  ASSERT_NE(b3, nullptr);
  EXPECT_EQ(b3->shape, Shape::kPolyhedron);
  EXPECT_THAT(b3->mesh.validate(), IsOk());
  EXPECT_DOUBLE_EQ(b3->length_mm, 60.0);
  EXPECT_DOUBLE_EQ(b3->width_mm, 30.0);
  EXPECT_DOUBLE_EQ(b3->height_mm, 140.0);
  EXPECT_EQ(b3->mesh.faces.size(), 12U);
  // The thesis's p5 = (60, 0, 50) in the body frame; the part frame is centred on the
  // footprint (x 0..60, y -30..0) at the bottom.
  const Eigen::Vector3d p5 = b3->part_T_model * Eigen::Vector3d(60, 0, 50);
  EXPECT_TRUE(p5.isApprox(Eigen::Vector3d(30, 15, 50)));
}

// App. VI: the gripper case, 72 x 55 x 163 mm, lies on its face x = 0 (x is vertical there).
TEST(RaptBlocks, TheCaseLiesOnItsSide) {
  const auto c = Catalogue::standard().find("rapt_case");
  ASSERT_NE(c, nullptr);
  EXPECT_DOUBLE_EQ(c->length_mm, 163.0);
  EXPECT_DOUBLE_EQ(c->width_mm, 55.0);
  EXPECT_DOUBLE_EQ(c->height_mm, 72.0);
  // Model x (up in the thesis's world) is the part's z.
  EXPECT_TRUE(
      (c->part_T_model.linear() * Eigen::Vector3d::UnitX()).isApprox(Eigen::Vector3d::UnitZ()));
  EXPECT_NEAR(c->part_T_model.linear().determinant(), 1.0, 1e-12);
  // The thesis's p9 = (72, 0, 0), centre of the top face, is the part's top centre.
  EXPECT_TRUE((c->part_T_model * Eigen::Vector3d(72, 0, 0)).isApprox(Eigen::Vector3d(0, 0, 72)));
}

TEST(Mesh, ValidateFindsAFlippedFace) {
  const auto b2 = Catalogue::standard().find("rapt_b2");
  ASSERT_NE(b2, nullptr);
  Mesh m = b2->mesh;
  std::reverse(m.faces[2].begin(), m.faces[2].end());
  EXPECT_THAT(m.validate(), IsErrWith(Errc::kInvalidArgument, "inconsistently oriented"));
  Mesh inside_out = b2->mesh;
  for (auto& f : inside_out.faces) {
    std::reverse(f.begin(), f.end());
  }
  EXPECT_THAT(inside_out.validate(), IsErrWith(Errc::kInvalidArgument, "negative volume"));
  Mesh bad_index = b2->mesh;
  bad_index.faces[0][0] = 99;
  EXPECT_THAT(bad_index.validate(), IsErrWith(Errc::kInvalidArgument, "face 0 uses vertex 99"));
}

TEST(PartClass, InvalidClassesSayWhatIsWrong) {
  Catalogue cat;
  EXPECT_THAT(cat.add(make_dip("dip7", 7, 19.0, 6.35, 7.62)),
              IsErrWith(Errc::kInvalidArgument, "even pin count"));
  EXPECT_THAT(cat.add(make_dip("cramped", 40, 20.0, 6.35, 7.62)),
              IsErrWith(Errc::kInvalidArgument, "need a body of at least 49.78 mm"));
  EXPECT_THAT(cat.add(make_prism("shiny", Shape::kRectangle, 10, 5, 2, 1.5)),
              IsErrWith(Errc::kInvalidArgument, "reflectance must be in [0, 1], got 1.5"));
  EXPECT_THAT(cat.add(make_prism("flat", Shape::kBox, 10, 5, -2, 0.5)),
              IsErrWith(Errc::kInvalidArgument, "part class 'flat': height_mm must be > 0"));
  EXPECT_EQ(cat.size(), 0U);
  ASSERT_THAT(cat.add(make_prism("plate", Shape::kRectangle, 10, 5, 2, 0.5)), IsOk());
  EXPECT_THAT(cat.add(make_prism("plate", Shape::kRectangle, 10, 5, 2, 0.5)),
              IsErrWith(Errc::kInvalidArgument, "defined twice"));
  EXPECT_EQ(cat.find("nothing"), nullptr);
  EXPECT_EQ(cat.list(), "plate");
}

// A parallel-jaw gripper takes an oblong part across it or along it (config/vision.yaml's
// "across" and "ends" for DIPs); squares, discs, triangles and polyhedra at their one grasp.
TEST(PartClass, BuiltInGraspYaws) {
  const Catalogue cat = Catalogue::standard();
  const std::vector<double> across_and_ends = {0.0, std::numbers::pi / 2.0};
  const std::vector<double> across = {0.0};
  for (const char* name : {"dip14", "dip40", "ic_7x30", "rectangle", "box"}) {
    SCOPED_TRACE(name);
    ASSERT_NE(cat.find(name), nullptr);
    EXPECT_EQ(cat.find(name)->grasp_yaws_rad, across_and_ends);
  }
  for (const char* name : {"square", "disc", "triangle", "rapt_b1", "rapt_b3", "rapt_case"}) {
    SCOPED_TRACE(name);
    ASSERT_NE(cat.find(name), nullptr);
    EXPECT_EQ(cat.find(name)->grasp_yaws_rad, across);
  }
  // A square box has 4-fold symmetry already; a rectangle of equal sides keeps both grasps.
  EXPECT_EQ(make_prism("cube", Shape::kBox, 20, 20, 20, 0.5).grasp_yaws_rad, across);
  EXPECT_EQ(make_prism("plate", Shape::kRectangle, 20, 20, 2, 0.5).grasp_yaws_rad, across_and_ends);
  EXPECT_EQ(PartClass{}.grasp_yaws_rad, across);
}

TEST(PartClass, GraspYawsMustBeGivenAndFinite) {
  PartClass none = make_dip("chip", 14, 19.05, 6.35, 7.62);
  none.grasp_yaws_rad.clear();
  EXPECT_THAT(none.validate(),
              IsErrWith(Errc::kInvalidArgument, "part class 'chip': grasp_yaws_rad is empty"));
  PartClass nan = make_prism("plate", Shape::kRectangle, 10, 5, 2, 0.5);
  nan.grasp_yaws_rad = {0.0, std::numeric_limits<double>::quiet_NaN()};
  EXPECT_THAT(nan.validate(), IsErrWith(Errc::kInvalidArgument,
                                        "part class 'plate': grasp_yaws_rad[1] is not finite"));
  Catalogue cat;
  EXPECT_THAT(cat.add(none), IsErrWith(Errc::kInvalidArgument, "grasp_yaws_rad"));
  EXPECT_EQ(cat.size(), 0U);
}

TEST(Shape, NamesRoundTrip) {
  for (const Shape s : {Shape::kDip, Shape::kRectangle, Shape::kSquare, Shape::kDisc,
                        Shape::kTriangle, Shape::kBox, Shape::kPolyhedron}) {
    const auto back = shape_from_string(to_string(s));
    ASSERT_THAT(back, IsOk());
    EXPECT_EQ(*back, s);
  }
  EXPECT_THAT(shape_from_string("circle"),
              IsErrWith(Errc::kInvalidArgument, "unknown shape 'circle'"));
}

TEST(PartClass, TriangleAndDiscOutlines) {
  const auto tri = make_prism("t", Shape::kTriangle, 30.0, 0.0, 2.0, 0.1);
  ASSERT_EQ(tri.footprint.size(), 3U);
  EXPECT_NEAR(tri.width_mm, 30.0 * std::sqrt(3.0) / 2.0, kTolMm);
  EXPECT_NEAR((tri.footprint[1] - tri.footprint[0]).norm(), 30.0, kTolMm);
  EXPECT_NEAR((tri.footprint[2] - tri.footprint[1]).norm(), 30.0, kTolMm);
  EXPECT_EQ(tri.yaw_symmetry, 3);
  const auto disc = make_prism("d", Shape::kDisc, 20.0, 0.0, 2.0, 0.1);
  EXPECT_DOUBLE_EQ(disc.width_mm, 20.0);
  for (const auto& p : disc.footprint) {  // circumscribed: never inside the circle
    EXPECT_GE(p.norm(), 10.0 - kTolMm);
    EXPECT_LE(p.norm(), 10.1);
  }
  EXPECT_EQ(disc.yaw_symmetry, 0);
}

}  // namespace
}  // namespace cell::world
