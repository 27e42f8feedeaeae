// System test of the Excalibur gateway: cell-gateway with the `excalibur` driver and
// cell-sim-excalibur as two real processes talking the ASCII dialect over a pseudo-terminal,
// on a private DDS domain/partition, with line noise injected by the simulator. The test acts
// as the motion service (trajectories) and as the operator (RESET), and reads the simulator's
// true joint angles (robot_id "excalibur.sim") to check where the arm really is.
#include <fcntl.h>
#include <fmt/format.h>
#include <gmock/gmock.h>
#include <gtest/gtest.h>
#include <unistd.h>

#include <chrono>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <numbers>
#include <optional>
#include <random>
#include <regex>
#include <sstream>
#include <string>

#include "cell/bus/participant.hpp"
#include "cell/bus/reader.hpp"
#include "cell/bus/request_reply.hpp"
#include "cell/bus/topics.hpp"
#include "cell/bus/view.hpp"
#include "cell/geometry/angles.hpp"
#include "cell/kinematics/robot_config.hpp"
#include "cell/motion/planner.hpp"
#include "cell/motion/wire.hpp"
#include "cell/process/child.hpp"
#include "cell/testing/env.hpp"
#include "cell/testing/matchers.hpp"

namespace cell {
namespace {

namespace fs = std::filesystem;
using namespace std::chrono_literals;
using ::cell::testing::IsOk;
using ::testing::HasSubstr;
using JointVector = kinematics::JointVector;
using Clock = std::chrono::steady_clock;

using geometry::kDeg;
constexpr double kToleranceDeg = 1.0;
/// The wire carries 0.01 deg: a reading may round by half of that.
constexpr double kWireDeg = 0.005;

std::string read_text(const std::string& path) {
  std::ifstream in(path);
  std::stringstream s;
  s << in.rdbuf();
  return s.str();
}

void write_text(const fs::path& path, const std::string& text) {
  std::ofstream out(path);
  out << text;
}

std::size_t count(const std::string& text, const std::string& what) {
  std::size_t n = 0;
  for (auto at = text.find(what); at != std::string::npos; at = text.find(what, at + 1)) {
    ++n;
  }
  return n;
}

JointVector deg_vector(std::initializer_list<double> values) {
  JointVector q(static_cast<Eigen::Index>(values.size()));
  Eigen::Index i = 0;
  for (double v : values) {
    q[i++] = v * kDeg;
  }
  return q;
}

/// What happened to one move.
enum class Outcome { kCompleted, kFailed, kRefused, kHung };

class GatewayExcaliburTest : public ::testing::Test {
 protected:
  GatewayExcaliburTest()
      : domain_(cell::testing::test_domain_id()), partition_(cell::testing::unique_partition()) {
    std::string pattern = "/tmp/cell-gateway-excalibur-XXXXXX";
    dir_ = mkdtemp(pattern.data()) != nullptr ? fs::path(pattern) : fs::path("/tmp/cell-gx");
  }
  ~GatewayExcaliburTest() override {
    if (gateway_.running()) {
      gateway_.stop(5s);
    }
    if (sim_.running()) {
      sim_.stop(5s);
    }
    std::error_code ec;
    fs::remove_all(dir_, ec);
  }

  /// Writes the configs and starts the simulator, then the gateway. The robot is the shipped
  /// Excalibur with faster joints (180 deg/s, 3600 deg/s^2), the link 115200 baud with the
  /// shipped dialect's pacing scaled down, so 1,000 moves fit the CI budget.
  void launch(double noise_per_line) {
    const std::string src = cell::testing::source_dir();
    std::string robot = read_text(src + "/config/robots/excalibur.yaml");
    robot =
        std::regex_replace(robot, std::regex("max_speed_deg_s: [0-9.]+"), "max_speed_deg_s: 180.0");
    robot = std::regex_replace(robot, std::regex("max_accel_deg_s2: [0-9.]+"),
                               "max_accel_deg_s2: 3600.0");
    write_text(dir_ / "excalibur.yaml", robot);
    std::string dialect = read_text(src + "/config/controllers/excalibur.yaml");
    dialect =
        std::regex_replace(dialect, std::regex("char_delay_ms: [0-9.]+"), "char_delay_ms: 0.1");
    dialect =
        std::regex_replace(dialect, std::regex("command_delay_ms: [0-9.]+"), "command_delay_ms: 2");
    dialect = std::regex_replace(dialect, std::regex("reply_timeout_ms: [0-9.]+"),
                                 "reply_timeout_ms: 60");
    write_text(dir_ / "dialect.yaml", dialect);
    const std::string link = (dir_ / "excalibur.pty").string();
    write_text(dir_ / "sim.yaml", fmt::format("robot_config: {0}/excalibur.yaml\n"
                                              "dialect: {0}/dialect.yaml\n"
                                              "link_path: {1}\n"
                                              "baud: 115200\n"
                                              "state_rate_hz: 100\n"
                                              "controller:\n"
                                              "  initial_deg: [0, 30, -150, 0, 0, 0]\n"
                                              "  limits_deg: {{theta1: [-90, 90]}}\n"
                                              "  min_char_interval_ms: 0.15\n"
                                              "  busy_after_line_ms: 1\n"
                                              "  reply_delay_ms: 0.5\n"
                                              "  gripper_time_s: 0.1\n"
                                              "  seed: 11\n"
                                              "noise:\n"
                                              "  probability_per_line: {2}\n"
                                              "  control_file: {0}/noise.yaml\n",
                                              dir_.string(), link, noise_per_line));
    write_text(dir_ / "gateway.yaml", fmt::format("service: {{id: gateway.excalibur}}\n"
                                                  "robot_config: {0}/excalibur.yaml\n"
                                                  "cycle_hz: 100\n"
                                                  "state_rate_hz: 100\n"
                                                  "driver:\n"
                                                  "  kind: excalibur\n"
                                                  "  device: {1}\n"
                                                  "  dialect: {0}/dialect.yaml\n"
                                                  "  baud: 115200\n"
                                                  "  emulate_baud: true\n"
                                                  "  open_timeout_s: 20\n"
                                                  "  tolerance_deg: {2}\n"
                                                  "  controller_timeout_s: 2\n"
                                                  "  arrival_margin_s: 1\n"
                                                  "  idle_poll_s: 0.1\n"
                                                  "  gripper_time_s: 0.1\n",
                                                  dir_.string(), link, kToleranceDeg));
    auto env = cell::testing::bus_env(domain_, partition_);
    env.push_back("CELL_HOME=" + src);
    auto sim = process::Child::spawn({.executable = cell::testing::bin_path("cell-sim-excalibur"),
                                      .args = {"--config", (dir_ / "sim.yaml").string()},
                                      .env = env});
    ASSERT_THAT(sim, IsOk());
    sim_ = std::move(*sim);
    auto gateway = process::Child::spawn({.executable = cell::testing::bin_path("cell-gateway"),
                                          .args = {"--config", (dir_ / "gateway.yaml").string()},
                                          .env = env});
    ASSERT_THAT(gateway, IsOk());
    gateway_ = std::move(*gateway);
    auto model = kinematics::load_robot((dir_ / "excalibur.yaml").string());
    ASSERT_THAT(model, IsOk());
    model_ = std::move(*model);
    client_.emplace(domain_, partition_);
    state_topic_.emplace(*client_, bus::topics::kRobotState);
    states_.emplace(*client_, *state_topic_, bus::topics::kRobotState);
    commands_.emplace(*client_, bus::topics::kRobotCommand, bus::topics::kRobotCommandReply,
                      "test");
    trajectories_.emplace(*client_, bus::topics::kTrajectory, bus::topics::kRobotCommandReply,
                          "test-t");
    ASSERT_TRUE(cell::testing::eventually(
        [&] {
          pump();
          return gateway_state_.has_value() && sim_state_.has_value();
        },
        30s))
        << "gateway output:\n"
        << gateway_out_ << "\nsimulator output:\n"
        << sim_out_;
  }

  /// Takes every RobotState received (keeping the latest per robot) and the children's output.
  void pump() {
    states_->wait_for_data(5ms);
    auto batch = states_->take_copies(256);
    if (batch) {
      for (auto& s : *batch) {
        const std::string_view id = bus::str(s->robot_id);
        if (id == "excalibur") {
          gateway_state_ = std::move(s);
        } else if (id == "excalibur.sim") {
          sim_state_ = std::move(s);
        }
      }
    }
    (void)gateway_.read_available(gateway_out_);
    (void)sim_.read_available(sim_out_);
  }

  static JointVector joints(const cell_robot_RobotState& s, bool setpoint = false) {
    const auto v = setpoint ? bus::span(s.setpoint_rad_or_mm) : bus::span(s.position_rad_or_mm);
    JointVector q(static_cast<Eigen::Index>(v.size()));
    for (std::size_t j = 0; j < v.size(); ++j) {
      q[static_cast<Eigen::Index>(j)] = v[j];
    }
    return q;
  }

  /// The simulator's true angles, from a sample stamped after `after_ns`.
  std::optional<JointVector> true_angles_after(std::int64_t after_ns) {
    const auto deadline = Clock::now() + 2s;
    while (Clock::now() < deadline) {
      pump();
      if (sim_state_ && (*sim_state_)->header.stamp_ns > after_ns) {
        return joints(**sim_state_);
      }
    }
    return std::nullopt;
  }

  Status command(cell_robot_RobotCommandKind kind) {
    cell_robot_RobotCommand c{};
    const std::string robot = "excalibur";
    c.robot_id = bus::borrow(robot);
    c.kind = kind;
    auto reply = commands_->call(c, 5s);
    if (!reply) {
      return std::move(reply).error();
    }
    if (!(*reply)->status.accepted) {
      return Error{Errc::kInvalidArgument, std::string(bus::str((*reply)->status.reason))};
    }
    return ok_status();
  }

  /// Sends `plan` as trajectory `id` and waits until the gateway says how it ended.
  Outcome run(const motion::Plan& plan, const std::string& id, std::string* why = nullptr) {
    motion::TrajectoryWire wire;
    motion::to_idl(plan, "excalibur", id, "test", wire);
    auto reply = trajectories_->call(wire.message, 5s);
    if (!reply || !(*reply)->status.accepted) {
      if (why != nullptr) {
        *why = reply ? std::string(bus::str((*reply)->status.reason)) : reply.error().message;
      }
      return Outcome::kRefused;
    }
    const auto deadline = Clock::now() + 20s;
    while (Clock::now() < deadline) {
      pump();
      if (!gateway_state_) {
        continue;
      }
      const cell_robot_RobotState& s = **gateway_state_;
      if (bus::str(s.trajectory_id) != id) {
        continue;
      }
      if (s.mode == cell_robot_MODE_FAULT) {
        if (why != nullptr) {
          *why = std::string(bus::str(s.fault_text));
        }
        return Outcome::kFailed;
      }
      if (s.mode == cell_robot_MODE_IDLE && !s.moving) {
        return Outcome::kCompleted;
      }
    }
    return Outcome::kHung;
  }

  /// RESET, then waits until the gateway reports IDLE.
  void reset() {
    ASSERT_THAT(command(cell_robot_CMD_RESET), IsOk());
    ASSERT_TRUE(cell::testing::eventually(
        [&] {
          pump();
          return gateway_state_ && (*gateway_state_)->mode == cell_robot_MODE_IDLE;
        },
        10s));
  }

  std::uint32_t domain_;
  std::string partition_;
  fs::path dir_;
  process::Child sim_;
  process::Child gateway_;
  std::string sim_out_;
  std::string gateway_out_;
  std::optional<kinematics::RobotModel> model_;
  std::optional<bus::Participant> client_;
  std::optional<bus::Topic<cell_robot_RobotState>> state_topic_;
  std::optional<bus::Reader<cell_robot_RobotState>> states_;
  std::optional<bus::Requester<cell_robot_RobotCommand, cell_robot_RobotCommandReply>> commands_;
  std::optional<bus::Requester<cell_motion_Trajectory, cell_robot_RobotCommandReply>> trajectories_;
  std::optional<bus::Owned<cell_robot_RobotState>> gateway_state_;
  std::optional<bus::Owned<cell_robot_RobotState>> sim_state_;
};

// The acceptance test: 1,000 moves with 1 % line noise (one fault in 1 % of the lines,
// each direction). Every move either completes at its target within the tolerance (checked on
// the simulator's true angles) or is reported failed; none ends anywhere else, and the link
// recovers by itself (no operator needed between moves unless a move failed).
TEST_F(GatewayExcaliburTest, ThousandMovesWithOnePercentLineNoiseEndAtTargetOrReportedFailed) {
  launch(0.01);
  motion::Planner planner(*model_, {});
  std::mt19937_64 rng(2024);
  std::uniform_real_distribution<double> step(-8.0, 8.0);
  // A box well inside every limit (theta1 also inside the controller's own +-90 deg).
  const std::array<std::array<double, 2>, 6> box = {
      {{-60, 60}, {10, 80}, {-170, -100}, {-60, 60}, {-60, 60}, {-60, 60}}};
  constexpr int kMoves = 1000;
  int completed = 0;
  int failed = 0;
  std::vector<std::string> failures;
  const auto t0 = Clock::now();
  for (int i = 0; i < kMoves; ++i) {
    ASSERT_TRUE(gateway_state_.has_value());
    const JointVector q0 = joints(**gateway_state_, /*setpoint=*/true);
    // A random step, re-drawn while the planner refuses it (the table and base guards).
    JointVector q1 = q0;
    Result<motion::Plan> plan = Error{Errc::kOutOfRange, "no target drawn"};
    for (int attempt = 0; attempt < 50 && !plan; ++attempt) {
      for (int j = 0; j < 6; ++j) {
        const auto& b = box[static_cast<std::size_t>(j)];
        q1[j] = std::clamp(q0[j] / kDeg + step(rng), b[0], b[1]) * kDeg;
      }
      if (attempt >= 10) {  // near a guard: head halfway back to the middle of the box
        q1 = q0 + (deg_vector({0, 45, -135, 0, 0, 0}) - q0) * 0.5;
      }
      plan = planner.move_joints(q0, q1, 1.0);
    }
    ASSERT_THAT(plan, IsOk()) << i;
    std::string why;
    const std::string id = fmt::format("m{}", i);
    const Outcome outcome = run(*plan, id, &why);
    ASSERT_NE(outcome, Outcome::kRefused) << id << ": " << why;
    ASSERT_NE(outcome, Outcome::kHung)
        << id << " neither completed nor failed within 20 s\n"
        << gateway_out_.substr(gateway_out_.size() > 4000 ? gateway_out_.size() - 4000 : 0);
    if (outcome == Outcome::kCompleted) {
      ++completed;
      const cell_robot_RobotState& s = **gateway_state_;
      // The gateway reports the requested target (within tolerance: no resync, case 17) ...
      EXPECT_LE((joints(s) - q1).cwiseAbs().maxCoeff(), 1e-9) << id;
      // ... and the arm really is within the tolerance of it.
      auto truth = true_angles_after(s.header.stamp_ns);
      ASSERT_TRUE(truth.has_value()) << id;
      EXPECT_LE((*truth - q1).cwiseAbs().maxCoeff() / kDeg, kToleranceDeg + kWireDeg)
          << id << " completed but the arm is elsewhere";
    } else {
      ++failed;
      EXPECT_FALSE(why.empty()) << id << " failed without saying why";
      failures.push_back(fmt::format("{}: {}", id, why));
      reset();
    }
  }
  const double elapsed_s = std::chrono::duration<double>(Clock::now() - t0).count();
  pump();
  const std::size_t line_errors = count(gateway_out_, "event=line_error");
  const std::size_t recovered = count(gateway_out_, "event=link_recovered");
  std::cout << fmt::format(
      "{} moves in {:.1f} s: {} completed at target, {} reported failed; "
      "{} line errors, {} recoveries by port reset + restore\n",
      kMoves, elapsed_s, completed, failed, line_errors, recovered);
  for (const auto& f : failures) {
    std::cout << "  failed: " << f << "\n";
  }
  EXPECT_EQ(completed + failed, kMoves);
  EXPECT_GT(line_errors, 20U) << "the noise did not reach the link";
  EXPECT_GT(recovered, 20U);
  EXPECT_LE(failed, kMoves / 100) << "the link did not recover by itself";
}

TEST_F(GatewayExcaliburTest, GarbageOnTheLineIsAnsweredWithAnErrorNothingMovesGatewayKeepsRunning) {
  launch(0.0);
  const JointVector before = joints(**sim_state_);
  // A second writer on the controller's line (a stray terminal), paced like a person typing so
  // that the controller reads every character (unpaced, it would only see an overrun).
  {
    const int fd = ::open((dir_ / "excalibur.pty").c_str(), O_WRONLY | O_NOCTTY);
    ASSERT_GE(fd, 0);
    const std::string garbage = std::string("HELLO ROBOT\r") + "\x01\x02\xff garbage\r" +
                                "MJ 90.00 0.00 0.00 0.00 0.00 0.00*0000\r";
    for (char c : garbage) {
      ASSERT_EQ(::write(fd, &c, 1), 1);
      std::this_thread::sleep_for(1ms);
    }
    ::close(fd);
  }
  ASSERT_TRUE(cell::testing::eventually(
      [&] {
        pump();
        return count(sim_out_, "event=rejected") >= 3;
      },
      10s))
      << sim_out_;
  EXPECT_THAT(sim_out_, HasSubstr("HELLO ROBOT"));
  EXPECT_THAT(sim_out_, HasSubstr("syntax error"));
  EXPECT_THAT(sim_out_, HasSubstr("checksum"));
  // Nothing moved, and the gateway still serves: a move completes afterwards.
  std::this_thread::sleep_for(500ms);
  pump();
  EXPECT_LE((joints(**sim_state_) - before).cwiseAbs().maxCoeff(), 1e-12);
  EXPECT_TRUE(gateway_.running());
  if ((*gateway_state_)->mode == cell_robot_MODE_FAULT) {
    reset();  // only if the garbage landed in an exchange too often (it should not)
  }
  motion::Planner planner(*model_, {});
  const JointVector q0 = joints(**gateway_state_, true);
  JointVector q1 = q0;
  q1[0] += 10 * kDeg;
  auto plan = planner.move_joints(q0, q1, 1.0);
  ASSERT_THAT(plan, IsOk());
  EXPECT_EQ(run(*plan, "after-garbage"), Outcome::kCompleted);
}

TEST_F(GatewayExcaliburTest, ATrajectoryOutsideLimitsIsRefusedAndATargetTheControllerRejectsFails) {
  launch(0.0);
  const JointVector q0 = joints(**gateway_state_, true);
  // Beyond the robot's theta2 limit (225 deg): refused by the gateway, nothing is sent.
  JointVector bad = q0;
  bad[1] = 230 * kDeg;
  motion::Plan plan;
  plan.trajectory = *trajectory::JointTrajectory::from_knots(
      {{0.0, q0, JointVector::Zero(6)}, {5.0, bad, JointVector::Zero(6)}});
  std::string why;
  EXPECT_EQ(run(plan, "too-far", &why), Outcome::kRefused);
  EXPECT_THAT(why, HasSubstr("theta2"));
  // Inside the robot's limits but beyond the controller's own theta1 range (+-90 deg): the
  // controller answers "move not achieved"; the gateway reports the move failed, with the arm's
  // true angles, and needs a RESET.
  motion::Planner planner(*model_, {});
  JointVector far = q0;
  far[0] = 120 * kDeg;
  auto far_plan = planner.move_joints(q0, far, 1.0);
  ASSERT_THAT(far_plan, IsOk());
  EXPECT_EQ(run(*far_plan, "beyond-controller", &why), Outcome::kFailed);
  EXPECT_THAT(why, HasSubstr("move not achieved: target outside the controller's joint limits"));
  const cell_robot_RobotState& s = **gateway_state_;
  auto truth = true_angles_after(s.header.stamp_ns);
  ASSERT_TRUE(truth.has_value());
  EXPECT_LE((joints(s) - *truth).cwiseAbs().maxCoeff() / kDeg, kWireDeg + 0.5)
      << "reported failed, but not where the arm is";
  reset();
}

}  // namespace
}  // namespace cell
