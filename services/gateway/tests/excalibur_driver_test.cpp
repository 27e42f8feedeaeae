#include "excalibur_driver.hpp"

#include <fmt/format.h>
#include <gmock/gmock.h>
#include <gtest/gtest.h>
#include <unistd.h>

#include <chrono>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <numbers>
#include <regex>
#include <sstream>
#include <thread>

#include "cell/config/yaml.hpp"
#include "cell/geometry/angles.hpp"
#include "cell/kinematics/robot_config.hpp"
#include "cell/motion/planner.hpp"
#include "cell/protocols/excalibur/angles.hpp"
#include "cell/protocols/excalibur/simulated_controller.hpp"
#include "cell/testing/env.hpp"
#include "cell/testing/matchers.hpp"
#include "gateway_config.hpp"
#include "servo.hpp"

namespace cell::gateway {
namespace {

namespace pe = protocols::excalibur;
using namespace std::chrono_literals;
using ::cell::testing::IsErrWith;
using ::cell::testing::IsOk;
using ::testing::HasSubstr;

using geometry::kDeg;
constexpr double kTolRad = 1e-12;

kinematics::RobotModel excalibur_model() {
  auto model =
      kinematics::load_robot(cell::testing::source_dir() + "/config/robots/excalibur.yaml");
  EXPECT_THAT(model, IsOk());
  return *model;
}

std::string dialect_path() {
  return cell::testing::source_dir() + "/config/controllers/excalibur.yaml";
}

/// The shipped dialect with a reply timeout of `reply_timeout_ms` instead of the 6809's 150 ms,
/// for a test that checks a clean link stays clean: the simulated controller is a thread of the
/// test, and a host busy with other tests can keep it from answering within 150 ms; the driver
/// then rightly counts a line error and recovers, which is the timing's test, not this one's.
std::shared_ptr<const pe::Dialect> dialect_with_reply_timeout(int reply_timeout_ms) {
  std::ifstream in(dialect_path());
  std::stringstream text;
  text << in.rdbuf();
  const std::string patched =
      std::regex_replace(text.str(), std::regex(R"(reply_timeout_ms: *[0-9.]+)"),
                         fmt::format("reply_timeout_ms: {}", reply_timeout_ms));
  EXPECT_NE(patched, text.str()) << "no reply_timeout_ms in " << dialect_path();
  auto doc = config::load_string(patched, dialect_path() + " (patched)");
  EXPECT_THAT(doc, IsOk());
  auto dialect = pe::Dialect::parse(*doc);
  EXPECT_THAT(dialect, IsOk());
  return std::make_shared<const pe::Dialect>(*dialect);
}

JointVector deg(std::initializer_list<double> values) {
  JointVector q(static_cast<Eigen::Index>(values.size()));
  Eigen::Index i = 0;
  for (double v : values) {
    q[i++] = v * kDeg;
  }
  return q;
}

/// The controller for these tests: the robot's limits in controller angles, fast joints (a
/// 20 deg move takes about 0.2 s), a 6809 that needs 0.3 ms between characters.
pe::ControllerSettings controller(const kinematics::RobotModel& model, const JointVector& initial) {
  const auto& ex = *model.excalibur();
  JointVector lower(6);
  JointVector upper(6);
  for (int j = 0; j < 6; ++j) {
    lower[j] = model.joints()[static_cast<std::size_t>(j)].lower;
    upper[j] = model.joints()[static_cast<std::size_t>(j)].upper;
  }
  pe::ControllerSettings s;
  s.lower_deg = pe::to_wire(ex, lower);
  s.upper_deg = pe::to_wire(ex, upper);
  s.lower_deg[0] = -90.0;  // the controller's own theta1 range is narrower than the model's
  s.upper_deg[0] = 90.0;
  s.speed_deg_s.fill(150.0);
  s.initial_deg = pe::to_wire(ex, initial);
  s.master_deg = {20, 10, 140, 0, 30, 0};
  s.accuracy_deg = 0.3;
  s.min_char_interval_s = 0.0003;
  s.busy_after_line_s = 0.001;
  s.gripper_time_s = 0.1;
  return s;
}

class ExcaliburDriverTest : public ::testing::Test {
 protected:
  ExcaliburDriverTest()
      : model_(excalibur_model()),
        dialect_(std::make_shared<const pe::Dialect>(*pe::Dialect::load(dialect_path()))),
        link_((std::filesystem::temp_directory_path() /
               fmt::format("cell-excalibur-driver-{}-{}/excalibur.pty", ::getpid(), counter_++))
                  .string()) {}

  ~ExcaliburDriverTest() override {
    driver_.reset();
    sim_.reset();
    std::error_code ec;  // the per-test directory of the link
    std::filesystem::remove_all(std::filesystem::path(link_).parent_path(), ec);
  }

  void start_sim(pe::ControllerSettings settings, pe::NoiseSettings noise = {}) {
    auto sim = pe::SimulatedController::start(*dialect_, settings,
                                              {.link_path = link_, .baud = 115200}, noise);
    ASSERT_THAT(sim, IsOk());
    sim_ = std::move(*sim);
  }
  ExcaliburDriverOptions options() const {
    ExcaliburDriverOptions o;
    o.device = link_;
    o.baud = 115200;
    o.emulate_baud = true;
    o.open_timeout_s = 2.0;
    o.controller_timeout_s = 2.0;
    o.arrival_margin_s = 0.5;
    o.idle_poll_s = 0.05;
    o.gripper_time_s = 0.1;
    return o;
  }
  void start_driver(ExcaliburDriverOptions o) {
    driver_ = std::make_unique<ExcaliburDriver>(model_, dialect_, std::move(o), 10ms);
    ASSERT_THAT(driver_->on_configure(), IsOk());
    ASSERT_THAT(driver_->on_activate(), IsOk());
  }
  void start(const JointVector& initial = deg({0, 30, -150, 0, 0, 0})) {
    start_sim(controller(model_, initial));
    start_driver(options());
  }

  /// Runs servo cycles (read, write `setpoint`) at 100 Hz until `done(state)` or `timeout`.
  template <typename Fn>
  bool cycle_until(const JointSetpoint& setpoint, Fn&& done, std::chrono::milliseconds timeout) {
    const auto deadline = Clock::now() + timeout;
    while (Clock::now() < deadline) {
      status_ = driver_->read(Clock::now(), state_);
      if (done(state_)) {
        return true;
      }
      (void)driver_->write(Clock::now(), setpoint);
      std::this_thread::sleep_for(10ms);
    }
    return false;
  }
  /// Sends a stationary target and waits until the driver has finished with it.
  bool move_to(const JointVector& target, std::chrono::milliseconds timeout = 5s) {
    JointSetpoint sp{target, JointVector::Zero(6)};
    (void)driver_->write(Clock::now(), sp);
    return cycle_until(
        sp, [](const JointState& s) { return !s.busy || s.fault_bits != 0; }, timeout);
  }
  JointVector sim_angles() const {
    return pe::from_wire(*model_.excalibur(), sim_->status().angles_deg);
  }

  static inline int counter_ = 0;
  kinematics::RobotModel model_;
  std::shared_ptr<const pe::Dialect> dialect_;
  std::string link_;
  std::unique_ptr<pe::SimulatedController> sim_;
  std::unique_ptr<ExcaliburDriver> driver_;
  JointState state_;
  CycleStatus status_ = CycleStatus::kOk;
};

// Digest 001 §2.3, case 9: the controller's (10, 0, 0, 5, 5, 5)* is the DH (10, 30, -150, 5, 5, 5).
TEST_F(ExcaliburDriverTest, ReadsTheControllersAnglesInTheDhConventionDigestCase9) {
  start(deg({10, 30, -150, 5, 5, 5}));
  EXPECT_EQ(sim_->status().angles_deg, (pe::ControllerAngles{10, 0, 0, 5, 5, 5}));
  ASSERT_EQ(driver_->read(Clock::now(), state_), CycleStatus::kOk);
  const JointVector expected = deg({10, 30, -150, 5, 5, 5});
  for (int j = 0; j < 6; ++j) {
    EXPECT_NEAR(state_.q[j], expected[j], 1e-9) << j;
  }
  EXPECT_TRUE(state_.homed);
  EXPECT_FALSE(state_.busy);
  EXPECT_EQ(state_.fault_bits, 0U);
}

TEST_F(ExcaliburDriverTest, MovesAndConfirmsTheTargetWithoutResyncWithinTolerance) {
  dialect_ = dialect_with_reply_timeout(3000);  // no line error, whatever the host's load
  start();
  const JointVector target = deg({20, 45, -120, 10, -20, 30});
  ASSERT_TRUE(move_to(target));
  EXPECT_EQ(status_, CycleStatus::kOk);
  // Within tolerance the requested value stands (digest 001 case 17: no resync).
  for (int j = 0; j < 6; ++j) {
    EXPECT_NEAR(state_.q[j], target[j], kTolRad) << j;
  }
  // And the arm really is there: within the tolerance when confirmed, settling within the
  // controller's accuracy (+-0.3 deg).
  EXPECT_LE((sim_angles() - target).cwiseAbs().maxCoeff(), 1.0 * kDeg);
  EXPECT_TRUE(cell::testing::eventually(
      [&] { return (sim_angles() - target).cwiseAbs().maxCoeff() <= 0.31 * kDeg; }, 2s));
  // Sent in controller angles: theta2* = 45 - 30, theta3* = -120 + 150.
  EXPECT_NEAR(sim_->status().target_deg[1], 15.0, 1e-9);
  EXPECT_NEAR(sim_->status().target_deg[2], 30.0, 1e-9);
  const auto stats = driver_->stats();
  EXPECT_EQ(stats.targets_done, 1U);
  EXPECT_EQ(stats.line_errors, 0U);
}

TEST_F(ExcaliburDriverTest, StreamsViaPointsWhileTheSetpointMoves) {
  start();
  const JointVector from = deg({0, 30, -150, 0, 0, 0});
  const JointVector to = deg({40, 50, -120, 20, 10, -10});
  const auto t0 = Clock::now();
  const double duration_s = 1.0;
  bool done = false;
  while (!done && Clock::now() - t0 < 6s) {
    const double t = std::chrono::duration<double>(Clock::now() - t0).count();
    const double u = std::min(t / duration_s, 1.0);
    JointSetpoint sp{from + (to - from) * u, u < 1.0 ? JointVector((to - from) / duration_s)
                                                     : JointVector(JointVector::Zero(6))};
    status_ = driver_->read(Clock::now(), state_);
    done = u >= 1.0 && !state_.busy;
    if (t > 0.1 && u < 0.9) {
      EXPECT_TRUE(state_.busy);
    }
    (void)driver_->write(Clock::now(), sp);
    std::this_thread::sleep_for(10ms);
  }
  ASSERT_TRUE(done);
  EXPECT_GT(driver_->stats().moves_sent, 3U);  // via points, then the exact target
  EXPECT_EQ(driver_->stats().targets_done, 1U);
  EXPECT_LE((state_.q - to).cwiseAbs().maxCoeff(), kTolRad);
  EXPECT_LE((sim_angles() - to).cwiseAbs().maxCoeff(), 1.0 * kDeg);
}

TEST_F(ExcaliburDriverTest, AMoveNotAchievedIsReportedFailedWithTheArmsTrueAngles) {
  start();
  const std::uint64_t moves_before = sim_->status().counters.moves;
  const JointVector target = deg({120, 30, -150, 0, 0, 0});  // theta1 beyond the controller's 90
  ASSERT_TRUE(move_to(target));
  EXPECT_EQ(status_, CycleStatus::kFault);
  EXPECT_EQ(state_.fault_bits, kFaultMoveNotAchieved);
  EXPECT_THAT(driver_->describe_faults(state_.fault_bits),
              HasSubstr("move not achieved: target outside the controller's joint limits"));
  // Never silently elsewhere: the reported state is where the arm is (it did not move).
  EXPECT_LE((state_.q - sim_angles()).cwiseAbs().maxCoeff(), 0.006 * kDeg);
  EXPECT_EQ(driver_->stats().targets_failed, 1U);
  // RESET clears the fault; the failed target is not sent again.
  ASSERT_THAT(driver_->command(DriverCommand::kReset, {}), IsOk());
  JointSetpoint hold{target, JointVector::Zero(6)};
  EXPECT_TRUE(cycle_until(
                  hold, [](const JointState&) { return false; }, 500ms) == false);
  EXPECT_EQ(status_, CycleStatus::kOk);
  EXPECT_EQ(sim_->status().counters.moves, moves_before);
  EXPECT_EQ(sim_->status().counters.not_achieved, 1U);
  // And the next target works.
  ASSERT_TRUE(move_to(deg({10, 30, -150, 0, 0, 0})));
  EXPECT_EQ(status_, CycleStatus::kOk);
}

// Digest 001 case 17: tolerance 1.0 deg; an arm 0.8 deg off is not resynced, 1.2 deg off is.
TEST_F(ExcaliburDriverTest, PositionCheckResyncsOnlyBeyondTheToleranceDigestCase17) {
  dialect_ = dialect_with_reply_timeout(3000);  // no line error, whatever the host's load
  for (const double bias : {0.8, 1.2}) {
    SCOPED_TRACE(bias);
    pe::ControllerSettings s = controller(model_, deg({0, 30, -150, 0, 0, 0}));
    s.accuracy_deg = 0.0;
    s.bias_deg = {0, bias, 0, 0, 0, 0};  // a miscalibrated theta2 pot
    s.own_check = false;                 // that the controller's own check does not notice
    driver_.reset();
    sim_.reset();
    start_sim(s);
    ExcaliburDriverOptions o = options();
    o.controller_timeout_s = 0.5;
    o.arrival_margin_s = 0.2;
    start_driver(o);
    const JointVector target = deg({10, 40, -140, 0, 0, 0});
    ASSERT_TRUE(move_to(target));
    if (bias < 1.0) {
      EXPECT_EQ(status_, CycleStatus::kOk);
      EXPECT_NEAR(state_.q[1], target[1], kTolRad);  // the requested value stands
    } else {
      EXPECT_EQ(status_, CycleStatus::kFault);
      EXPECT_EQ(state_.fault_bits, kFaultPositionCheck);
      EXPECT_NEAR(state_.q[1], target[1] + bias * kDeg, 0.006 * kDeg);  // resynced
      EXPECT_THAT(driver_->describe_faults(state_.fault_bits), HasSubstr("off by 1.20 deg"));
    }
  }
}

TEST_F(ExcaliburDriverTest, RecoversFromLineNoiseByItself) {
  start();
  ASSERT_THAT(sim_->set_noise(pe::NoiseSettings{0.05, 0.0}), IsOk());
  for (int i = 0; i < 15; ++i) {
    const JointVector target = deg({5.0 * (i % 4), 30 + 2.0 * (i % 3), -150, 0, 0, 0});
    ASSERT_TRUE(move_to(target, 10s)) << i;
    ASSERT_EQ(status_, CycleStatus::kOk) << driver_->describe_faults(state_.fault_bits);
    EXPECT_LE((sim_angles() - target).cwiseAbs().maxCoeff(), 1.0 * kDeg) << i;
  }
  const auto stats = driver_->stats();
  EXPECT_GT(stats.line_errors, 0U);
  EXPECT_GT(stats.recoveries, 0U);
  EXPECT_EQ(stats.escalations, 0U);
}

// A loaded host delivers a pty's (or a serial port's) lines late: a reply late by less than
// host_latency_s is taken and counted, with no port reset (a reset for a reply that was only
// late cut the next lines and desynchronised the replies: badinput's flood, 2 runs of 3).
TEST_F(ExcaliburDriverTest, AReplyLatePastItsReplyTimeIsTakenAndCountedWithinTheHostsLatency) {
  start();
  const auto before = driver_->stats();
  // The reply time here: the dialect's 150 ms and the line's bytes at 115200 baud.
  sim_->set_reply_delay(0.35);
  for (int i = 0; i < 3; ++i) {
    const JointVector target = deg({4.0 * (i + 1), 30, -150, 0, 0, 0});
    ASSERT_TRUE(move_to(target, 20s)) << i;
    ASSERT_EQ(status_, CycleStatus::kOk) << driver_->describe_faults(state_.fault_bits);
    EXPECT_LE((sim_angles() - target).cwiseAbs().maxCoeff(), 1.0 * kDeg) << i;
  }
  const auto stats = driver_->stats();
  EXPECT_GT(stats.late_replies, before.late_replies);
  // Normally no line error at all. A host stall longer than host_latency_s is a real one: it
  // is recovered from (the restore's first tries wait for the late controller), never escalated.
  EXPECT_EQ(stats.line_errors - before.line_errors, stats.recoveries - before.recoveries);
  EXPECT_EQ(stats.escalations, before.escalations);
  EXPECT_GE(stats.worst_reply_s, 0.35);
  EXPECT_LT(stats.worst_reply_s, 0.15 + 1.0 + 0.5);  // the reply time and host_latency_s, + slack
}

TEST_F(ExcaliburDriverTest, WithNoHostLatencyALateReplyIsALineError) {
  start_sim(controller(model_, deg({0, 30, -150, 0, 0, 0})));
  ExcaliburDriverOptions o = options();
  o.host_latency_s = 0.0;
  start_driver(o);
  sim_->set_reply_delay(0.35);
  ASSERT_TRUE(move_to(deg({6, 30, -150, 0, 0, 0}), 30s));
  EXPECT_EQ(status_, CycleStatus::kFault);
  EXPECT_EQ(state_.fault_bits & kFaultLink, kFaultLink);
  EXPECT_EQ(driver_->stats().late_replies, 0U);
  EXPECT_GT(driver_->stats().line_errors, 0U);
}

TEST_F(ExcaliburDriverTest, PersistentLineErrorsBecomeAnOperatorFaultThatResetClears) {
  start();
  ASSERT_THAT(sim_->set_noise(pe::NoiseSettings{1.0, 0.0}), IsOk());
  ASSERT_TRUE(move_to(deg({10, 30, -150, 0, 0, 0}), 20s));
  EXPECT_EQ(status_, CycleStatus::kFault);
  EXPECT_EQ(state_.fault_bits & kFaultLink, kFaultLink);
  EXPECT_THAT(driver_->describe_faults(state_.fault_bits),
              HasSubstr("serial link lost: line errors persisted after 5 port resets"));
  EXPECT_EQ(driver_->stats().escalations, 1U);
  ASSERT_THAT(sim_->set_noise(pe::NoiseSettings{}), IsOk());
  ASSERT_THAT(driver_->command(DriverCommand::kReset, {}), IsOk());
  ASSERT_TRUE(move_to(deg({-10, 35, -150, 0, 0, 0})));
  EXPECT_EQ(status_, CycleStatus::kOk);
}

TEST_F(ExcaliburDriverTest, ALostControllerIsAFaultAndAReplacementIsFoundAfterReset) {
  // The controller is lost by its pty going away, not by a slow reply: a loaded host must not
  // fail the activation or the relink with a line error first.
  dialect_ = dialect_with_reply_timeout(3000);
  start();
  sim_.reset();  // the simulator dies: its pty and symlink go away
  ASSERT_TRUE(move_to(deg({10, 30, -150, 0, 0, 0}), 20s));
  EXPECT_EQ(status_, CycleStatus::kFault);
  EXPECT_EQ(state_.fault_bits & kFaultLink, kFaultLink);
  start_sim(controller(model_, deg({0, 30, -150, 0, 0, 0})));  // a new pty behind the symlink
  std::this_thread::sleep_for(1500ms);                         // the driver relinks by itself
  ASSERT_THAT(driver_->command(DriverCommand::kReset, {}), IsOk());
  ASSERT_TRUE(move_to(deg({-10, 35, -150, 0, 0, 0})));
  EXPECT_EQ(status_, CycleStatus::kOk) << driver_->describe_faults(state_.fault_bits);
}

TEST_F(ExcaliburDriverTest, ModesToleranceAndGripper) {
  start();
  CommandArgs args;
  args.tolerance_rad = 0.5 * kDeg;
  ASSERT_THAT(driver_->command(DriverCommand::kSetTolerance, args), IsOk());
  ASSERT_TRUE(cell::testing::eventually([&] { return sim_->status().tolerance_deg == 0.5; }, 2s));
  args.tolerance_rad = 50 * kDeg;
  EXPECT_THAT(driver_->command(DriverCommand::kSetTolerance, args),
              IsErrWith(Errc::kInvalidArgument, "outside the controller's range"));
  // The same verdict before anything is sent (the servo asks it when the command is posted).
  EXPECT_THAT(driver_->check(DriverCommand::kSetTolerance, args),
              IsErrWith(Errc::kInvalidArgument, "50 deg is outside the controller's range"));
  args.tolerance_rad = 0.5 * kDeg;
  EXPECT_THAT(driver_->check(DriverCommand::kSetTolerance, args), IsOk());
  // Manual: the master arm drives the slave; the driver reports busy and follows the arm.
  args.mode = cell_robot_MODE_MANUAL;
  ASSERT_THAT(driver_->command(DriverCommand::kSetMode, args), IsOk());
  const JointVector master = pe::from_wire(*model_.excalibur(), {20, 10, 140, 0, 30, 0});
  JointSetpoint hold{deg({0, 30, -150, 0, 0, 0}), JointVector::Zero(6)};
  ASSERT_TRUE(cycle_until(
      hold,
      [&](const JointState& s) {
        return s.busy && (s.q - master).cwiseAbs().maxCoeff() < 0.05 * kDeg;
      },
      5s));
  EXPECT_EQ(sim_->status().mode, pe::Mode::kManual);
  args.mode = cell_robot_MODE_IDLE;  // back to host
  ASSERT_THAT(driver_->command(DriverCommand::kSetMode, args), IsOk());
  ASSERT_TRUE(cycle_until(
      hold, [](const JointState& s) { return !s.busy; }, 2s));
  EXPECT_EQ(sim_->status().mode, pe::Mode::kHost);
  args.mode = cell_robot_MODE_FAULT;
  EXPECT_THAT(driver_->command(DriverCommand::kSetMode, args),
              IsErrWith(Errc::kInvalidArgument, "no mode for robot mode"));
  // The gripper: closing, then closed after the assumed time (no aperture feedback).
  ASSERT_THAT(driver_->command(DriverCommand::kGripperClose, {}), IsOk());
  ASSERT_EQ(driver_->read(Clock::now(), state_), CycleStatus::kOk);
  EXPECT_EQ(state_.gripper, cell_robot_GRIPPER_CLOSING);
  EXPECT_TRUE(state_.busy);
  ASSERT_TRUE(cycle_until(
      hold, [](const JointState& s) { return s.gripper == cell_robot_GRIPPER_CLOSED && !s.busy; },
      2s));
  EXPECT_TRUE(sim_->status().gripper_closed);
  // What the controller does not have.
  EXPECT_FALSE(driver_->supports(DriverCommand::kSetGains));
  EXPECT_TRUE(driver_->supports(DriverCommand::kSetMode));
  EXPECT_THAT(driver_->command(DriverCommand::kLights, {}),
              IsErrWith(Errc::kInvalidArgument, "lights"));
  EXPECT_THAT(driver_->command(DriverCommand::kHome, {}), IsOk());  // pots: always homed
}

TEST_F(ExcaliburDriverTest, GivesUpOpeningAMissingPortAfterTheOpenTimeout) {
  ExcaliburDriverOptions o = options();
  o.device = "/nonexistent/excalibur.pty";
  o.open_timeout_s = 0.3;
  ExcaliburDriver driver(model_, dialect_, o, 10ms);
  ASSERT_THAT(driver.on_configure(), IsOk());
  const auto t0 = Clock::now();
  EXPECT_THAT(driver.on_activate(),
              IsErrWith(Errc::kIo, "serial port /nonexistent/excalibur.pty: cannot open"));
  EXPECT_GE(Clock::now() - t0, 300ms);
}

/// The driver under the gateway's real-time core: a planned trajectory and a failed move.
TEST_F(ExcaliburDriverTest, UnderTheServoATrajectoryEndsAtItsTargetOrInAReportedFault) {
  start_sim(controller(model_, deg({0, 30, -150, 0, 0, 0})));
  Servo servo(model_, std::make_unique<ExcaliburDriver>(model_, dialect_, options(), 10ms),
              0.5 * kDeg, 0.5);
  ASSERT_THAT(servo.start(Clock::now()), IsOk());
  std::atomic<bool> stop{false};
  std::thread loop([&] {
    while (!stop) {
      servo.cycle(Clock::now());
      std::this_thread::sleep_for(10ms);
    }
  });
  motion::Planner planner(model_, {});
  const JointVector start = servo.snapshot().setpoint.q;
  const JointVector target = deg({30, 50, -130, 10, 0, 0});
  auto plan = planner.move_joints(start, target, 1.0);
  ASSERT_THAT(plan, IsOk());
  ASSERT_THAT(servo.post_trajectory(*plan, "t1"), IsOk());
  EXPECT_TRUE(cell::testing::eventually(
      [&] {
        const auto s = servo.snapshot();
        return s.trajectory_id == "t1" && s.mode == cell_robot_MODE_IDLE;
      },
      10s));
  EXPECT_LE((servo.snapshot().measured.q - target).cwiseAbs().maxCoeff(), kTolRad);
  EXPECT_LE((sim_angles() - target).cwiseAbs().maxCoeff(), 1.0 * kDeg);
  // Beyond the controller's own theta1 limit: reported failed through the servo's fault path.
  auto bad = planner.move_joints(target, deg({100, 50, -130, 10, 0, 0}), 1.0);
  ASSERT_THAT(bad, IsOk());
  ASSERT_THAT(servo.post_trajectory(*bad, "t2"), IsOk());
  EXPECT_TRUE(cell::testing::eventually(
      [&] { return servo.snapshot().mode == cell_robot_MODE_FAULT; }, 10s));
  const auto snapshot = servo.snapshot();
  EXPECT_THAT(snapshot.fault_text, HasSubstr("move not achieved"));
  EXPECT_LE((snapshot.measured.q - sim_angles()).cwiseAbs().maxCoeff(), 0.3 * kDeg);
  bool fault_event = false;
  for (const auto& e : servo.take_events()) {
    fault_event = fault_event || (e.code == "robot.fault" &&
                                  e.text.find("move not achieved") != std::string::npos);
  }
  EXPECT_TRUE(fault_event);
  stop = true;
  loop.join();
  servo.shutdown();
}

TEST(ExcaliburDriverConfig, ReadsItsKeysStrictlyWithLocations) {
  const std::string yaml = fmt::format(
      "robot_config: {0}/config/robots/excalibur.yaml\n"
      "driver:\n"
      "  kind: excalibur\n"
      "  device: /tmp/x.pty\n"
      "  baud: 9601\n"
      "  tolerance_deg: 50\n"
      "  follow: sideways\n"
      "  colour: red\n"
      "  realtime_priority: -1\n",
      cell::testing::source_dir());
  auto config = load_config(*config::load_string(yaml, "g.yaml"));
  ASSERT_FALSE(config);
  const std::string& m = config.error().message;
  EXPECT_THAT(m, HasSubstr("g.yaml:5:9: key 'driver.baud': must be one of 1200"));
  EXPECT_THAT(m, HasSubstr("key 'driver.tolerance_deg': 50 is outside the controller's range"));
  EXPECT_THAT(m, HasSubstr("key 'driver.follow': must be 'stream' or 'final', got 'sideways'"));
  EXPECT_THAT(m, HasSubstr("unknown key 'driver.colour'"));
  EXPECT_THAT(m, HasSubstr("key 'driver.realtime_priority': must be 0 (none) or a SCHED_FIFO "
                           "priority 1..99, got -1"));
  auto missing = load_config(*config::load_string(
      "robot_config: x.yaml\ndriver: {kind: excalibur, device: /tmp/x, dialect: /nope.yaml}\n",
      "g.yaml"));
  ASSERT_FALSE(missing);
  EXPECT_THAT(missing.error().message, HasSubstr("key 'driver.dialect': /nope.yaml: cannot open"));
  auto good = load_config(*config::load_string(
      "robot_config: x.yaml\ndriver: {kind: excalibur, device: run/excalibur.pty}\n", "g.yaml"));
  EXPECT_THAT(good, IsOk());
}

}  // namespace
}  // namespace cell::gateway
