#include "servo.hpp"

#include <algorithm>
#include <numbers>

#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include "cell/kinematics/robot_config.hpp"
#include "cell/motion/planner.hpp"
#include "cell/testing/env.hpp"
#include "cell/testing/matchers.hpp"
#include "ideal_driver.hpp"
#include "cell/testing/vectors.hpp"

namespace cell::gateway {
namespace {

using ::cell::testing::IsErrWith;
using ::cell::testing::IsOk;
using namespace std::chrono_literals;

double deg(double d) { return d * std::numbers::pi / 180; }

inline JointVector jv(std::initializer_list<double> values) {
  return cell::testing::vec<JointVector>(values);
}

/// A scripted controller: follows setpoints like the ideal robot, but a test can raise fault
/// bits or make the link fail, and it records the commands it received.
class FakeDriver final : public RobotDriver {
 public:
  explicit FakeDriver(JointVector q0) : q_(std::move(q0)) {
    info_.name = "fake";
    info_.dof = static_cast<int>(q_.size());
  }
  Status on_configure() override { return ok_status(); }
  Status on_activate() override { return ok_status(); }
  void on_deactivate() noexcept override {}
  void on_cleanup() noexcept override {}
  CycleStatus read(Clock::time_point, JointState& s) override {
    s.q = q_;
    s.qd = JointVector::Zero(q_.size());
    s.effort = JointVector::Zero(q_.size());
    s.homed = true;
    s.gripper = gripper;
    s.fault_bits = fault_bits;
    s.clock_advance_s = clock_advance_s;
    if (link_down) {
      return CycleStatus::kRetry;
    }
    return fault_bits != 0 ? CycleStatus::kFault : CycleStatus::kOk;
  }
  CycleStatus write(Clock::time_point, const JointSetpoint& sp) override {
    q_ = sp.q;
    last_written = sp.q;
    ++writes;
    return CycleStatus::kOk;
  }
  /// The arm comes to rest at `q` on its own (a board that let go of it in a fault).
  void rest_at(JointVector q) { q_ = std::move(q); }
  /// As the 7545's board: the setpoint moves at most `d` of path time a cycle.
  void bound_advance(std::chrono::nanoseconds d) { info_.max_setpoint_advance = d; }
  void set_link_retries(int n) { info_.link_retries = n; }
  Status command(DriverCommand c, const CommandArgs&) override {
    commands.push_back(c);
    if (c == DriverCommand::kReset) {
      fault_bits = 0;
    }
    if (c == DriverCommand::kGripperClose) {
      gripper = cell_robot_GRIPPER_CLOSED;
    }
    if (c == DriverCommand::kGripperOpen) {
      gripper = cell_robot_GRIPPER_OPEN;
    }
    return ok_status();
  }
  Status check(DriverCommand c, const CommandArgs& args) const override {
    if (c == DriverCommand::kSetTolerance && args.tolerance_rad > 0.1) {
      return Error{Errc::kInvalidArgument, "tolerance outside the fake's range"};
    }
    return ok_status();
  }
  std::string describe_faults(std::uint32_t bits) const override {
    return bits & 0x1000 ? "PS/2 did not provide torques in time (0x1000)" : "other";
  }
  const DriverInfo& info() const noexcept override { return info_; }

  std::uint32_t fault_bits = 0;
  bool link_down = false;
  double clock_advance_s = -1.0;  ///< JointState::clock_advance_s reported by every read()
  cell_robot_GripperState gripper = cell_robot_GRIPPER_OPEN;
  std::vector<DriverCommand> commands;
  int writes = 0;
  JointVector last_written;

 private:
  DriverInfo info_;
  JointVector q_;
};

class ServoTest : public ::testing::Test {
 protected:
  ServoTest()
      : model_(*kinematics::load_robot(cell::testing::source_dir() + "/config/robots/ibm7545.yaml")),
        planner_(model_, motion::PlannerOptions{}) {}

  /// Runs cycles of 1 ms from now_ until `done` holds or `max_s` passes.
  template <typename Fn>
  bool run_until(Servo& servo, Fn&& done, double max_s) {
    for (double t = 0; t < max_s; t += 0.001) {
      now_ += 1ms;
      servo.cycle(now_);
      if (done(servo.snapshot())) {
        return true;
      }
    }
    return false;
  }

  /// Posts a long move from `q0` and runs cycles until `progress` of it is done.
  void run_into_a_move(Servo& servo, const JointVector& q0, double progress) {
    ASSERT_THAT(
        servo.post_trajectory(*planner_.move_joints(q0, jv({deg(90), deg(45), 200, 0}), 1.0), "t"),
        IsOk());
    ASSERT_TRUE(
        run_until(servo, [&](const ServoSnapshot& s) { return s.progress > progress; }, 10));
  }

  kinematics::RobotModel model_;
  motion::Planner planner_;
  Clock::time_point now_ = Clock::now();
};

// A command the controller would refuse is refused when posted, never acknowledged and queued.
TEST_F(ServoTest, ACommandOutsideTheControllersLimitsIsRefusedWhenPosted) {
  auto driver = std::make_unique<FakeDriver>(jv({deg(45), deg(105), 0, 0}));
  FakeDriver* fake = driver.get();
  Servo servo(model_, std::move(driver), deg(0.5), 0.5);
  ASSERT_THAT(servo.start(now_), IsOk());
  CommandArgs args;
  args.tolerance_rad = 0.5;
  EXPECT_THAT(servo.post_command(cell_robot_CMD_SET_TOLERANCE, args),
              IsErrWith(Errc::kInvalidArgument, "outside the fake's range"));
  args.tolerance_rad = 0.01;
  ASSERT_THAT(servo.post_command(cell_robot_CMD_SET_TOLERANCE, args), IsOk());
  run_until(servo, [&](const ServoSnapshot&) { return !fake->commands.empty(); }, 0.1);
  ASSERT_EQ(fake->commands.size(), 1U);
  EXPECT_EQ(fake->commands[0], DriverCommand::kSetTolerance);
}

TEST_F(ServoTest, IdealRobotRefusesUntilHomedThenFollowsExactly) {
  const JointVector q0 = jv({deg(45), deg(105), 0, 0});
  Servo servo(model_, std::make_unique<IdealDriver>(4, q0, 0.5, 1ms), deg(0.5), 0.5);
  ASSERT_THAT(servo.start(now_), IsOk());
  auto plan = planner_.move_joints(q0, jv({deg(60), deg(90), 100, deg(30)}), 1.0);
  ASSERT_THAT(plan, IsOk());
  EXPECT_THAT(servo.post_trajectory(*plan, "t1"), IsErrWith(Errc::kNotReady, "not homed"));
  ASSERT_THAT(servo.post_command(cell_robot_CMD_HOME, {}), IsOk());
  servo.cycle(now_ += 1ms);
  ASSERT_THAT(servo.post_trajectory(*plan, "t1"), IsOk());
  EXPECT_THAT(servo.post_trajectory(*plan, "t2"), IsErrWith(Errc::kNotReady, "busy"));
  ASSERT_TRUE(run_until(servo, [](const ServoSnapshot& s) { return s.moving; }, 0.01));
  // Halfway it is where the trajectory says.
  const double half = plan->trajectory.duration_s() / 2;
  ASSERT_TRUE(run_until(servo, [&](const ServoSnapshot& s) { return s.progress >= 0.5; }, 10));
  EXPECT_TRUE(servo.snapshot().measured.q.isApprox(plan->trajectory.sample(half).q, 1e-2));
  ASSERT_TRUE(run_until(servo, [](const ServoSnapshot& s) { return !s.moving; }, 10));
  servo.cycle(now_ += 1ms);  // a cycle reads before it writes: measured lags one cycle
  const ServoSnapshot s = servo.snapshot();
  EXPECT_EQ(s.mode, cell_robot_MODE_IDLE);
  EXPECT_EQ(s.trajectory_id, "t1");
  EXPECT_DOUBLE_EQ(s.progress, 1.0);
  EXPECT_TRUE(s.measured.q.isApprox(plan->trajectory.end(), 1e-12));
  EXPECT_THAT(s.base_T_tool, ::cell::testing::IsNearPose(*model_.forward(plan->trajectory.end()), 1e-9));
}

// A move that ends on a joint's limit: at every read the ideal arm is on the path sampled at
// that instant (the host writes the point one setpoint_lead ahead), and never past the end,
// so the next move does not start beyond the limit (an extrapolating arm overshot theta4's
// 180 deg by a hair and the next move was refused).
TEST_F(ServoTest, IdealRobotIsOnThePathAtEveryReadAndNeverPastTheLimitItEndsOn) {
  const JointVector q0 = jv({deg(45), deg(105), 0, deg(90)});
  const kinematics::JointSpec& wrist = model_.joints()[3];
  const JointVector goal = jv({deg(60), deg(90), 100, wrist.upper});
  Servo servo(model_, std::make_unique<IdealDriver>(4, q0, 0.5, 1ms), deg(0.5), 0.5);
  ASSERT_THAT(servo.start(now_), IsOk());
  ASSERT_THAT(servo.post_command(cell_robot_CMD_HOME, {}), IsOk());
  servo.cycle(now_ += 1ms);
  auto plan = planner_.move_joints(q0, goal, 1.0);
  ASSERT_THAT(plan, IsOk());
  ASSERT_THAT(servo.post_trajectory(*plan, "to-limit"), IsOk());
  double worst_off_path = 0.0;
  int reads = 0;
  bool started = false;
  for (int i = 0; i < 20000; ++i) {
    servo.cycle(now_ += 1ms);
    const ServoSnapshot s = servo.snapshot();
    EXPECT_LE(s.measured.q[3], wrist.upper) << "read " << i;
    if (s.moving) {
      started = true;
      // progress is the fraction of the path's time the setpoint written this cycle is at;
      // the arm read this cycle holds the previous cycle's setpoint, one lead behind it.
      const double t_read = s.progress * plan->trajectory.duration_s() - 0.001;
      if (t_read > 0.0) {
        worst_off_path = std::max(
            worst_off_path,
            (s.measured.q - plan->trajectory.sample(t_read).q).cwiseAbs().maxCoeff());
        ++reads;
      }
    } else if (started) {
      break;
    }
  }
  ASSERT_TRUE(started);
  EXPECT_GT(reads, 100);
  EXPECT_LT(worst_off_path, 1e-9);
  for (int i = 0; i < 3; ++i) {  // held there, cycle after cycle
    servo.cycle(now_ += 1ms);
    EXPECT_TRUE(servo.snapshot().measured.q.isApprox(goal, 1e-12));
  }
}

/// A controller whose homing, like the 7545's find_home(), re-zeroes its counters and reports
/// done while the arm still coasts a little past the index; its home is every joint at 0.
class HomingDriver final : public RobotDriver {
 public:
  explicit HomingDriver(JointVector q0) : q_(std::move(q0)) { info_.dof = 4; }
  Status on_configure() override { return ok_status(); }
  Status on_activate() override { return ok_status(); }
  void on_deactivate() noexcept override {}
  void on_cleanup() noexcept override {}
  CycleStatus read(Clock::time_point, JointState& s) override {
    if (homing_reads_ > 0 && --homing_reads_ == 0) {
      homed_ = true;
      q_ = jv({0.002, -0.001, 0.3, 0.004});  // re-zeroed, still coasting onto the index
    }
    s.q = q_;
    s.qd = JointVector::Zero(4);
    s.effort = JointVector::Zero(4);
    s.homed = homed_;
    s.busy = homing_reads_ > 0;
    return CycleStatus::kOk;
  }
  CycleStatus write(Clock::time_point, const JointSetpoint& sp) override {
    last_written = sp.q;
    return CycleStatus::kOk;
  }
  Status command(DriverCommand c, const CommandArgs&) override {
    if (c == DriverCommand::kHome) {
      homed_ = false;
      homing_reads_ = 50;
    }
    return ok_status();
  }
  bool home_joints(JointVector& out) const override {
    out = JointVector::Zero(4);
    return true;
  }
  std::string describe_faults(std::uint32_t) const override { return "none"; }
  const DriverInfo& info() const noexcept override { return info_; }

  JointVector last_written;

 private:
  DriverInfo info_;
  JointVector q_;
  bool homed_ = false;
  int homing_reads_ = 0;
};

// After homing, the host's setpoint is the controller's home: not the setpoint from before
// (in counts the homing re-zeroed, so holding it would drive the arm off home by the
// power-up offset) nor the joints measured at the end (the arm was still coasting).
TEST_F(ServoTest, AfterHomingTheSetpointIsTheControllersHome) {
  auto driver = std::make_unique<HomingDriver>(jv({deg(10), deg(-20), 50, deg(5)}));
  HomingDriver* fake = driver.get();
  Servo servo(model_, std::move(driver), deg(0.5), 0.5);
  ASSERT_THAT(servo.start(now_), IsOk());
  EXPECT_TRUE(servo.snapshot().setpoint.q.isApprox(jv({deg(10), deg(-20), 50, deg(5)})));
  ASSERT_THAT(servo.post_command(cell_robot_CMD_HOME, {}), IsOk());
  ASSERT_TRUE(run_until(servo, [](const ServoSnapshot& s) { return s.mode == cell_robot_MODE_HOMING; }, 0.1));
  ASSERT_TRUE(run_until(
      servo, [](const ServoSnapshot& s) { return s.measured.homed && s.mode == cell_robot_MODE_IDLE; },
      1.0));
  servo.cycle(now_ += 1ms);
  EXPECT_TRUE(servo.snapshot().setpoint.q.isZero(0.0)) << servo.snapshot().setpoint.q.transpose();
  EXPECT_TRUE(fake->last_written.isZero(0.0)) << fake->last_written.transpose();
}

TEST_F(ServoTest, RefusesATrajectoryThatDoesNotStartHere) {
  const JointVector q0 = jv({deg(45), deg(105), 0, 0});
  Servo servo(model_, std::make_unique<FakeDriver>(q0), deg(0.5), 0.5);
  ASSERT_THAT(servo.start(now_), IsOk());
  auto plan = planner_.move_joints(jv({deg(50), deg(105), 0, 0}), q0, 1.0);
  ASSERT_THAT(plan, IsOk());
  EXPECT_THAT(servo.post_trajectory(*plan, "t"),
              IsErrWith(Errc::kInvalidArgument,
                        "trajectory starts with joint j1 at 50.00 deg but the robot is at 45.00 deg"));
}

TEST_F(ServoTest, StopHaltsWithinOneCycleAndNeedsAReset) {
  const JointVector q0 = jv({deg(45), deg(105), 0, 0});
  auto driver = std::make_unique<FakeDriver>(q0);
  FakeDriver* fake = driver.get();
  Servo servo(model_, std::move(driver), deg(0.5), 0.5);
  ASSERT_THAT(servo.start(now_), IsOk());
  auto plan = planner_.move_joints(q0, jv({deg(90), deg(45), 200, deg(90)}), 1.0);
  ASSERT_THAT(servo.post_trajectory(*plan, "t"), IsOk());
  ASSERT_TRUE(run_until(servo, [](const ServoSnapshot& s) { return s.progress > 0.3; }, 10));
  ASSERT_THAT(servo.post_command(cell_robot_CMD_STOP, {}), IsOk());
  servo.cycle(now_ += 1ms);  // the stop takes effect in this cycle
  const JointVector held = servo.snapshot().setpoint.q;
  EXPECT_EQ(servo.snapshot().mode, cell_robot_MODE_STOPPED);
  ASSERT_FALSE(run_until(servo, [&](const ServoSnapshot& s) { return s.setpoint.q != held; }, 0.5));
  EXPECT_THAT(servo.post_trajectory(*planner_.move_joints(held, q0, 1.0), "u"),
              IsErrWith(Errc::kNotReady, "stopped"));
  ASSERT_THAT(servo.post_command(cell_robot_CMD_RESET, {}), IsOk());
  servo.cycle(now_ += 1ms);
  EXPECT_EQ(servo.snapshot().mode, cell_robot_MODE_IDLE);
  EXPECT_THAT(servo.post_trajectory(*planner_.move_joints(held, q0, 1.0), "u"), IsOk());
  EXPECT_GT(fake->writes, 0);
}

TEST_F(ServoTest, ControllerFaultStopsMotionIsReportedAndCleared) {
  const JointVector q0 = jv({deg(45), deg(105), 0, 0});
  auto driver = std::make_unique<FakeDriver>(q0);
  FakeDriver* fake = driver.get();
  Servo servo(model_, std::move(driver), deg(0.5), 0.5);
  ASSERT_THAT(servo.start(now_), IsOk());
  run_into_a_move(servo, q0, 0.2);
  ASSERT_FALSE(HasFatalFailure());
  fake->fault_bits = 0x1000;
  servo.cycle(now_ += 1ms);
  const ServoSnapshot s = servo.snapshot();
  EXPECT_EQ(s.mode, cell_robot_MODE_FAULT);
  EXPECT_FALSE(s.moving);
  EXPECT_THAT(s.fault_text, ::testing::HasSubstr("torques in time"));
  const auto events = servo.take_events();
  ASSERT_FALSE(events.empty());
  EXPECT_EQ(events[0].code, "robot.fault");
  EXPECT_THAT(events[0].text, ::testing::HasSubstr("0x1000"));
  EXPECT_THAT(servo.post_trajectory(*planner_.move_joints(s.setpoint.q, q0, 1.0), "u"),
              IsErrWith(Errc::kNotReady, "fault"));
  ASSERT_THAT(servo.post_command(cell_robot_CMD_RESET, {}), IsOk());
  servo.cycle(now_ += 1ms);
  EXPECT_EQ(servo.snapshot().mode, cell_robot_MODE_IDLE);
  EXPECT_EQ(std::count(fake->commands.begin(), fake->commands.end(), DriverCommand::kReset), 1)
      << "out of a fault, the controller is reset";
}

// A reset clears a fault or a stop; only a fault reaches the controller. A reset of a robot
// that moves, or rests, with neither changes nothing (a stray or flooded RESET must neither
// restart a healthy controller, the Excalibur's reboot, nor halt a move), and a reset after a
// stop clears the servo's own state without restarting the controller.
TEST_F(ServoTest, AResetReachesTheControllerOnlyOutOfAFault) {
  const JointVector q0 = jv({deg(45), deg(105), 0, 0});
  auto driver = std::make_unique<FakeDriver>(q0);
  FakeDriver* fake = driver.get();
  Servo servo(model_, std::move(driver), deg(0.5), 0.5);
  ASSERT_THAT(servo.start(now_), IsOk());
  ASSERT_THAT(servo.post_command(cell_robot_CMD_RESET, {}), IsOk());
  servo.cycle(now_ += 1ms);
  EXPECT_EQ(servo.snapshot().mode, cell_robot_MODE_IDLE);
  run_into_a_move(servo, q0, 0.2);
  ASSERT_FALSE(HasFatalFailure());
  const double before = servo.snapshot().progress;
  ASSERT_THAT(servo.post_command(cell_robot_CMD_RESET, {}), IsOk());
  servo.cycle(now_ += 1ms);
  servo.cycle(now_ += 1ms);
  EXPECT_EQ(servo.snapshot().mode, cell_robot_MODE_MOVING) << "a reset does not halt a move";
  EXPECT_GT(servo.snapshot().progress, before);
  ASSERT_THAT(servo.post_command(cell_robot_CMD_STOP, {}), IsOk());
  servo.cycle(now_ += 1ms);
  ASSERT_EQ(servo.snapshot().mode, cell_robot_MODE_STOPPED);
  ASSERT_THAT(servo.post_command(cell_robot_CMD_RESET, {}), IsOk());
  servo.cycle(now_ += 1ms);
  EXPECT_EQ(servo.snapshot().mode, cell_robot_MODE_IDLE);
  EXPECT_EQ(std::count(fake->commands.begin(), fake->commands.end(), DriverCommand::kReset), 0)
      << "no fault: the controller was never reset";
}

// A fault mid-move, after which the arm rests elsewhere than its last setpoint (the 7545's
// board lets go of a joint whose torque word overflowed): once reset, the servo holds the arm
// where it is, cycle after cycle, instead of driving it back to the old setpoint (on the
// simulated 7545 that was a 281-count jump and a second torque fault at once).
TEST_F(ServoTest, AfterAResetTheArmIsHeldWhereItRestsNotWhereItWasLastSent) {
  const JointVector q0 = jv({deg(45), deg(105), 0, 0});
  auto driver = std::make_unique<FakeDriver>(q0);
  FakeDriver* fake = driver.get();
  Servo servo(model_, std::move(driver), deg(0.5), 0.5);
  ASSERT_THAT(servo.start(now_), IsOk());
  run_into_a_move(servo, q0, 0.3);
  ASSERT_FALSE(HasFatalFailure());
  fake->fault_bits = 0x0100;
  servo.cycle(now_ += 1ms);
  ASSERT_EQ(servo.snapshot().mode, cell_robot_MODE_FAULT);
  const JointVector sent = fake->last_written;
  JointVector rest = sent;
  rest[0] += deg(3);  // coasted 2600 counts of J1 on
  fake->rest_at(rest);
  servo.cycle(now_ += 1ms);
  ASSERT_THAT(servo.post_command(cell_robot_CMD_RESET, {}), IsOk());
  for (int i = 0; i < 5; ++i) {
    servo.cycle(now_ += 1ms);
    EXPECT_EQ(servo.snapshot().mode, cell_robot_MODE_IDLE) << "cycle " << i;
    EXPECT_TRUE(fake->last_written.isApprox(rest, 1e-12))
        << "cycle " << i << ": wrote J1 " << fake->last_written[0] << " rad, the arm rests at "
        << rest[0] << " rad";
  }
  // The next move starts where the arm rests.
  EXPECT_THAT(servo.post_trajectory(*planner_.move_joints(rest, q0, 1.0), "back"), IsOk());
}

// A host stall of 20 ms in the middle of a move: with the advance bounded to 2 ms (the 7545),
// the path moves on 2 ms and the rest of the stall delays it (no jump of 20 ms x speed, a
// torque fault on the board); unbounded (the ideal arm), the path keeps to the wall clock.
TEST_F(ServoTest, AStalledCycleDelaysThePathWhenTheControllerBoundsItsAdvance) {
  const JointVector q0 = jv({deg(45), deg(105), 0, 0});
  for (const bool bounded : {true, false}) {
    auto driver = std::make_unique<FakeDriver>(q0);
    FakeDriver* fake = driver.get();
    if (bounded) {
      fake->bound_advance(2ms);
    }
    Servo servo(model_, std::move(driver), deg(0.5), 0.5);
    ASSERT_THAT(servo.start(now_), IsOk());
    auto plan = planner_.move_joints(q0, jv({deg(90), deg(45), 200, 0}), 1.0);
    ASSERT_THAT(plan, IsOk());
    const double d = plan->trajectory.duration_s();
    ASSERT_THAT(servo.post_trajectory(*plan, "t"), IsOk());
    ASSERT_TRUE(run_until(servo, [](const ServoSnapshot& s) { return s.progress > 0.4; }, 10));
    const double before_s = servo.snapshot().progress * d;
    servo.cycle(now_ += 20ms);
    const ServoSnapshot s = servo.snapshot();
    const double advanced_s = s.progress * d - before_s;
    EXPECT_NEAR(advanced_s, bounded ? 0.002 : 0.020, 1e-9) << (bounded ? "bounded" : "free");
    EXPECT_NEAR(s.path_delay_s, bounded ? 0.018 : 0.0, 1e-9);
    EXPECT_TRUE(fake->last_written.isApprox(plan->trajectory.sample(before_s + advanced_s).q,
                                            1e-9));
    // The move still ends where it was going, that much later.
    ASSERT_TRUE(run_until(servo, [](const ServoSnapshot& x) { return !x.moving; }, 10));
    servo.cycle(now_ += 1ms);
    EXPECT_TRUE(servo.snapshot().measured.q.isApprox(plan->trajectory.end(), 1e-12));
  }
}

// A controller whose clock the driver reads (the simulated 7545 board): the path advances by
// that clock, not the host's. A 20 ms host stall in which the board ran one period moves the
// path 1 ms; a cycle without an exchange (0) holds it; jittered host cycles (0.7 ms, 1.3 ms)
// still move it exactly one period each. The move ends where it was going.
TEST_F(ServoTest, ThePathFollowsTheControllersClockWhenTheDriverReadsIt) {
  const JointVector q0 = jv({deg(45), deg(105), 0, 0});
  auto driver = std::make_unique<FakeDriver>(q0);
  FakeDriver* fake = driver.get();
  fake->bound_advance(2ms);  // not used while the clock is known
  fake->clock_advance_s = 0.001;
  Servo servo(model_, std::move(driver), deg(0.5), 0.5);
  ASSERT_THAT(servo.start(now_), IsOk());
  auto plan = planner_.move_joints(q0, jv({deg(90), deg(45), 200, 0}), 1.0);
  ASSERT_THAT(plan, IsOk());
  const double d = plan->trajectory.duration_s();
  ASSERT_THAT(servo.post_trajectory(*plan, "t"), IsOk());
  ASSERT_TRUE(run_until(servo, [](const ServoSnapshot& s) { return s.progress > 0.4; }, 10));
  const auto path_s = [&] { return servo.snapshot().progress * d; };
  double before_s = path_s();
  servo.cycle(now_ += 20ms);
  EXPECT_NEAR(path_s() - before_s, 0.001, 1e-9) << "a 20 ms stall, one board period";
  EXPECT_NEAR(servo.snapshot().path_delay_s, 0.019, 1e-9);
  before_s = path_s();
  fake->clock_advance_s = 0.0;
  servo.cycle(now_ += 1ms);
  EXPECT_NEAR(path_s() - before_s, 0.0, 1e-9) << "no exchange, no board time";
  fake->clock_advance_s = 0.001;
  for (const auto gap : {700us, 1300us, 700us, 1300us}) {
    before_s = path_s();
    servo.cycle(now_ += gap);
    EXPECT_NEAR(path_s() - before_s, 0.001, 1e-9) << "host gap " << gap.count() << " us";
  }
  EXPECT_TRUE(fake->last_written.isApprox(plan->trajectory.sample(path_s()).q, 1e-9));
  ASSERT_TRUE(run_until(servo, [](const ServoSnapshot& x) { return !x.moving; }, 10));
  servo.cycle(now_ += 1ms);
  EXPECT_TRUE(servo.snapshot().measured.q.isApprox(plan->trajectory.end(), 1e-12));
}

TEST_F(ServoTest, LinkFailingFourCyclesInARowIsAFault) {
  const JointVector q0 = jv({deg(45), deg(105), 0, 0});
  auto driver = std::make_unique<FakeDriver>(q0);
  FakeDriver* fake = driver.get();
  Servo servo(model_, std::move(driver), deg(0.5), 0.5);
  ASSERT_THAT(servo.start(now_), IsOk());
  fake->link_down = true;
  for (int i = 0; i < 3; ++i) {
    servo.cycle(now_ += 1ms);
    EXPECT_NE(servo.snapshot().mode, cell_robot_MODE_FAULT) << "retry " << i;
  }
  servo.cycle(now_ += 1ms);
  EXPECT_EQ(servo.snapshot().mode, cell_robot_MODE_FAULT);
  EXPECT_EQ(servo.snapshot().fault_text, "link to the controller failed 4 cycles in a row");
  // One fault while the link stays down, not one a cycle.
  (void)servo.take_events();
  for (int i = 0; i < 5; ++i) {
    servo.cycle(now_ += 1ms);
  }
  EXPECT_TRUE(servo.take_events().empty());
}

// A driver that waits longer for its controller (a simulated 7545 board with a 20 ms grace
// for a late master is waited for 20 cycles of its own stalls).
TEST_F(ServoTest, TheDriverSaysHowManyCyclesWithoutAnExchangeItWaits) {
  const JointVector q0 = jv({deg(45), deg(105), 0, 0});
  auto driver = std::make_unique<FakeDriver>(q0);
  FakeDriver* fake = driver.get();
  fake->set_link_retries(20);
  Servo servo(model_, std::move(driver), deg(0.5), 0.5);
  ASSERT_THAT(servo.start(now_), IsOk());
  fake->link_down = true;
  for (int i = 0; i < 20; ++i) {
    servo.cycle(now_ += 1ms);
    ASSERT_NE(servo.snapshot().mode, cell_robot_MODE_FAULT) << "retry " << i;
  }
  fake->link_down = false;  // back within the grace: nothing happened
  servo.cycle(now_ += 1ms);
  EXPECT_EQ(servo.snapshot().mode, cell_robot_MODE_IDLE);
  fake->link_down = true;
  for (int i = 0; i < 21; ++i) {
    servo.cycle(now_ += 1ms);
  }
  EXPECT_EQ(servo.snapshot().mode, cell_robot_MODE_FAULT);
  EXPECT_EQ(servo.snapshot().fault_text, "link to the controller failed 21 cycles in a row");
}

TEST_F(ServoTest, PickClosesTheGripperAtTheBottom) {
  const JointVector q0 = jv({deg(45), deg(105), 0, 0});
  auto driver = std::make_unique<FakeDriver>(q0);
  FakeDriver* fake = driver.get();
  Servo servo(model_, std::move(driver), deg(0.5), 0.5);
  ASSERT_THAT(servo.start(now_), IsOk());
  Eigen::Isometry3d grasp = Eigen::Isometry3d::Identity();
  grasp.translation() = Eigen::Vector3d(134.39, 501.25, -227.7);
  auto plan = planner_.pick_or_place(q0, grasp, 27.7, true, 1.0);
  ASSERT_THAT(plan, IsOk());
  const double t_close = plan->events[0].t_s;
  ASSERT_THAT(servo.post_trajectory(*plan, "pick"), IsOk());
  servo.cycle(now_ += 1ms);
  ASSERT_TRUE(run_until(servo, [&](const ServoSnapshot&) { return !fake->commands.empty(); }, 20));
  EXPECT_EQ(fake->commands[0], DriverCommand::kGripperClose);
  const ServoSnapshot at_close = servo.snapshot();
  EXPECT_NEAR(at_close.progress * plan->trajectory.duration_s(), t_close, 0.002);
  EXPECT_THAT(at_close.base_T_tool, ::cell::testing::IsNearPose(grasp, 0.01));
  ASSERT_TRUE(run_until(servo, [](const ServoSnapshot& s) { return !s.moving; }, 20));
}

TEST_F(ServoTest, AlterMovesTheDestinationByTheTotalCorrection) {
  const JointVector q0 = jv({deg(45), deg(105), 100, 0});
  Servo servo(model_, std::make_unique<FakeDriver>(q0), deg(0.5), 0.5);
  ASSERT_THAT(servo.start(now_), IsOk());
  Eigen::Isometry3d goal = *model_.forward(q0);
  goal.translation() += Eigen::Vector3d(40, 30, 0);
  auto plan = planner_.track(q0, goal, false, true, 1.0);
  ASSERT_THAT(plan, IsOk());
  ASSERT_THAT(servo.post_trajectory(*plan, "track"), IsOk());
  trajectory::AlterCorrection c;
  c.translation_mm = Eigen::Vector3d(0, -12, 0);
  servo.post_alter(c, now_, "track");
  trajectory::AlterCorrection stale;
  stale.translation_mm = Eigen::Vector3d(100, 0, 0);
  servo.post_alter(stale, now_, "earlier");  // another trajectory's correction: ignored
  ASSERT_TRUE(run_until(servo, [](const ServoSnapshot& s) { return s.tracking; }, 10));
  ASSERT_THAT(servo.post_command(cell_robot_CMD_ALTER_OFF, {}), IsOk());
  ASSERT_TRUE(run_until(servo, [](const ServoSnapshot& s) { return !s.moving; }, 1));
  Eigen::Isometry3d expected = goal;
  expected.translation().y() -= 12;
  EXPECT_THAT(servo.snapshot().base_T_tool, ::cell::testing::IsNearPose(expected, 1e-6));
}

}  // namespace
}  // namespace cell::gateway
