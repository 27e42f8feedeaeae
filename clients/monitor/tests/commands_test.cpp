#include "commands.hpp"

#include <numbers>

#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include "cell/kinematics/robot_config.hpp"
#include "cell/testing/env.hpp"
#include "cell/testing/matchers.hpp"
#include "monitor_test_robots.hpp"

namespace cell::monitor {
namespace {

using ::cell::testing::IsErr;
using ::cell::testing::IsErrWith;
using ::cell::testing::IsNearPose;
using nlohmann::json;

constexpr double kTolMm = 1e-9;

double deg(double d) { return d * std::numbers::pi / 180.0; }

using test::robot;

RobotSample sample_at(const kinematics::RobotModel& model, std::vector<double> q) {
  RobotSample s;
  s.robot_id = model.id();
  s.q = q;
  kinematics::JointVector v(static_cast<Eigen::Index>(q.size()));
  for (std::size_t i = 0; i < q.size(); ++i) {
    v[static_cast<Eigen::Index>(i)] = q[i];
  }
  s.base_T_tool = model.forward(v).value();
  s.pose_valid = true;
  return s;
}

TEST(ParseMotion, JointsInDisplayUnitsAreCheckedAgainstLimits) {
  const auto m = robot("ibm7545");
  auto cmd = parse_motion(json{{"robot", "ibm7545"}, {"joints", {45, 105, 10, -30}},
                               {"speed", 0.25}, {"preview", true}},
                          m, nullptr);
  ASSERT_TRUE(cmd) << cmd.error().message;
  EXPECT_EQ(cmd->kind, cell_motion_MOTION_MOVE_JOINTS);
  EXPECT_NEAR(cmd->joints[0], deg(45), 1e-12);
  EXPECT_NEAR(cmd->joints[2], 10.0, 1e-12);  // mm stay mm
  EXPECT_DOUBLE_EQ(cmd->speed_scale, 0.25);
  EXPECT_TRUE(cmd->preview);
  EXPECT_THAT(parse_motion(json{{"joints", {45, 150, 0, 0}}}, m, nullptr),
              IsErrWith(Errc::kOutOfRange, "'j2' = 150.000 deg is outside its limits"));
  EXPECT_THAT(parse_motion(json{{"joints", {45, 105, 0}}}, m, nullptr),
              IsErrWith(Errc::kInvalidArgument, "list of 4 numbers"));
  EXPECT_THAT(parse_motion(json{{"joints", {45, "x", 0, 0}}}, m, nullptr),
              IsErrWith(Errc::kInvalidArgument, "joints[1]"));
}

TEST(ParseMotion, RefusesMalformedRequestsNamingTheField) {
  const auto m = robot("ibm7545");
  EXPECT_THAT(parse_motion(json::array(), m, nullptr), IsErr(Errc::kInvalidArgument));
  EXPECT_THAT(parse_motion(json{{"robot", "ibm7545"}}, m, nullptr),
              IsErrWith(Errc::kInvalidArgument, "exactly one of"));
  EXPECT_THAT(parse_motion(json{{"joints", {1, 1, 1, 1}}, {"stop", true}}, m, nullptr),
              IsErrWith(Errc::kInvalidArgument, "exactly one of"));
  EXPECT_THAT(parse_motion(json{{"stop", true}, {"speed", 7}}, m, nullptr),
              IsErrWith(Errc::kOutOfRange, "'speed'"));
  EXPECT_THAT(parse_motion(json{{"stop", true}, {"preview", "yes"}}, m, nullptr),
              IsErrWith(Errc::kInvalidArgument, "'preview'"));
  EXPECT_THAT(parse_motion(json{{"pose", {{"xyz_mm", {1, 2}}}}}, m, nullptr),
              IsErrWith(Errc::kInvalidArgument, "xyz_mm"));
  EXPECT_THAT(parse_motion(json{{"jog", {{"space", "joint"}, {"joint", "j9"}, {"delta", 1}}}}, m,
                           nullptr),
              IsErrWith(Errc::kNotReady, "no state from robot"));
}

TEST(ParseMotion, JointJogStartsFromTheLatestState) {
  const auto m = robot("ibm7545");
  const auto now = sample_at(m, {deg(45), deg(105), 0, 0});
  auto cmd = parse_motion(json{{"jog", {{"space", "joint"}, {"joint", "z"}, {"delta", 5}}}}, m,
                          &now);
  ASSERT_TRUE(cmd) << cmd.error().message;
  EXPECT_NEAR(cmd->joints[2], 5.0, 1e-12);
  EXPECT_NEAR(cmd->joints[1], deg(105), 1e-12);
  EXPECT_EQ(cmd->what, "jog z +5 mm");
  EXPECT_THAT(parse_motion(json{{"jog", {{"space", "joint"}, {"joint", 1}, {"delta", 40}}}}, m,
                           &now),
              IsErrWith(Errc::kOutOfRange, "'j2'"));
  EXPECT_THAT(parse_motion(json{{"jog", {{"space", "joint"}, {"joint", 7}, {"delta", 1}}}}, m,
                           &now),
              IsErrWith(Errc::kInvalidArgument, "'joint'"));
}

TEST(ParseMotion, CartesianJogInBaseAndToolFrames) {
  const auto m = robot("excalibur");
  const auto now = sample_at(m, {deg(30), deg(45), deg(-120), deg(20), deg(-40), deg(60)});
  auto base = parse_motion(json{{"jog", {{"space", "base"}, {"axis", "x"}, {"delta", 10}}}}, m, &now);
  ASSERT_TRUE(base);
  EXPECT_EQ(base->kind, cell_motion_MOTION_MOVE_LINEAR);
  Eigen::Isometry3d expected = now.base_T_tool;
  expected.translation().x() += 10.0;
  EXPECT_THAT(base->target, IsNearPose(expected, kTolMm));
  // Digest 001 §8.2 case 11: +20 mm along the tool's a (z) axis moves p by 20 a.
  auto tool = parse_motion(json{{"jog", {{"space", "tool"}, {"axis", "z"}, {"delta", 20}}}}, m, &now);
  ASSERT_TRUE(tool);
  const Eigen::Vector3d a = now.base_T_tool.linear().col(2);
  EXPECT_NEAR((tool->target.translation() - now.base_T_tool.translation() - 20.0 * a).norm(), 0,
              kTolMm);
  EXPECT_TRUE(tool->target.linear().isApprox(now.base_T_tool.linear(), 1e-12));
  auto rz = parse_motion(json{{"jog", {{"space", "base"}, {"axis", "rz"}, {"delta", 90}}}}, m, &now);
  ASSERT_TRUE(rz);
  EXPECT_NEAR((rz->target.translation() - now.base_T_tool.translation()).norm(), 0, kTolMm);
  EXPECT_THAT(parse_motion(json{{"jog", {{"space", "world"}, {"axis", "x"}, {"delta", 1}}}}, m, &now),
              IsErrWith(Errc::kInvalidArgument, "joint, base or tool"));
  EXPECT_THAT(parse_motion(json{{"jog", {{"space", "base"}, {"axis", "w"}, {"delta", 1}}}}, m, &now),
              IsErrWith(Errc::kInvalidArgument, "'axis'"));
}

TEST(ParseRobotCommand, KnowsTheCommandsAndRobots) {
  auto spec = parse_robot_command(json{{"robot", "ibm7545"}, {"command", "close"}}, {"ibm7545"});
  ASSERT_TRUE(spec);
  EXPECT_EQ(spec->kind, cell_robot_CMD_GRIPPER_CLOSE);
  EXPECT_THAT(parse_robot_command(json{{"robot", "r2d2"}, {"command", "home"}}, {"ibm7545"}),
              IsErrWith(Errc::kInvalidArgument, "unknown robot 'r2d2'"));
  EXPECT_THAT(parse_robot_command(json{{"robot", "ibm7545"}, {"command", "dance"}}, {"ibm7545"}),
              IsErrWith(Errc::kInvalidArgument, "home, open, close, stop or reset"));
  EXPECT_THAT(parse_robot_command(json{{"robot", 3}}, {"ibm7545"}),
              IsErrWith(Errc::kInvalidArgument, "must be a string"));
}

TEST(ParseJob, SubmitFromATemplateAndCommands) {
  std::vector<JobTemplate> templates(1);
  templates[0].name = "table";
  templates[0].kind = "table_pick_place";
  auto spec = parse_job_submit(json{{"template", "table"}}, templates, 1234);
  ASSERT_TRUE(spec);
  EXPECT_EQ(spec->job_id, "table-1234");
  EXPECT_EQ(spec->kind, cell_task_JOB_TABLE_PICK_PLACE);
  EXPECT_EQ(parse_job_submit(json{{"template", "table"}, {"job_id", "j-1"}}, templates, 0)->job_id,
            "j-1");
  EXPECT_THAT(parse_job_submit(json{{"template", "table"}, {"job_id", "../etc"}}, templates, 0),
              IsErrWith(Errc::kInvalidArgument, "job_id"));
  EXPECT_THAT(parse_job_submit(json{{"template", "nope"}}, templates, 0),
              IsErrWith(Errc::kInvalidArgument, "known: table"));
  auto cmd = parse_job_command(json{{"job_id", "j-1"}, {"command", "pause"}});
  ASSERT_TRUE(cmd);
  EXPECT_EQ(cmd->kind, cell_task_JOB_PAUSE);
  EXPECT_THAT(parse_job_command(json{{"job_id", "j-1"}, {"command", "explode"}}),
              IsErr(Errc::kInvalidArgument));
}

TEST(GraspToolPose, TurnsTheToolAxisToHowTheRobotReaches) {
  const Eigen::Isometry3d world_T_base(Eigen::Translation3d(0, 0, 981.51));
  Eigen::Isometry3d world_T_grasp = Eigen::Isometry3d::Identity();
  world_T_grasp.translation() << 134.39, 501.25, 753.81;
  world_T_grasp.linear() = Eigen::AngleAxisd(0.4, Eigen::Vector3d::UnitZ()).toRotationMatrix();
  auto scara = grasp_tool_pose(robot("ibm7545"), world_T_base, world_T_grasp);
  ASSERT_TRUE(scara);
  EXPECT_NEAR(scara->translation().z(), 753.81 - 981.51, 1e-9);
  EXPECT_GT(scara->linear()(2, 2), 0.99);  // z up, as the SCARA's tool
  auto arm = grasp_tool_pose(robot("excalibur"), world_T_base, world_T_grasp);
  ASSERT_TRUE(arm);
  EXPECT_LT(arm->linear()(2, 2), -0.99);  // approach vector down into the part
  EXPECT_NEAR((arm->translation() - scara->translation()).norm(), 0, 1e-9);
}

TEST(SafeName, AcceptsIdsAndRefusesPaths) {
  EXPECT_TRUE(safe_name("demo_1.yaml"));
  for (const char* bad : {"", ".", "..", "a/b", "../x", "a b", "x\n"}) {
    EXPECT_FALSE(safe_name(bad)) << bad;
  }
  EXPECT_FALSE(safe_name(std::string(65, 'a')));
}

}  // namespace
}  // namespace cell::monitor
