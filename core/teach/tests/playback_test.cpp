#include "cell/teach/playback.hpp"

#include <numbers>

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
using ::cell::testing::IsNearPose;
using ::cell::testing::IsOk;
using ::testing::HasSubstr;

using test::deg;
using test::ibm7545;
using test::kTolMm;
using test::kTolRad;
using test::q7545;

/// p1, close, p2 (line), wait 0.2, p3, open
Task task3() {
  Task task;
  task.name = "t";
  task.robot_id = "ibm7545";
  auto pose = [](const char* name, const kinematics::JointVector& q,
                 MoveKind move = MoveKind::kJoint) {
    PoseStep p;
    p.name = name;
    p.joints = q;
    p.move = move;
    return p;
  };
  EXPECT_THAT(task.append(pose("p1", q7545(45, 105, 0, 0))), IsOk());
  EXPECT_THAT(task.append(GripperStep{GripperAction::kClose}), IsOk());
  EXPECT_THAT(task.append(pose("p2", q7545(50, 100, 100, 10), MoveKind::kLine)), IsOk());
  EXPECT_THAT(task.append(WaitStep{0.2}), IsOk());
  EXPECT_THAT(task.append(pose("p3", q7545(30, 80, 50, -20))), IsOk());
  EXPECT_THAT(task.append(GripperStep{GripperAction::kOpen}), IsOk());
  return task;
}

/// Records what it is asked to do; fails on the `fail_at`-th action.
class FakeRunner final : public StepRunner {
 public:
  Result<StepOutcome> run(const Action& action) override {
    actions.push_back(action);
    if (fail_at && actions.size() == *fail_at) {
      return Error{Errc::kOutOfRange, "refused: joint 'j2' beyond its limit"};
    }
    StepOutcome out;
    out.duration_s = 1.0;
    if (action.kind == Action::Kind::kMove) {
      out.final_joints = action.joints;
    }
    return out;
  }
  std::vector<Action> actions;
  std::optional<std::size_t> fail_at;
};

TEST(Playback, ForwardTakesEveryStepAsRecorded) {
  const auto model = ibm7545();
  FakeRunner runner;
  auto report = play(task3(), model, runner, {});
  ASSERT_TRUE(report) << report.error().message;
  EXPECT_TRUE(report->ok()) << report->brief();
  EXPECT_EQ(report->steps_done, 6U);
  ASSERT_EQ(runner.actions.size(), 6U);  // every step forward is an action (none is kNone)
  EXPECT_EQ(runner.actions[0].kind, Action::Kind::kMove);
  EXPECT_EQ(runner.actions[1].kind, Action::Kind::kGripper);
  EXPECT_EQ(runner.actions[1].gripper, GripperAction::kClose);
  EXPECT_EQ(runner.actions[2].move, MoveKind::kLine);
  EXPECT_THAT(runner.actions[2].base_T_tool,
              IsNearPose(model.forward(q7545(50, 100, 100, 10)).value(), kTolMm));
  EXPECT_DOUBLE_EQ(runner.actions[2].speed_scale, 0.5);  // the task's default
  EXPECT_EQ(runner.actions[3].kind, Action::Kind::kWait);
  EXPECT_EQ(report->final_joints.value(), q7545(30, 80, 50, -20));
  EXPECT_EQ(report->brief(), "6/6 steps in 6.00 s");
}

TEST(Playback, BackwardUndoesEachStep) {
  const auto model = ibm7545();
  FakeRunner runner;
  PlaybackOptions options;
  options.direction = Direction::kBackward;
  auto report = play(task3(), model, runner, options);
  ASSERT_TRUE(report) << report.error().message;
  // Undo open -> close; undo p3 -> back to p2; wait -> nothing; undo p2 -> back to p1 (by a
  // line, as p2 came); undo close -> open; undo p1 -> nothing.
  ASSERT_EQ(runner.actions.size(), 4U);
  EXPECT_EQ(runner.actions[0].gripper, GripperAction::kClose);
  EXPECT_EQ(runner.actions[1].pose_name, "p2");
  EXPECT_EQ(runner.actions[1].step_index, 4U);
  EXPECT_EQ(runner.actions[2].pose_name, "p1");
  EXPECT_EQ(runner.actions[2].move, MoveKind::kLine);
  EXPECT_EQ(runner.actions[3].gripper, GripperAction::kOpen);
  EXPECT_EQ(report->steps_done, 6U);
}

TEST(Playback, StopsAtTheFailingStepAndSaysWhich) {
  const auto model = ibm7545();
  FakeRunner runner;
  runner.fail_at = 3;  // the line move to p2
  auto report = play(task3(), model, runner, {});
  ASSERT_TRUE(report);
  EXPECT_FALSE(report->ok());
  EXPECT_EQ(report->failed_step, 2U);
  EXPECT_EQ(report->steps_done, 2U);
  EXPECT_THAT(report->brief(), HasSubstr("stopped at step 3 after 2/6 steps"));
  EXPECT_THAT(report->brief(), HasSubstr("'p2'"));
  EXPECT_THAT(report->brief(), HasSubstr("beyond its limit"));
}

TEST(Playback, RangeAndSpeedOverride) {
  const auto model = ibm7545();
  FakeRunner runner;
  PlaybackOptions options;
  options.from = 2;
  options.to = 5;
  options.speed_override = 0.25;
  auto report = play(task3(), model, runner, options);
  ASSERT_TRUE(report);
  ASSERT_EQ(runner.actions.size(), 3U);
  EXPECT_EQ(runner.actions[0].pose_name, "p2");
  EXPECT_DOUBLE_EQ(runner.actions[0].speed_scale, 0.25);
  EXPECT_EQ(runner.actions[2].pose_name, "p3");
  options.to = 9;
  EXPECT_THAT(play(task3(), model, runner, options),
              IsErrWith(Errc::kOutOfRange, "not a range of the task's 6 steps"));
  options.to = std::nullopt;
  options.speed_override = 1.5;
  EXPECT_THAT(play(task3(), model, runner, options), IsErr(Errc::kOutOfRange));
}

TEST(Cursor, StepsForwardAndBackAcrossTheTask) {
  const auto model = ibm7545();
  const Task task = task3();
  Cursor cursor;
  EXPECT_THAT(cursor.peek_backward(task, model), IsErrWith(Errc::kOutOfRange, "at the start"));
  for (std::size_t i = 0; i < task.steps.size(); ++i) {
    auto a = cursor.peek_forward(task, model);
    ASSERT_TRUE(a) << i;
    EXPECT_EQ(a->step_index, i);
    cursor.advance();
  }
  EXPECT_THAT(cursor.peek_forward(task, model), IsErrWith(Errc::kOutOfRange, "at the end"));
  auto back = cursor.peek_backward(task, model);
  ASSERT_TRUE(back);
  EXPECT_EQ(back->kind, Action::Kind::kGripper);
  EXPECT_EQ(back->gripper, GripperAction::kClose);  // undo the final open
  cursor.retreat();
  back = cursor.peek_backward(task, model);
  ASSERT_TRUE(back);
  EXPECT_EQ(back->pose_name, "p2");  // undo p3: back to p2
  Task shorter = task;
  ASSERT_THAT(shorter.remove(5), IsOk());
  ASSERT_THAT(shorter.remove(4), IsOk());
  cursor.clamp(shorter);
  EXPECT_EQ(cursor.position(), 4U);
  EXPECT_THAT(cursor.seek(shorter, 5), IsErr(Errc::kOutOfRange));
  EXPECT_THAT(cursor.seek(shorter, 0), IsOk());
}

TEST(Simulate, PlansEveryStepOfflineAndEndsOnTheRecordedPoses) {
  const auto model = ibm7545();
  const Task task = task3();
  auto run = simulate(task, model, q7545(90, 90, 0, 0), {});
  ASSERT_TRUE(run) << run.error().message;
  ASSERT_EQ(run->size(), 6U);
  double t = 0.0;
  for (const auto& s : *run) {
    EXPECT_NEAR(s.start_s, t, 1e-9);
    t += s.duration_s;
    ASSERT_FALSE(s.samples.empty());
  }
  // Each move ends exactly on its recorded joints (line moves within the IK's rounding).
  const auto& p1 = (*run)[0];
  EXPECT_GT(p1.duration_s, 0.5);  // 45 deg of J1 at 45 deg/s and speed 0.5: > 1 s
  for (int k = 0; k < 4; ++k) {
    EXPECT_NEAR(p1.samples.back()[k], q7545(45, 105, 0, 0)[k], kTolRad);
    EXPECT_NEAR((*run)[4].samples.back()[k], q7545(30, 80, 50, -20)[k], 1e-6);
  }
  EXPECT_NEAR(p1.samples.front()[0], deg(90), kTolRad);
  EXPECT_EQ((*run)[1].gripper, GripperAction::kClose);
  EXPECT_THAT(model.forward((*run)[2].samples.back()).value(),
              IsNearPose(model.forward(q7545(50, 100, 100, 10)).value(), 1e-6));
  EXPECT_DOUBLE_EQ((*run)[3].duration_s, 0.2);
}

TEST(Simulate, RefusesWhatThePlannerRefusesNamingTheStep) {
  const auto model = ibm7545();
  Task task;
  task.name = "t";
  task.robot_id = "ibm7545";
  PoseStep a;
  a.name = "a";
  a.joints = q7545(10, 10, 0, 0);
  PoseStep b;
  b.name = "b";
  b.joints = q7545(190, 10, 0, 0);
  b.move = MoveKind::kLine;  // a straight line from a to b leaves the workspace box
  ASSERT_THAT(task.append(a), IsOk());
  ASSERT_THAT(task.append(b), IsOk());
  auto run = simulate(task, model, q7545(10, 10, 0, 0), {});
  ASSERT_FALSE(run);
  EXPECT_THAT(run.error().message, HasSubstr("step 2: move (line) to 'b'"));
  kinematics::JointVector bad(2);
  bad << 0, 0;
  EXPECT_THAT(simulate(task, model, bad, {}), IsErr(Errc::kInvalidArgument));
}

}  // namespace
}  // namespace cell::teach
