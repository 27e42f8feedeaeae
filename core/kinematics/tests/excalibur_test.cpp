#include "cell/kinematics/excalibur.hpp"

#include <cmath>

#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include "cell/geometry/angles.hpp"
#include "cell/geometry/pose.hpp"
#include "cell/testing/matchers.hpp"
#include "cell/testing/tolerances.hpp"
#include "support/test_robots.hpp"

namespace cell::kinematics {
namespace {

using ::cell::testing::IsErrWith;
using ::cell::testing::IsNearPose;
using ::cell::testing::IsOk;
using geometry::deg_to_rad;
using geometry::kPi;
using geometry::rad_to_deg;

using ::cell::testing::kTolMm;
constexpr double kPrintedTol = 5.1e-5;   // the digest prints 4 decimals
constexpr double kPrintedTolMm = 0.051;  // placeholder positions printed to 0.001 cm

ExcaliburJoints deg(double a, double b, double c, double d, double e, double f) {
  ExcaliburJoints q;
  q << deg_to_rad(a), deg_to_rad(b), deg_to_rad(c), deg_to_rad(d), deg_to_rad(e), deg_to_rad(f);
  return q;
}

// Joint vectors equal modulo 2 pi per joint, within tol_deg.
MATCHER_P2(IsNearJointsDeg, expected, tol_deg, "joints near the expected ones (deg, mod 360)") {
  for (int i = 0; i < 6; ++i) {
    const double diff = rad_to_deg(geometry::wrap_to_pi(arg(i) - expected(i)));
    if (std::abs(diff) > tol_deg) {
      *result_listener << "joint " << i + 1 << " is " << rad_to_deg(arg(i)) << " deg, expected "
                       << rad_to_deg(expected(i)) << " deg";
      return false;
    }
  }
  return true;
}

class ExcaliburTest : public ::testing::Test {
 protected:
  void SetUp() override {
    auto robot = test::load_shipped("excalibur");
    ASSERT_TRUE(robot) << robot.error().message;
    model_ = *robot->excalibur();
  }

  void expect_nao(const Eigen::Isometry3d& t,
                  const Eigen::Vector3d& n,
                  const Eigen::Vector3d& o,
                  const Eigen::Vector3d& a) {
    EXPECT_LT((t.linear().col(0) - n).cwiseAbs().maxCoeff(), kPrintedTol)
        << "n = " << t.linear().col(0).transpose();
    EXPECT_LT((t.linear().col(1) - o).cwiseAbs().maxCoeff(), kPrintedTol)
        << "o = " << t.linear().col(1).transpose();
    EXPECT_LT((t.linear().col(2) - a).cwiseAbs().maxCoeff(), kPrintedTol)
        << "a = " << t.linear().col(2).transpose();
  }

  const IkSolution& branch(const IkSolutions& all, std::string_view name) {
    const IkSolution* s = all.find(name);
    EXPECT_NE(s, nullptr) << name;
    return s != nullptr ? *s : all[0];
  }

  ExcaliburModel model_;
};

// Digest 001 §8.2 case 1: q = 0 -> T6 = [I | (a2, 0, d1 + d4 + d6)], q* = (0, -30, 150, 0, 0, 0).
TEST_F(ExcaliburTest, Case1ZeroJointsStandTheForearmUp) {
  const Eigen::Isometry3d t = forward(model_, ExcaliburJoints::Zero());
  EXPECT_TRUE(t.linear().isIdentity(1e-15));
  EXPECT_TRUE(t.translation().isApprox(Eigen::Vector3d(304.8, 0.0, 711.2), 1e-15));
  EXPECT_THAT(to_controller(model_, ExcaliburJoints::Zero()),
              IsNearJointsDeg(deg(0, -30, 150, 0, 0, 0), 1e-12));
}

// Case 2: controller zero q* = 0, i.e. q = (0, 30, -150, 0, 0, 0), the elbow-up rest pose.
TEST_F(ExcaliburTest, Case2ControllerZero) {
  const ExcaliburJoints q = from_controller(model_, ExcaliburJoints::Zero());
  EXPECT_THAT(q, IsNearJointsDeg(deg(0, 30, -150, 0, 0, 0), 1e-12));
  const Eigen::Isometry3d t = forward(model_, q);
  expect_nao(t, {-0.5, 0, -0.8660}, {0, 1, 0}, {0.8660, 0, -0.5});
  EXPECT_NEAR(t.translation().x(), 659.91, kPrintedTolMm);
  EXPECT_NEAR(t.translation().y(), 0.0, 1e-12);
  EXPECT_NEAR(t.translation().z(), 177.80, kPrintedTolMm);
  // Exact: p = (0.8660 (a2 + d4 + d6), 0, d1 + 0.5 (a2 - d4 - d6)).
  EXPECT_NEAR(t.translation().x(), std::sqrt(3.0) / 2.0 * 762.0, kTolMm);
  EXPECT_NEAR(t.translation().z(), 254.0 + 0.5 * (304.8 - 304.8 - 152.4), kTolMm);
  const auto all = inverse_all(model_, t);
  ASSERT_THAT(all, IsOk());
  EXPECT_THAT(branch(*all, "shoulder_front/elbow_up/wrist_noflip").q, IsNearJointsDeg(q, 1e-9));
}

// Case 3: q = (30, 45, -120, 20, -40, 60), q* = (30, 15, 30, 20, -40, 60).
TEST_F(ExcaliburTest, Case3FourBranchesOfTheThesis) {
  const ExcaliburJoints q = deg(30, 45, -120, 20, -40, 60);
  EXPECT_THAT(to_controller(model_, q), IsNearJointsDeg(deg(30, 15, 30, 20, -40, 60), 1e-12));
  const Eigen::Isometry3d t = forward(model_, q);
  expect_nao(t, {-0.7270, 0.6712, -0.1447}, {0.1661, 0.3764, 0.9114}, {0.6663, 0.6385, -0.3852});
  EXPECT_LT((t.translation() - Eigen::Vector3d(543.16, 352.28, 489.71)).cwiseAbs().maxCoeff(),
            kPrintedTolMm);
  const auto all = inverse_all(model_, t);
  ASSERT_THAT(all, IsOk());
  // Elbow-up with the thesis's printed theta4 formula (= our flipped wrist) returns the input.
  EXPECT_THAT(branch(*all, "shoulder_front/elbow_up/wrist_flip").q, IsNearJointsDeg(q, 1e-9));
  // Elbow-up with the corrected S5 > 0 formula.
  EXPECT_THAT(branch(*all, "shoulder_front/elbow_up/wrist_noflip").q,
              IsNearJointsDeg(deg(30, 45, -120, -160, 40, -120), 1e-9));
  // Elbow-down: theta2 = 15, theta3 = -60.
  EXPECT_THAT(branch(*all, "shoulder_front/elbow_down/wrist_flip").q,
              IsNearJointsDeg(deg(30, 15, -60, 13.638, -68.814, 70.568), 1e-3));
  EXPECT_NEAR(rad_to_deg(branch(*all, "shoulder_front/elbow_down/wrist_noflip").q(1)), 15.0, 1e-9);
  EXPECT_NEAR(rad_to_deg(branch(*all, "shoulder_front/elbow_down/wrist_noflip").q(2)), -60.0, 1e-9);
  ASSERT_EQ(all->size(), 8u);
  for (const IkSolution& s : *all) {
    EXPECT_THAT(forward(model_, ExcaliburJoints(s.q)), IsNearPose(t, kTolMm)) << s.branch;
  }
}

// Case 4: q = (-60, 60, -100, -45, 70, 10); the elbow-up, S5 > 0 branch returns the input.
TEST_F(ExcaliburTest, Case4ElbowUpNoFlipReturnsTheInput) {
  const ExcaliburJoints q = deg(-60, 60, -100, -45, 70, 10);
  const Eigen::Isometry3d t = forward(model_, q);
  expect_nao(t, {0.3358, -0.8123, 0.4769}, {0.8376, 0.0259, -0.5456}, {0.4309, 0.5827, 0.6891});
  EXPECT_LT((t.translation() - Eigen::Vector3d(239.82, -212.86, 856.48)).cwiseAbs().maxCoeff(),
            kPrintedTolMm);
  const auto all = inverse_all(model_, t);
  ASSERT_THAT(all, IsOk());
  EXPECT_THAT(branch(*all, "shoulder_front/elbow_up/wrist_noflip").q, IsNearJointsDeg(q, 1e-9));
  for (const IkSolution& s : *all) {
    EXPECT_THAT(forward(model_, ExcaliburJoints(s.q)), IsNearPose(t, kTolMm)) << s.branch;
  }
  // The default choice rule, seeded with the input, returns the input.
  const auto nearest = inverse(model_, t, q);
  ASSERT_THAT(nearest, IsOk());
  EXPECT_THAT(*nearest, IsNearJointsDeg(q, 1e-9));
}

// Case 5: a wrist centre farther than a2 + d4 from the shoulder gives |S3| > 1: rejected with
// the distance and the reach.
TEST_F(ExcaliburTest, Case5RejectsTargetsOutOfReachAndSaysWhy) {
  const Eigen::Isometry3d t = geometry::make_pose({900.0, 0.0, 254.0}, {.pitch = kPi / 2});
  const auto all = inverse_all(model_, t);
  EXPECT_THAT(all, IsErrWith(Errc::kOutOfRange, "is 747.600 mm from the shoulder"));
  EXPECT_THAT(all, IsErrWith(Errc::kOutOfRange, "the arm reaches [0.000, 609.600] mm"));
  EXPECT_THAT(all, IsErrWith(Errc::kOutOfRange, "target (900.000, 0.000, 254.000) mm"));
}

// Case 6: for the pose of case 2 the + root gives theta3 = -30; the elbow switch gives
// 180 - (-30) = 210 = -150 deg, not -30 +- 180.
TEST_F(ExcaliburTest, Case6ElbowSwitchIsPiMinusTheta3) {
  const Eigen::Isometry3d t = forward(model_, deg(0, 30, -150, 0, 0, 0));
  const auto all = inverse_all(model_, t);
  ASSERT_THAT(all, IsOk());
  EXPECT_NEAR(rad_to_deg(branch(*all, "shoulder_front/elbow_down/wrist_noflip").q(2)), -30.0, 1e-9);
  EXPECT_NEAR(rad_to_deg(branch(*all, "shoulder_front/elbow_up/wrist_noflip").q(2)), -150.0, 1e-9);
}

// Case 7: FK(15, 30, -150, 25, 0, 40) = FK(15, 30, -150, 0, 0, 65); IK returns theta4 = 0,
// theta5 = 0, theta6 = 65 (the thesis's rule), or keeps theta4 with the keep_theta4 policy.
TEST_F(ExcaliburTest, Case7WristSingularityGivesAllTheRollToTheta6) {
  const Eigen::Isometry3d t = forward(model_, deg(15, 30, -150, 25, 0, 40));
  EXPECT_THAT(forward(model_, deg(15, 30, -150, 0, 0, 65)), IsNearPose(t, 1e-12));
  const auto all = inverse_all(model_, t);
  ASSERT_THAT(all, IsOk());
  const IkSolution& s = branch(*all, "shoulder_front/elbow_up/wrist_noflip");
  EXPECT_TRUE(s.singular);
  EXPECT_THAT(s.q, IsNearJointsDeg(deg(15, 30, -150, 0, 0, 65), 1e-9));
  for (const IkSolution& any : *all) {
    EXPECT_TRUE(any.q.allFinite());
    EXPECT_THAT(forward(model_, ExcaliburJoints(any.q)), IsNearPose(t, kTolMm)) << any.branch;
  }
  ExcaliburModel keep = model_;
  keep.wrist_singularity = WristSingularity::kKeepTheta4;
  const auto kept = inverse_all(keep, t, deg(15, 30, -150, 25, 0, 40));
  ASSERT_THAT(kept, IsOk());
  EXPECT_THAT(branch(*kept, "shoulder_front/elbow_up/wrist_noflip").q,
              IsNearJointsDeg(deg(15, 30, -150, 25, 0, 40), 1e-9));
}

// Case 8: q = (0, 90, -90, 0, 0, 0) puts the wrist centre on the base axis, p = (0, 0,
// d1 + a2 + d4 + d6). No NaN; theta1 keeps the reference (or 0).
TEST_F(ExcaliburTest, Case8ShoulderSingularityKeepsTheta1) {
  const Eigen::Isometry3d t = forward(model_, deg(0, 90, -90, 0, 0, 0));
  EXPECT_TRUE(t.translation().isApprox(Eigen::Vector3d(0, 0, 1016.0), 1e-12));
  const auto plain = inverse_all(model_, t);
  ASSERT_THAT(plain, IsOk());
  EXPECT_NEAR(branch(*plain, "shoulder_front/elbow_up/wrist_noflip").q(0), 0.0, 1e-12);
  const ExcaliburJoints reference = deg(40, 80, -90, 0, 10, 0);
  const auto all = inverse_all(model_, t, reference);
  ASSERT_THAT(all, IsOk());
  for (const IkSolution& s : *all) {
    EXPECT_TRUE(s.q.allFinite()) << s.branch;
    EXPECT_TRUE(s.singular) << s.branch;
    EXPECT_THAT(forward(model_, ExcaliburJoints(s.q)), IsNearPose(t, kTolMm)) << s.branch;
  }
  EXPECT_NEAR(rad_to_deg(branch(*all, "shoulder_front/elbow_up/wrist_noflip").q(0)), 40.0, 1e-9);
  EXPECT_NEAR(
      rad_to_deg(geometry::wrap_to_pi(branch(*all, "shoulder_back/elbow_up/wrist_noflip").q(0))),
      -140.0, 1e-9);
}

// Case 9: controller (10, 0, 0, 5, 5, 5)* <-> DH (10, 30, -150, 5, 5, 5).
TEST_F(ExcaliburTest, Case9ControllerAngleConversion) {
  EXPECT_THAT(from_controller(model_, deg(10, 0, 0, 5, 5, 5)),
              IsNearJointsDeg(deg(10, 30, -150, 5, 5, 5), 1e-12));
  EXPECT_THAT(to_controller(model_, deg(10, 30, -150, 5, 5, 5)),
              IsNearJointsDeg(deg(10, 0, 0, 5, 5, 5), 1e-12));
}

// Case 10: a target below the table (pz < 0) or inside the base radius is refused.
TEST_F(ExcaliburTest, Case10GuardsRefuseTableAndBase) {
  const Eigen::Isometry3d below = geometry::make_pose({400.0, 0.0, -5.0}, {.pitch = kPi});
  EXPECT_THAT(
      inverse_all(model_, below),
      IsErrWith(Errc::kOutOfRange, "tool point z = -5.000 mm is outside cartesian_limits.z_mm"));
  EXPECT_THAT(inverse_all(model_, below), IsErrWith(Errc::kOutOfRange, "table guard"));
  const Eigen::Isometry3d at_base = geometry::make_pose({50.0, 60.0, 100.0}, {.pitch = kPi});
  EXPECT_THAT(inverse_all(model_, at_base), IsErrWith(Errc::kOutOfRange, "inside the base guard"));
  EXPECT_THAT(check_guards(model_, at_base),
              IsErrWith(Errc::kOutOfRange, "radius 78.102 mm < 120.000 mm"));
  EXPECT_THAT(check_guards(model_, geometry::make_pose({400.0, 0.0, 5.0}, {})), IsOk());
}

// Case 11: from case 3, +2 cm along a gives p' = (55.649, 36.505, 48.201) cm with the same
// orientation; a world +X move changes only px.
TEST_F(ExcaliburTest, Case11RelativeMoves) {
  const ExcaliburJoints q = deg(30, 45, -120, 20, -40, 60);
  const Eigen::Isometry3d t = forward(model_, q);
  const Eigen::Isometry3d along_a = geometry::translate_in_frame(t, {0.0, 0.0, 20.0});
  EXPECT_LT((along_a.translation() - Eigen::Vector3d(556.49, 365.05, 482.01)).cwiseAbs().maxCoeff(),
            kPrintedTolMm);
  const auto moved = inverse(model_, along_a, q);
  ASSERT_THAT(moved, IsOk());
  EXPECT_THAT(forward(model_, *moved), IsNearPose(along_a, kTolMm));
  Eigen::Isometry3d world_x = t;
  world_x.translation().x() += 10.0;
  const auto moved_x = inverse(model_, world_x, q);
  ASSERT_THAT(moved_x, IsOk());
  const Eigen::Isometry3d back = forward(model_, *moved_x);
  EXPECT_NEAR(back.translation().x(), t.translation().x() + 10.0, kTolMm);
  EXPECT_NEAR(back.translation().y(), t.translation().y(), kTolMm);
  EXPECT_NEAR(back.translation().z(), t.translation().z(), kTolMm);
  EXPECT_LT(geometry::rotation_distance(back.linear(), t.linear()), 1e-12);
}

// With a2 = d4 the folded arm (theta3 = 90 deg) brings the wrist centre onto the shoulder, where
// theta2 is free. Near it, 1 - S3 must not be formed by cancellation (a 1M-sample search found a
// 1.7e-8 mm round-trip error there before 1 - S3 was computed from distances); exactly on it,
// theta2 keeps the reference.
TEST_F(ExcaliburTest, NearlyAndFullyFoldedArmStayAccurate) {
  for (const double theta3 : {-269.999932, -270.0}) {
    SCOPED_TRACE(theta3);
    const ExcaliburJoints q =
        deg(90.154617, 170.171864, theta3, -132.72509, -116.014837, -77.216773);
    ExcaliburModel m = model_;
    m.cartesian_limits = CartesianLimits{};
    const Eigen::Isometry3d t = forward(m, q);
    const auto all = inverse_all(m, t, q);
    ASSERT_THAT(all, IsOk());
    for (const IkSolution& s : *all) {
      EXPECT_TRUE(s.q.allFinite()) << s.branch;
      EXPECT_THAT(forward(m, ExcaliburJoints(s.q)), IsNearPose(t, kTolMm)) << s.branch;
    }
  }
}

TEST_F(ExcaliburTest, BranchIsChosenByNameOrRejectedWithTheValidNames) {
  const Eigen::Isometry3d t = forward(model_, deg(30, 45, -120, 20, -40, 60));
  const auto flip =
      inverse(model_, t, "shoulder_front/elbow_up/wrist_flip", ExcaliburJoints::Zero());
  ASSERT_THAT(flip, IsOk());
  EXPECT_THAT(*flip, IsNearJointsDeg(deg(30, 45, -120, 20, -40, 60), 1e-9));
  EXPECT_THAT(inverse(model_, t, "elbow_sideways", ExcaliburJoints::Zero()),
              IsErrWith(Errc::kInvalidArgument,
                        "unknown IK branch 'elbow_sideways'; valid branches: "
                        "shoulder_front/elbow_up/wrist_noflip, "));
}

TEST_F(ExcaliburTest, NamedBranchOutsideItsLimitsNamesTheJoint) {
  // Case 3 elbow-up no-flip has theta4 = -160 deg; narrow theta4 to +-150 deg.
  ExcaliburModel narrow = model_;
  narrow.joints[3].lower = deg_to_rad(-150.0);
  narrow.joints[3].upper = deg_to_rad(150.0);
  const Eigen::Isometry3d t = forward(narrow, deg(30, 45, -120, 20, -40, 60));
  EXPECT_THAT(inverse(narrow, t, "shoulder_front/elbow_up/wrist_noflip", ExcaliburJoints::Zero()),
              IsErrWith(Errc::kOutOfRange,
                        "branch shoulder_front/elbow_up/wrist_noflip: joint 'theta4' = -160.000 "
                        "deg is outside its limits [-150.000, 150.000] deg"));
}

// The branch names describe the geometry: shoulder_front aims the arm plane at the wrist
// centre, elbow_up keeps the elbow above the shoulder-wrist line, wrist_noflip has sin
// theta5 >= 0.
TEST_F(ExcaliburTest, BranchNamesMatchTheArmGeometry) {
  const ExcaliburJoints q = deg(-35, 70, -110, 30, 50, -20);
  const Eigen::Isometry3d t = forward(model_, q);
  const auto all = inverse_all(model_, t);
  ASSERT_THAT(all, IsOk());
  const Eigen::Vector3d w = wrist_centre(model_, t);
  const Eigen::Vector3d shoulder(0, 0, model_.d1_mm);
  for (const IkSolution& s : *all) {
    SCOPED_TRACE(s.branch);
    const std::string name(s.branch);
    const double t1 = s.q(0), t2 = s.q(1);
    const Eigen::Vector3d elbow =
        shoulder + model_.a2_mm * Eigen::Vector3d(std::cos(t1) * std::cos(t2),
                                                  std::sin(t1) * std::cos(t2), std::sin(t2));
    const Eigen::Vector3d radial(std::cos(t1), std::sin(t1), 0.0);
    const bool front = radial.dot(w - shoulder) > 0.0;
    EXPECT_EQ(front, name.starts_with("shoulder_front"));
    // In the vertical arm plane, with the horizontal axis pointing at the wrist centre: the elbow
    // is above the shoulder-wrist chord when it lies counter-clockwise of it.
    const Eigen::Vector2d toward_wrist = Eigen::Vector2d(w.x(), w.y()).normalized();
    const Eigen::Vector2d chord(Eigen::Vector2d(w.x(), w.y()).norm(), w.z() - shoulder.z());
    const Eigen::Vector2d e(toward_wrist.dot(Eigen::Vector2d(elbow.x(), elbow.y())),
                            elbow.z() - shoulder.z());
    const double above = chord.x() * e.y() - chord.y() * e.x();
    EXPECT_EQ(above > 0.0, name.find("elbow_up") != std::string::npos);
    EXPECT_EQ(std::sin(s.q(4)) >= 0.0, name.ends_with("wrist_noflip"));
  }
}

TEST_F(ExcaliburTest, RejectsNonRigidTargetsAndNonFiniteReferences) {
  Eigen::Isometry3d t = forward(model_, deg(30, 45, -120, 20, -40, 60));
  ExcaliburJoints bad = ExcaliburJoints::Zero();
  bad(2) = std::nan("");
  EXPECT_THAT(inverse_all(model_, t, bad), IsErrWith(Errc::kInvalidArgument, "reference joints"));
  t.linear() *= 2.0;
  EXPECT_THAT(inverse_all(model_, t), IsErrWith(Errc::kInvalidArgument, "not orthonormal"));
}

}  // namespace
}  // namespace cell::kinematics
