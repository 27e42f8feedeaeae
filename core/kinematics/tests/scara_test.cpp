#include "cell/kinematics/scara.hpp"

#include <cmath>

#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include "cell/geometry/angles.hpp"
#include "cell/geometry/pose.hpp"
#include "cell/geometry/pose2.hpp"
#include "cell/testing/matchers.hpp"
#include "cell/testing/tolerances.hpp"
#include "support/test_robots.hpp"

namespace cell::kinematics {
namespace {

using ::cell::testing::IsErrWith;
using ::cell::testing::IsNearPose;
using ::cell::testing::IsOk;
using geometry::deg_to_rad;
using geometry::rad_to_deg;
using ::testing::HasSubstr;

using ::cell::testing::kTolMm;

class Ibm7545Test : public ::testing::Test {
 protected:
  void SetUp() override {
    auto robot = test::load_shipped("ibm7545");
    ASSERT_TRUE(robot) << robot.error().message;
    model_ = *robot->scara();
  }

  // Counts of a joint vector (all four joints have encoder scales on the 7545).
  CountVector counts(const ScaraJoints& q) const {
    auto c = to_counts(model_.joints, JointVector(q));
    EXPECT_THAT(c, IsOk());
    return c ? *c : CountVector::Zero(4);
  }

  // The R axis at (x, y) [mm], Z = z_mm down, part angle yaw [rad] in the world.
  static Eigen::Isometry3d target(double x, double y, double z_mm = 200.0, double yaw = 0.0) {
    return geometry::to_3d(geometry::Pose2{x, y, yaw}, -z_mm);
  }

  ScaraModel model_;
};

// Digest 000 §9.2 case 1: the Out_pos table of cubic_spline() is IK(-250, y) in counts. Our IK
// reproduces the printed IK exactly and the table within the +-3 counts the digest explains
// (row (-250, 280): table (82262, 50705), printed IK (82260, 50702)).
TEST_F(Ibm7545Test, ReproducesTheOutPosTable) {
  struct Row {
    double y_mm;
    std::int64_t table_j1, table_j2;  // Out_pos as printed in the code
    std::int64_t ik_j1, ik_j2;        // the code's IK of (-250, y), [derived]
  };
  const Row rows[] = {{250, 84496, 52967, 84496, 52967},
                      {280, 82262, 50705, 82260, 50702},
                      {310, 80578, 48281, 80578, 48281},
                      {340, 79411, 45701, 79411, 45701},
                      {370, 78726, 42948, 78726, 42948}};
  for (const Row& row : rows) {
    SCOPED_TRACE(row.y_mm);
    const auto q = inverse(model_, target(-250.0, row.y_mm), ElbowBranch::kJ2Positive);
    ASSERT_THAT(q, IsOk());
    const CountVector c = counts(*q);
    EXPECT_EQ(c(0), row.ik_j1);
    EXPECT_EQ(c(1), row.ik_j2);
    EXPECT_LE(std::abs(c(0) - row.table_j1), 3);
    EXPECT_LE(std::abs(c(1) - row.table_j2), 3);
    EXPECT_EQ(c(2), 76192);  // Z = 200 mm = 200 * 380.96 counts (digest 000 §5)
    EXPECT_EQ(c(3), 0);      // Out_pos R = 0
  }
}

// Digest 000 §9.2 case 2: the image-grab pose J1 = 0x9951, J2 = 0xB646.
TEST_F(Ibm7545Test, GrabPoseCountsAnglesAndPositionAgree) {
  CountVector grab(4);
  grab << 39249, 46662, 0, 0;
  const auto q = from_counts(model_.joints, grab);
  ASSERT_THAT(q, IsOk());
  EXPECT_NEAR(rad_to_deg((*q)(0)), 45.0, 0.05);
  EXPECT_NEAR(rad_to_deg((*q)(1)), 105.0, 0.05);
  const Eigen::Isometry3d base_T_tool = forward(model_, ScaraJoints(*q));
  EXPECT_NEAR(base_T_tool.translation().x(), 66.37, 0.005);
  EXPECT_NEAR(base_T_tool.translation().y(), 407.88, 0.005);
  // IK of that point returns the same counts exactly, from the exact point and from the
  // two-decimal one the digest prints.
  for (const Eigen::Isometry3d& t : {base_T_tool, target(66.37, 407.88, 0.0)}) {
    const auto back = inverse(model_, t, ElbowBranch::kJ2Positive);
    ASSERT_THAT(back, IsOk());
    const CountVector c = counts(*back);
    EXPECT_EQ(c(0), 39249);
    EXPECT_EQ(c(1), 46662);
  }
}

// Digest 000 §9.2 case 3: home counts (0, 0) <-> (650, 0) mm.
TEST_F(Ibm7545Test, HomeIsFullyStretchedAlongBaseX) {
  const Eigen::Isometry3d home = forward(model_, ScaraJoints::Zero());
  EXPECT_THAT(home, IsNearPose(target(650.0, 0.0, 0.0), kTolMm));
  const auto q = inverse(model_, home, ElbowBranch::kJ2Positive);
  ASSERT_THAT(q, IsOk());
  const CountVector c = counts(*q);
  EXPECT_EQ(c, CountVector::Zero(4));
}

// The 7545's Z counts grow downward (digest 000 §2.1): Z = 227.7 mm is 227.7 mm below home.
TEST_F(Ibm7545Test, ZJointIsPositiveDown) {
  const Eigen::Isometry3d t = forward(model_, ScaraJoints(0.5, 1.0, 227.7, 0.0));
  EXPECT_NEAR(t.translation().z(), -227.7, kTolMm);
  const auto q = inverse(model_, t, ElbowBranch::kJ2Positive);
  ASSERT_THAT(q, IsOk());
  EXPECT_NEAR((*q)(2), 227.7, kTolMm);
  EXPECT_EQ(counts(*q)(2), 86745);  // 227.7 * 380.96 = 86744.6 counts, rounded
}

// Digest 000 §5, eq. 4.2/4.3 and §9.2 case 11: O_r = -(alpha + J1 + J2 - 90 - angl_err), with
// J1, J2 the image-time joints (grab pose) and angl_err = 1.8 deg. The part's world angle is
// phi = alpha + J1 + J2 - 90 - angl_err; gripping it at (134.39, 501.25) mm (case 9) must give
// R = -phi: -58.19 deg = -13241 counts for the vertical IC (alpha = 0), and, folded by 180 deg
// for the symmetric IC, +31.82 deg = 7240 counts for the horizontal one.
TEST_F(Ibm7545Test, RollIsReferencedToTheWorldAsTheThesisOrientationFormula) {
  const double j1_deg = 39249 / 872.2222;
  const double j2_deg = 46662 / 444.4444;
  const double angl_err_deg = 1.8;
  // Vertical long side: alpha = 0.
  const double phi_vertical = deg_to_rad(0.0 + j1_deg + j2_deg - 90.0 - angl_err_deg);
  const auto q =
      inverse(model_, target(134.39, 501.25, 227.7, phi_vertical), ElbowBranch::kJ2Positive);
  ASSERT_THAT(q, IsOk());
  EXPECT_NEAR(rad_to_deg((*q)(3)), -58.19, 0.005);
  EXPECT_EQ(counts(*q)(3), -13241);
  // Digest 000 §9.2 case 9: (134.39, 501.25) mm -> (41050, 33985) counts, derived from the
  // unrounded point; from the two-decimal point J2 lands 1 count lower.
  EXPECT_EQ(counts(*q)(0), 41050);
  EXPECT_LE(std::abs(counts(*q)(1) - 33985), 1);
  // Horizontal long side: alpha = (atan(100 / 0.01) + atan(100 / 0.01)) / 2 as the code does.
  const double alpha_deg = rad_to_deg(std::atan(100.0 / 0.01));
  const double phi_horizontal = deg_to_rad(alpha_deg + j1_deg + j2_deg - 90.0 - angl_err_deg);
  const auto h =
      inverse(model_, target(134.39, 501.25, 227.7, phi_horizontal), ElbowBranch::kJ2Positive);
  ASSERT_THAT(h, IsOk());
  ScaraJoints folded = *h;
  folded(3) = geometry::fold_half_turn(folded(3));
  EXPECT_NEAR(rad_to_deg(folded(3)), 31.82, 0.005);
  EXPECT_EQ(counts(folded)(3), 7240);
}

TEST_F(Ibm7545Test, WorldReferencedRollDoesNotDependOnTheArm) {
  const double yaw = deg_to_rad(25.0);
  const auto a = inverse(model_, target(-250, 250, 200, yaw), ElbowBranch::kJ2Positive);
  const auto b = inverse(model_, target(300, 300, 200, yaw), ElbowBranch::kJ2Positive);
  ASSERT_THAT(a, IsOk());
  ASSERT_THAT(b, IsOk());
  EXPECT_GT(std::abs(((*a)(0) + (*a)(1)) - ((*b)(0) + (*b)(1))), 0.5);  // different arm poses
  EXPECT_NEAR((*a)(3), -yaw, 1e-12);
  EXPECT_NEAR((*b)(3), -yaw, 1e-12);
  EXPECT_NEAR(tool_yaw_from_roll(model_, 1.0, 2.0, -yaw), yaw, 1e-12);
}

TEST_F(Ibm7545Test, CartesianBoxOfTheCodeIsCheckedFirst) {
  EXPECT_THAT(inverse(model_, target(651.0, 0.0), ElbowBranch::kJ2Positive),
              IsErrWith(Errc::kOutOfRange,
                        "tool point x = 651.000 mm is outside cartesian_limits.x_mm "
                        "[-650.000, 650.000] mm"));
  EXPECT_THAT(inverse(model_, target(0.0, -400.0), ElbowBranch::kJ2Positive),
              IsErrWith(Errc::kOutOfRange, "y = -400.000 mm"));
}

TEST_F(Ibm7545Test, RejectsTargetBeyondReachAndSaysWhy) {
  const auto far = inverse(model_, target(600.0, 300.0), ElbowBranch::kJ2Positive);
  EXPECT_THAT(far, IsErrWith(Errc::kOutOfRange, "670.820 mm from the J1 axis"));
  EXPECT_THAT(far, IsErrWith(Errc::kOutOfRange, "[150.000, 650.000] mm"));
  EXPECT_THAT(inverse(model_, target(100.0, 0.0), ElbowBranch::kJ2Positive),
              IsErrWith(Errc::kOutOfRange, "100.000 mm from the J1 axis"));
}

TEST_F(Ibm7545Test, RejectsATiltedToolAxis) {
  Eigen::Isometry3d t = target(300, 300);
  t.rotate(Eigen::AngleAxisd(deg_to_rad(1.0), Eigen::Vector3d::UnitY()));
  EXPECT_THAT(inverse(model_, t, ElbowBranch::kJ2Positive),
              IsErrWith(Errc::kInvalidArgument, "tilted 1.000000 deg"));
}

TEST_F(Ibm7545Test, RejectsNonRigidTargets) {
  Eigen::Isometry3d t = target(300, 300);
  t.translation().x() = std::nan("");
  EXPECT_THAT(inverse_all(model_, t), IsErrWith(Errc::kInvalidArgument, "base_T_tool"));
}

// With J1 limited to [0, 200] deg and J2 to [0, 135] deg, a point at -30 deg bearing is out of
// the 7545's joint space on both branches: the error lists each branch and its joint.
TEST_F(Ibm7545Test, NamesTheJointWhenEveryBranchBreaksALimit) {
  const auto q = inverse(model_, target(367.0, -212.0), ScaraJoints::Zero());
  EXPECT_THAT(q, IsErrWith(Errc::kOutOfRange, "no IK branch is within the joint limits"));
  EXPECT_THAT(q, IsErrWith(Errc::kOutOfRange, "j2_positive: joint 'j1' = "));
  EXPECT_THAT(q, IsErrWith(Errc::kOutOfRange, "[0.000, 200.000] deg"));
  EXPECT_THAT(q, IsErrWith(Errc::kOutOfRange, "j2_negative: joint 'j2' = "));
  const auto named = inverse(model_, target(367.0, -212.0), ElbowBranch::kJ2Negative);
  EXPECT_THAT(named, IsErrWith(Errc::kOutOfRange, "branch j2_negative: joint 'j2'"));
}

// The code adds 2 pi to a negative J1 (digest 000 §5); limit fitting does the same.
TEST_F(Ibm7545Test, NegativeJ1IsUnwrappedIntoTheLimits) {
  const ScaraJoints q(deg_to_rad(190.0), deg_to_rad(60.0), 10.0, 0.2);
  const auto back = inverse(model_, forward(model_, q), ElbowBranch::kJ2Positive);
  ASSERT_THAT(back, IsOk());
  EXPECT_NEAR((*back)(0), q(0), 1e-9);
}

TEST_F(Ibm7545Test, BothBranchesReachTheSamePose) {
  const Eigen::Isometry3d t = target(-250.0, 310.0, 50.0, 0.3);
  const auto all = inverse_all(model_, t);
  ASSERT_THAT(all, IsOk());
  ASSERT_EQ(all->size(), 2u);
  EXPECT_EQ((*all)[0].branch, "j2_positive");
  EXPECT_GT((*all)[0].q(1), 0.0);
  EXPECT_TRUE((*all)[0].within_limits());
  EXPECT_EQ((*all)[1].branch, "j2_negative");
  EXPECT_LT(std::sin((*all)[1].q(1)), 0.0);
  EXPECT_EQ((*all)[1].violated_joint, 1);  // J2 < 0 is outside [0, 135] deg
  for (const IkSolution& s : *all) {
    EXPECT_THAT(forward(model_, ScaraJoints(s.q)), IsNearPose(t, kTolMm));
  }
}

// Calibration (thesis §4.4: link_1 and link_2 are +-1 mm): a model with other links is a new
// model; the shipped one is untouched.
TEST_F(Ibm7545Test, CalibratedLinksMakeANewModel) {
  ScaraModel calibrated = model_;
  calibrated.link1_mm = 400.8;
  calibrated.link2_mm = 249.5;
  auto robot = RobotModel::create("ibm7545", calibrated);
  ASSERT_THAT(robot, IsOk());
  const auto home = robot->forward(JointVector::Zero(4));
  ASSERT_THAT(home, IsOk());
  EXPECT_NEAR(home->translation().x(), 650.3, kTolMm);
  EXPECT_NEAR(forward(model_, ScaraJoints::Zero()).translation().x(), 650.0, kTolMm);
}

class PickerTest : public ::testing::Test {
 protected:
  void SetUp() override {
    auto robot = test::load_shipped("scara_picker");
    ASSERT_TRUE(robot) << robot.error().message;
    model_ = *robot->scara();
  }
  ScaraModel model_;
};

TEST_F(PickerTest, SharesTheScaraCodeWithItsOwnLinksAndLinkReferencedRoll) {
  EXPECT_NEAR(forward(model_, ScaraJoints::Zero()).translation().x(), 600.0, kTolMm);
  const ScaraJoints q(0.3, -0.9, 120.0, 0.4);
  const Eigen::Isometry3d t = forward(model_, q);
  const auto rz = geometry::from_3d(t);
  ASSERT_THAT(rz, IsOk());
  EXPECT_NEAR(rz->rz, 0.3 - 0.9 + 0.4, 1e-12);  // yaw = J1 + J2 + R
  EXPECT_NEAR(t.translation().z(), -120.0, kTolMm);
}

TEST_F(PickerTest, NearestBranchFollowsTheSeed) {
  const ScaraJoints q(0.3, -0.9, 120.0, 0.4);
  const Eigen::Isometry3d t = forward(model_, q);
  const auto near_negative = inverse(model_, t, ScaraJoints(0.2, -1.0, 100.0, 0.0));
  ASSERT_THAT(near_negative, IsOk());
  EXPECT_TRUE(near_negative->isApprox(q, 1e-9));
  const auto near_positive = inverse(model_, t, ScaraJoints(-0.5, 1.0, 100.0, 0.0));
  ASSERT_THAT(near_positive, IsOk());
  EXPECT_GT((*near_positive)(1), 0.0);
  EXPECT_THAT(forward(model_, *near_positive), IsNearPose(t, kTolMm));
}

// The R joint spans +-360 deg on the picker: the solution closest to the seed is chosen.
TEST_F(PickerTest, RollIsUnwrappedTowardTheSeed) {
  const ScaraJoints q(0.3, -0.9, 120.0, deg_to_rad(300.0));
  const auto back = inverse(model_, forward(model_, q), ElbowBranch::kJ2Negative,
                            ScaraJoints(0.3, -0.9, 120.0, deg_to_rad(290.0)));
  ASSERT_THAT(back, IsOk());
  EXPECT_NEAR(rad_to_deg((*back)(3)), 300.0, 1e-9);
  const auto wrapped = inverse(model_, forward(model_, q), ElbowBranch::kJ2Negative);
  ASSERT_THAT(wrapped, IsOk());
  EXPECT_NEAR(rad_to_deg((*wrapped)(3)), -60.0, 1e-9);
}

TEST_F(PickerTest, ToolOffsetIsAppliedAndInvertedAtTheFlange) {
  ScaraModel with_tool = model_;
  with_tool.flange_T_tool = geometry::make_pose({40.0, 0.0, -80.0}, {.roll = geometry::kPi});
  const ScaraJoints q(0.3, -0.9, 120.0, 0.4);
  const Eigen::Isometry3d t = forward(with_tool, q);
  EXPECT_THAT(t, IsNearPose(forward(model_, q) * with_tool.flange_T_tool, kTolMm));
  const auto back = inverse(with_tool, t, ElbowBranch::kJ2Negative);
  ASSERT_THAT(back, IsOk());  // the tool z points down; the flange is still vertical
  EXPECT_TRUE(back->isApprox(q, 1e-9));
}

// Links 300/300 let the R axis reach the J1 axis, where J1 is free: no NaN, reference J1 kept.
TEST(ScaraSingular, TargetOnTheJ1AxisKeepsTheReferenceJ1) {
  ScaraModel m;
  m.link1_mm = 300.0;
  m.link2_mm = 300.0;
  m.joints[0] = {"j1", JointType::kRevolute, -3.0, 3.0, 1.0, 4.0};
  m.joints[1] = {"j2", JointType::kRevolute, -3.2, 3.2, 1.0, 4.0};
  m.joints[2] = {"z", JointType::kPrismatic, -100.0, 100.0, 100.0, 400.0};
  m.joints[3] = {"r", JointType::kRevolute, -3.2, 3.2, 1.0, 4.0};
  ASSERT_THAT(m.validate(), IsOk());
  const Eigen::Isometry3d on_axis = geometry::to_3d({0.0, 0.0, 0.5}, 10.0);
  const auto all = inverse_all(m, on_axis, ScaraJoints(0.7, 3.0, 0.0, 0.0));
  ASSERT_THAT(all, IsOk());
  for (const IkSolution& s : *all) {
    EXPECT_TRUE(s.q.allFinite());
    EXPECT_TRUE(s.singular);
    EXPECT_NEAR(s.q(0), 0.7, 1e-12);
    EXPECT_THAT(forward(m, ScaraJoints(s.q)), IsNearPose(on_axis, kTolMm));
  }
}

}  // namespace
}  // namespace cell::kinematics
