#include "cell/kinematics/robot_model.hpp"

#include <cmath>

#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include "cell/geometry/angles.hpp"
#include "cell/geometry/pose2.hpp"
#include "cell/testing/matchers.hpp"
#include "cell/testing/tolerances.hpp"
#include "support/test_robots.hpp"

namespace cell::kinematics {
namespace {

using ::cell::testing::IsErr;
using ::cell::testing::IsErrWith;
using ::cell::testing::IsNearPose;
using ::cell::testing::IsOk;
using geometry::deg_to_rad;
using ::testing::ElementsAre;

using ::cell::testing::kTolMm;

TEST(RobotModel, ExposesKindDofJointsAndBranches) {
  const auto scara = test::load_shipped("ibm7545");
  ASSERT_THAT(scara, IsOk());
  EXPECT_EQ(scara->id(), "ibm7545");
  EXPECT_EQ(scara->kind(), RobotKind::kScara);
  EXPECT_EQ(scara->dof(), 4);
  EXPECT_EQ(scara->joints()[2].name, "z");
  EXPECT_EQ(scara->joints()[2].type, JointType::kPrismatic);
  EXPECT_NEAR(scara->joints()[0].max_speed, deg_to_rad(45.0), 1e-15);
  EXPECT_THAT(scara->branch_names(), ElementsAre("j2_positive", "j2_negative"));
  EXPECT_NE(scara->scara(), nullptr);
  EXPECT_EQ(scara->excalibur(), nullptr);

  const auto arm = test::load_shipped("excalibur");
  ASSERT_THAT(arm, IsOk());
  EXPECT_EQ(arm->kind(), RobotKind::kExcalibur);
  EXPECT_EQ(arm->dof(), 6);
  EXPECT_EQ(arm->branch_names().size(), 8u);
  EXPECT_EQ(arm->joints()[5].name, "theta6");
  EXPECT_TRUE(arm->cartesian_limits().base_guard.has_value());
}

TEST(RobotModel, ForwardChecksTheJointVector) {
  const auto robot = test::load_shipped("excalibur");
  ASSERT_THAT(robot, IsOk());
  EXPECT_THAT(robot->forward(JointVector::Zero(4)),
              IsErrWith(Errc::kInvalidArgument, "joint vector has 4 entries, robot has 6 joints"));
  JointVector q = JointVector::Zero(6);
  q(4) = INFINITY;
  EXPECT_THAT(robot->forward(q), IsErrWith(Errc::kInvalidArgument, "joint 'theta5' is not finite"));
  const auto home = robot->forward(JointVector::Zero(6));
  ASSERT_THAT(home, IsOk());
  EXPECT_NEAR(home->translation().z(), 711.2, kTolMm);
}

TEST(RobotModel, InverseNearestAndByNameAgreeWithTheKindSpecificSolvers) {
  const auto robot = test::load_shipped("excalibur");
  ASSERT_THAT(robot, IsOk());
  JointVector q(6);
  q << 0.5, 1.0, -2.0, 0.3, -0.7, 0.2;
  const auto pose = robot->forward(q);
  ASSERT_THAT(pose, IsOk());
  const auto nearest = robot->inverse(*pose, q);
  ASSERT_THAT(nearest, IsOk());
  EXPECT_TRUE(nearest->isApprox(q, 1e-9));
  const auto named = robot->inverse(*pose, "shoulder_back/elbow_down/wrist_noflip", q);
  ASSERT_THAT(named, IsOk());
  EXPECT_THAT(*robot->forward(*named), IsNearPose(*pose, kTolMm));
  EXPECT_THAT(robot->inverse(*pose, "j2_positive", q), IsErr(Errc::kInvalidArgument));
  EXPECT_THAT(robot->inverse(*pose, JointVector::Zero(4)),
              IsErrWith(Errc::kInvalidArgument, "joint vector has 4 entries"));
}

TEST(RobotModel, ScaraThroughTheGenericInterface) {
  const auto robot = test::load_shipped("ibm7545");
  ASSERT_THAT(robot, IsOk());
  const Eigen::Isometry3d target = geometry::to_3d({-250.0, 250.0, 0.0}, -200.0);
  const auto all = robot->inverse_all(target);
  ASSERT_THAT(all, IsOk());
  EXPECT_EQ(all->size(), 2u);
  const auto q = robot->inverse(target, JointVector::Zero(4));
  ASSERT_THAT(q, IsOk());
  const auto counts = robot->to_counts(*q);
  ASSERT_THAT(counts, IsOk());
  EXPECT_EQ((*counts)(0), 84496);
  EXPECT_EQ((*counts)(1), 52967);
  const auto back = robot->from_counts(*counts);
  ASSERT_THAT(back, IsOk());
  EXPECT_THAT(robot->check_limits(*back), IsOk());
  JointVector over = *back;
  over(1) = deg_to_rad(136.0);
  EXPECT_THAT(robot->check_limits(over), IsErrWith(Errc::kOutOfRange, "joint 'j2' = 136.000 deg"));
}

TEST(RobotModel, ExcaliburHasNoEncoderScales) {
  const auto robot = test::load_shipped("excalibur");
  ASSERT_THAT(robot, IsOk());
  EXPECT_THAT(robot->to_counts(JointVector::Zero(6)),
              IsErrWith(Errc::kInvalidArgument, "joint 'theta1' has no encoder scale"));
}

TEST(RobotModel, CreateValidatesTheModel) {
  ScaraModel m;
  m.link1_mm = 400.0;
  m.link2_mm = -250.0;
  m.joints[0] = {"j1", JointType::kRevolute, 0.0, 3.0, 1.0, 4.0};
  m.joints[1] = {"j2", JointType::kRevolute, 0.0, 2.0, 1.0, 4.0};
  m.joints[2] = {"z", JointType::kPrismatic, 0.0, 250.0, 100.0, 400.0};
  m.joints[3] = {"r", JointType::kRevolute, -3.0, 3.0, 0.0, 4.0};
  const auto robot = RobotModel::create("broken", m);
  EXPECT_THAT(robot, IsErrWith(Errc::kConfig, "robot 'broken': "));
  EXPECT_THAT(robot, IsErrWith(Errc::kConfig, "key 'scara.link2_mm': must be > 0, got -250"));
  EXPECT_THAT(robot,
              IsErrWith(Errc::kConfig, "key 'joints[3].max_speed_deg_s': must be > 0, got 0"));
  EXPECT_THAT(RobotModel::create("", ExcaliburModel{}), IsErr(Errc::kInvalidArgument));
}

}  // namespace
}  // namespace cell::kinematics
