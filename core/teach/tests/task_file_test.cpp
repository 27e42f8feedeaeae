#include "cell/teach/task_file.hpp"

#include <unistd.h>

#include <cstdio>
#include <filesystem>
#include <fstream>
#include <numbers>

#include <fmt/format.h>
#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include "cell/kinematics/robot_config.hpp"
#include "cell/testing/env.hpp"
#include "cell/testing/matchers.hpp"
#include "teach_test_support.hpp"

namespace cell::teach {
namespace {

using ::cell::testing::IsErr;
using ::cell::testing::IsErrWith;
using ::cell::testing::IsOk;
using ::testing::HasSubstr;

using test::deg;
using test::ibm7545;
using test::kTolMm;
using test::kTolRad;
using test::lookup;
using test::q7545;

Task two_poses() {
  Task task;
  task.name = "demo";
  task.robot_id = "ibm7545";
  PoseStep a;
  a.name = "grab";
  a.joints = q7545(45, 105, 0, 0);
  PoseStep b;
  b.name = "above";
  b.joints = q7545(41.2, 98.7, 150, 30);
  b.move = MoveKind::kLine;
  b.speed_scale = 0.3;
  EXPECT_THAT(task.append(a), IsOk());
  EXPECT_THAT(task.append(GripperStep{GripperAction::kClose}), IsOk());
  EXPECT_THAT(task.append(b), IsOk());
  EXPECT_THAT(task.append(WaitStep{0.5}), IsOk());
  return task;
}

Result<Task> parse(const std::string& yaml) {
  auto doc = config::load_string(yaml, "task.yaml");
  if (!doc) {
    return std::move(doc).error();
  }
  return parse_task(*doc, lookup());
}

TEST(TaskFile, RoundTripsThroughYamlExactlyToSixDecimals) {
  const auto model = ibm7545();
  const Task task = two_poses();
  auto yaml = to_yaml(task, model);
  ASSERT_TRUE(yaml) << yaml.error().message;
  EXPECT_THAT(*yaml, HasSubstr("joints: {j1_deg: 45.000000, j2_deg: 105.000000, z_mm: 0.000000"));
  EXPECT_THAT(*yaml, HasSubstr("- gripper: close"));
  EXPECT_THAT(*yaml, HasSubstr("move: line"));
  auto back = parse(*yaml);
  ASSERT_TRUE(back) << back.error().message << "\n" << *yaml;
  ASSERT_EQ(back->steps.size(), 4U);
  EXPECT_EQ(back->name, "demo");
  const auto& b = std::get<PoseStep>(back->steps[2]);
  EXPECT_EQ(b.name, "above");
  EXPECT_EQ(b.move, MoveKind::kLine);
  EXPECT_DOUBLE_EQ(b.speed_scale, 0.3);
  const auto& expected = std::get<PoseStep>(task.steps[2]).joints;
  for (int k = 0; k < 4; ++k) {
    EXPECT_NEAR(b.joints[k], expected[k], 1e-6) << k;  // six decimals of deg / mm
  }
  EXPECT_EQ(std::get<GripperStep>(back->steps[1]).action, GripperAction::kClose);
  EXPECT_DOUBLE_EQ(std::get<WaitStep>(back->steps[3]).duration_s, 0.5);
}

TEST(TaskFile, WritesTheToolPoseFromForwardKinematics) {
  // J1 45 deg, J2 105 deg: 400 (cos 45, sin 45) + 250 (cos 150, sin 150) = (66.336, 407.843)
  // mm (digest 000 §9.2 case 2 rounds it to (66.37, 407.88)).
  const auto model = ibm7545();
  Task task;
  task.name = "grab";
  task.robot_id = "ibm7545";
  PoseStep p;
  p.name = "grab";
  p.joints = q7545(45, 105, 0, 0);
  ASSERT_THAT(task.append(p), IsOk());
  auto yaml = to_yaml(task, model);
  ASSERT_TRUE(yaml);
  EXPECT_THAT(*yaml, HasSubstr("xyz_mm: [66.336362, 407.842712, 0.000000]"));
}

TEST(TaskFile, NamesQuotedTextSurvivesTheRoundTrip) {
  const auto model = ibm7545();
  Task task = two_poses();
  task.name = "pick \"ic8\": then\\place";
  task.description = "line one\nline two";
  auto yaml = to_yaml(task, model);
  ASSERT_TRUE(yaml);
  auto back = parse(*yaml);
  ASSERT_TRUE(back) << back.error().message;
  EXPECT_EQ(back->name, task.name);
  EXPECT_EQ(back->description, task.description);
}

TEST(TaskFile, ReportsEveryProblemWithItsLocation) {
  auto t = parse(
      "task: bad\n"
      "robot: ibm7545\n"
      "speed_scale: 2\n"
      "steps:\n"
      "  - pose: a\n"
      "    joints: {j1_deg: 45, j2_deg: 105, z_mm: 0, r_mm: 0}\n"
      "  - gripper: squeeze\n"
      "  - pose: a\n"
      "    joints: {j1_deg: 45, j2_deg: 170, z_mm: 0, r_deg: 0}\n"
      "  - wait_s: -1\n"
      "  - {pose: c, gripper: open}\n"
      "  - pose: d\n"
      "    colour: red\n"
      "    joints: {j1_deg: 45, j2_deg: 105, z_mm: 0, r_deg: 0}\n");
  ASSERT_FALSE(t);
  EXPECT_EQ(t.error().code, Errc::kConfig);
  const std::string& m = t.error().message;
  EXPECT_THAT(m, HasSubstr("task.yaml:3:"));
  EXPECT_THAT(m, HasSubstr("speed_scale"));
  EXPECT_THAT(m, HasSubstr("r_deg"));            // missing joint key
  EXPECT_THAT(m, HasSubstr("r_mm"));             // unknown key (wrong unit)
  EXPECT_THAT(m, HasSubstr("squeeze"));
  EXPECT_THAT(m, HasSubstr("used twice"));
  EXPECT_THAT(m, HasSubstr("'j2' = 170.000 deg is outside its limits"));
  EXPECT_THAT(m, HasSubstr("wait_s"));
  EXPECT_THAT(m, HasSubstr("exactly one of pose, gripper, wait_s"));
  EXPECT_THAT(m, HasSubstr("colour"));
  EXPECT_THAT(m, HasSubstr("task.yaml:13:"));
}

TEST(TaskFile, RefusesAToolPoseThatDisagreesWithTheJoints) {
  auto t = parse(
      "task: t\nrobot: ibm7545\nsteps:\n"
      "  - pose: a\n"
      "    joints: {j1_deg: 45, j2_deg: 105, z_mm: 0, r_deg: 0}\n"
      "    tool: {xyz_mm: [70.0, 407.88, 0], rpy_deg: [0, 0, 0]}\n");
  ASSERT_FALSE(t);
  EXPECT_THAT(t.error().message, HasSubstr("disagrees with the joints' forward kinematics"));
  EXPECT_THAT(t.error().message, HasSubstr("task.yaml:6:"));
}

TEST(TaskFile, UnknownRobotIsReportedAtTheRobotKey) {
  auto t = parse("task: t\nrobot: puma560\nsteps: []\n");
  ASSERT_FALSE(t);
  EXPECT_THAT(t.error().message, HasSubstr("task.yaml:2:"));
  EXPECT_THAT(t.error().message, HasSubstr("cannot load robot 'puma560'"));
}

TEST(TaskFile, RefusesNonYamlAndNonMaps) {
  EXPECT_THAT(parse("task: [unclosed\n"), IsErr(Errc::kConfig));
  EXPECT_THAT(parse("- just\n- a list\n"), IsErr(Errc::kConfig));
  EXPECT_THAT(parse("task: t\nrobot: ibm7545\nsteps: [3, 4]\n"),
              IsErrWith(Errc::kConfig, "expected a map"));
}

TEST(TaskEdit, InsertRemoveMoveRenameKeepOrderAndRefuseBadIndices) {
  Task task = two_poses();  // grab, close, above, wait
  EXPECT_THAT(task.move(2, 0), IsOk());  // above, grab, close, wait
  EXPECT_EQ(std::get<PoseStep>(task.steps[0]).name, "above");
  EXPECT_EQ(std::get<PoseStep>(task.steps[1]).name, "grab");
  EXPECT_THAT(task.remove(2), IsOk());  // above, grab, wait
  ASSERT_EQ(task.steps.size(), 3U);
  EXPECT_TRUE(std::holds_alternative<WaitStep>(task.steps[2]));
  EXPECT_THAT(task.insert(1, GripperStep{GripperAction::kOpen}), IsOk());
  EXPECT_TRUE(std::holds_alternative<GripperStep>(task.steps[1]));
  EXPECT_THAT(task.rename(0, "top"), IsOk());
  EXPECT_EQ(task.find("top"), 0U);
  EXPECT_THAT(task.rename(0, "grab"), IsErrWith(Errc::kInvalidArgument, "exists already"));
  EXPECT_THAT(task.rename(1, "x"), IsErrWith(Errc::kInvalidArgument, "not a pose"));
  EXPECT_THAT(task.remove(9), IsErrWith(Errc::kOutOfRange, "step 10 is out of range"));
  EXPECT_THAT(task.move(0, 4), IsErr(Errc::kOutOfRange));
  EXPECT_THAT(task.insert(6, WaitStep{1}), IsErr(Errc::kOutOfRange));
  PoseStep dup;
  dup.name = "grab";
  dup.joints = q7545(45, 105, 0, 0);
  EXPECT_THAT(task.append(dup), IsErrWith(Errc::kInvalidArgument, "exists already"));
  EXPECT_EQ(task.steps.size(), 4U);  // nothing accepted was lost
}

TEST(TaskRecord, RecordsJointsWithAFreshNameAndRefusesOutsideLimits) {
  const auto model = ibm7545();
  Task task = two_poses();
  auto p = record_pose(task, model, q7545(30, 60, 10, 5));
  ASSERT_TRUE(p) << p.error().message;
  EXPECT_EQ(p->name, "p3");
  EXPECT_NEAR(p->joints[2], 10.0, kTolMm);
  EXPECT_NEAR(p->joints[0], deg(30), kTolRad);
  EXPECT_THAT(record_pose(task, model, q7545(30, 140, 0, 0)),
              IsErrWith(Errc::kOutOfRange, "'j2'"));
  EXPECT_THAT(record_pose(task, model, q7545(30, 60, 0, 0), "grab"),
              IsErrWith(Errc::kInvalidArgument, "exists already"));
  kinematics::JointVector short_q(3);
  short_q << 0, 0, 0;
  EXPECT_THAT(record_pose(task, model, short_q), IsErr(Errc::kInvalidArgument));
}

TEST(TaskFile, SavesAtomicallyAndLoadsBack) {
  const auto model = ibm7545();
  const std::string dir = ::testing::TempDir() + "/teach-" + std::to_string(getpid());
  std::filesystem::create_directories(dir);
  const std::string path = dir + "/t.yaml";
  ASSERT_THAT(save_task(path, two_poses(), model), IsOk());
  EXPECT_FALSE(std::filesystem::exists(path + ".tmp"));
  kinematics::RobotModel loaded_model = ibm7545();
  auto back = load_task(path, lookup(), &loaded_model);
  ASSERT_TRUE(back) << back.error().message;
  EXPECT_EQ(back->steps.size(), 4U);
  EXPECT_EQ(loaded_model.id(), "ibm7545");
  EXPECT_THAT(save_task(dir + "/missing/dir/t.yaml", two_poses(), model),
              IsErrWith(Errc::kIo, "cannot write"));
  std::filesystem::remove_all(dir);
}

TEST(TaskFile, TheShippedExampleLoads) {
  auto t = load_task(cell::testing::source_dir() + "/config/tasks/ibm7545_demo.yaml", lookup());
  ASSERT_TRUE(t) << t.error().message;
  EXPECT_EQ(t->robot_id, "ibm7545");
  EXPECT_GE(t->pose_count(), 3U);
}

// Digest 001 §8.2 case 18: 800 samples (80 s at 10 Hz) fit 24 KB in the controller; our
// human-readable file is larger per sample but must stay reasonable (under 250 bytes each).
TEST(TaskFile, EightHundredSamplesStayCompact) {
  const auto model = ibm7545();
  Task task;
  task.name = "long";
  task.robot_id = "ibm7545";
  for (int i = 0; i < 800; ++i) {
    auto p = record_pose(task, model, q7545(10 + i * 0.2, 20 + i * 0.1, i * 0.25, i * 0.3 - 120));
    ASSERT_TRUE(p) << p.error().message;
    ASSERT_THAT(task.append(*p), IsOk());
  }
  auto yaml = to_yaml(task, model);
  ASSERT_TRUE(yaml);
  EXPECT_LT(yaml->size(), 800U * 250U);
  auto back = parse(*yaml);
  ASSERT_TRUE(back) << back.error().message;
  EXPECT_EQ(back->steps.size(), 800U);
}

}  // namespace
}  // namespace cell::teach
