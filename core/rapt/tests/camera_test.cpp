#include "cell/rapt/camera.hpp"

#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include "cell/testing/matchers.hpp"
#include "support.hpp"

namespace cell::rapt {
namespace {

using ::cell::testing::IsErr;

constexpr double kTolImage = 1e-4;  // the thesis prints 6-7 significant digits

struct Printed {
  int situation;
  const char* edge;
  double y1, z1, y2, z2;
};

// Digest 003 §6.1 [verified]: every camera prediction printed in Appendix V section 3 (8
// LOOKs, 16 end points of which two coincide, each coordinate to 1e-4).
constexpr Printed kPrinted[] = {
    {3, "e1", -17.28073, 7.71058, -18.4667, 27.44932},
    {3, "e2", -15.52914, 20.09619, -20.18789, 20.09619},
    {10, "e1", 0.0, 12.33334, -24.66667, 12.33334},
    {10, "e2", -33.05263, 56.50052, -34.00656, -43.74868},
    {11, "e2", -4.111111, 4.111114, 20.55556, 4.111114},  // checks the end-point quirk
    {11, "e1", -4.111111, 4.111114, -4.111111, -37.0},
    {14, "e1", 35.71429, 7.142859, -14.28571, 7.142859},
    {14, "e2", 4.310345, 21.55173, 4.310345, 8.62069},
};

TEST(CameraAppendixV, ReproducesEveryPrintedEndPoint) {
  const CompiledProgram& cp = testing::appendix_v();
  int checked = 0;
  for (const Printed& p : kPrinted) {
    bool found = false;
    for (const CompiledPackage& pkg : cp.packages) {
      for (const CompiledLook& look : pkg.looks) {
        if (pkg.situation != p.situation || cp.program.feature(look.decl.edge).name != p.edge) {
          continue;
        }
        found = true;
        EXPECT_NEAR(look.predicted[0].x(), p.y1, kTolImage) << p.situation << " " << p.edge;
        EXPECT_NEAR(look.predicted[0].y(), p.z1, kTolImage) << p.situation << " " << p.edge;
        EXPECT_NEAR(look.predicted[1].x(), p.y2, kTolImage) << p.situation << " " << p.edge;
        EXPECT_NEAR(look.predicted[1].y(), p.z2, kTolImage) << p.situation << " " << p.edge;
        checked += 4;
      }
    }
    EXPECT_TRUE(found) << p.situation << " " << p.edge;
  }
  EXPECT_EQ(checked, 32);
}

// Digest §2.3 / §8.2 case 8: situation 11, e2 of b2 through cam6, tolerance (0, 12, 12): the
// short side is 4.11 +- 185*12/225 = -5.76..13.98 and the long side keeps what stays in view
// whatever the error, 5.76..10.69; printed rounded as p1 (6;-6), p2 (6;14), p3 (11;-6).
TEST(CameraAppendixV, WindowOfSituation11MatchesThePrintedWindow) {
  const CompiledProgram& cp = testing::appendix_v();
  const CompiledPackage& pkg = cp.packages[2];
  ASSERT_EQ(pkg.situation, 11);
  const Window& w = pkg.looks[0].window;
  EXPECT_NEAR(w.half_width, 185.0 * 12.0 / 225.0, 1e-9);
  EXPECT_NEAR(w.p1.x(), 6.0, 0.5);
  EXPECT_NEAR(w.p1.y(), -6.0, 0.5);
  EXPECT_NEAR(w.p2.x(), 6.0, 0.5);
  EXPECT_NEAR(w.p2.y(), 14.0, 0.5);
  EXPECT_NEAR(w.p3.x(), 11.0, 0.5);
  EXPECT_NEAR(w.p3.y(), -6.0, 0.5);
  EXPECT_TRUE(w.guaranteed);
}

TEST(Camera, JacobianMatchesFiniteDifferences) {
  CameraModel cam;
  cam.world_T_camera =
      frame_from_x(Eigen::Vector3d(300, 40, 80), Eigen::Vector3d(-1, 0.2, -0.3).normalized(),
                   Eigen::Vector3d(0, 1, 0));
  cam.focus = 50;
  const Eigen::Vector3d p(10, -20, 30);
  const Eigen::Matrix<double, 2, 3> j = cam.jacobian(p);
  for (int i = 0; i < 3; ++i) {
    const double h = 1e-5;
    const Eigen::Vector2d d = (*cam.project(p + h * Eigen::Vector3d::Unit(i)) -
                               *cam.project(p - h * Eigen::Vector3d::Unit(i))) /
                              (2 * h);
    EXPECT_NEAR(d.x(), j(0, i), 1e-7);
    EXPECT_NEAR(d.y(), j(1, i), 1e-7);
  }
  EXPECT_THAT(cam.project(Eigen::Vector3d(400, 40, 80)), IsErr(Errc::kOutOfRange));
}

TEST(Camera, GeneratedFaceContainsTheLensCentreAndTheImagedPoints) {
  CameraModel cam;
  cam.world_T_camera = frame_from_x(Eigen::Vector3d(0, 0, 500), Eigen::Vector3d(0, 0, -1));
  cam.focus = 25;
  const Eigen::Vector3d a(10, 20, 0);
  const Eigen::Vector3d b(-30, 5, 40);
  auto face = face_from_image(cam, *cam.project(a), *cam.project(b));
  ASSERT_TRUE(face);
  EXPECT_NEAR(face->normal.dot(a - face->point), 0.0, 1e-9);
  EXPECT_NEAR(face->normal.dot(b - face->point), 0.0, 1e-9);
  EXPECT_NEAR(face->normal.norm(), 1.0, 1e-12);
  EXPECT_THAT(face_from_image(cam, ImagePoint(1, 2), ImagePoint(1, 2)),
              IsErr(Errc::kInvalidArgument));
}

}  // namespace
}  // namespace cell::rapt
