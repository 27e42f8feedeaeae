#include <fmt/format.h>
#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include <csignal>
#include <thread>

#include "cell/bus/request_reply.hpp"
#include "cell/bus/view.hpp"
#include "cell/kinematics/robot_config.hpp"
#include "cell/motion/planner.hpp"
#include "cell/process/child.hpp"
#include "cell/testing/env.hpp"
#include "cell/testing/matchers.hpp"
#include "cell/testing/service_harness.hpp"
#include "gateway_service.hpp"

namespace cell::gateway {
namespace {

using namespace std::chrono_literals;
using Harness = cell::testing::ServiceHarness<GatewayConfig, GatewayService>;

GatewayConfig ideal_config() {
  const std::string yaml = fmt::format(
      "service: {{id: gateway.ibm7545}}\n"
      "robot_config: {}/config/robots/ibm7545.yaml\n"
      "cycle_hz: 1000\n"
      "state_rate_hz: 100\n"
      "driver: {{kind: ideal, initial_joints: [45, 105, 0, 0], gripper_time_s: 0.05}}\n",
      cell::testing::source_dir());
  auto config = load_config(*config::load_string(yaml, "gateway.yaml"));
  EXPECT_TRUE(config) << config.error().message;
  return *config;
}

TEST(GatewayConfig, DriverKeysAreCheckedByTheDriverWithLocations) {
  auto doc = config::load_string(
      "robot_config: x.yaml\ndriver: {kind: ideal, gripper_time_s: -1, colour: red}\n", "g.yaml");
  ASSERT_TRUE(doc);
  auto config = load_config(*doc);
  ASSERT_FALSE(config);
  EXPECT_THAT(config.error().message,
              ::testing::HasSubstr("key 'driver.gripper_time_s': must be in [0, 10], got -1"));
  EXPECT_THAT(config.error().message, ::testing::HasSubstr("unknown key 'driver.colour'"));
  const auto puma = config::load_string("robot_config: x.yaml\ndriver: {kind: puma}\n", "g.yaml");
  ASSERT_TRUE(puma);
  config = load_config(*puma);
  ASSERT_FALSE(config);
  EXPECT_THAT(
      config.error().message,
      ::testing::HasSubstr("g.yaml:2:16: key 'driver.kind': unknown driver 'puma' (known: ideal"));
}

class GatewayTest : public ::testing::Test {
 protected:
  GatewayTest()
      : domain_(cell::testing::test_domain_id()),
        partition_(cell::testing::unique_partition()),
        gateway_(domain_, partition_, ideal_config(), "gateway"),
        client_(domain_, partition_),
        commands_(client_, bus::topics::kRobotCommand, bus::topics::kRobotCommandReply, "test"),
        trajectories_(client_, bus::topics::kTrajectory, bus::topics::kRobotCommandReply, "test-t"),
        state_topic_(client_, bus::topics::kRobotState),
        states_(client_, state_topic_, bus::topics::kRobotState),
        model_(*kinematics::load_robot(ideal_config().robot_config)) {}

  Result<bus::Owned<cell_robot_RobotCommandReply>> command(cell_robot_RobotCommandKind kind,
                                                           const std::string& robot = "ibm7545") {
    cell_robot_RobotCommand c{};
    c.robot_id = bus::borrow(robot);
    c.kind = kind;
    return commands_.call(c, 5s);
  }

  /// The latest RobotState (waits up to 2 s for one).
  std::optional<bus::Owned<cell_robot_RobotState>> latest() {
    std::optional<bus::Owned<cell_robot_RobotState>> last;
    const auto deadline = std::chrono::steady_clock::now() + 2s;
    while (!last && std::chrono::steady_clock::now() < deadline) {
      states_.wait_for_data(100ms);
      auto batch = states_.take_copies(64);
      for (auto& s : *batch) {
        last = std::move(s);
      }
    }
    return last;
  }

  std::uint32_t domain_;
  std::string partition_;
  Harness gateway_;
  bus::Participant client_;
  bus::Requester<cell_robot_RobotCommand, cell_robot_RobotCommandReply> commands_;
  bus::Requester<cell_motion_Trajectory, cell_robot_RobotCommandReply> trajectories_;
  bus::Topic<cell_robot_RobotState> state_topic_;
  bus::Reader<cell_robot_RobotState> states_;
  kinematics::RobotModel model_;
};

TEST_F(GatewayTest, PublishesStateAtTheConfiguredRate) {
  ASSERT_TRUE(latest().has_value());
  std::size_t n = 0;
  const auto start = std::chrono::steady_clock::now();
  while (std::chrono::steady_clock::now() - start < 1s) {
    states_.wait_for_data(50ms);
    n += states_.take_copies(64)->size();
  }
  EXPECT_GT(n, 70U);  // 100 Hz nominal; generous for a loaded 2-core machine
  EXPECT_LT(n, 130U);
  auto s = latest();
  EXPECT_EQ(bus::str((*s)->robot_id), "ibm7545");
  EXPECT_EQ(bus::span((*s)->position_rad_or_mm).size(), 4U);
  EXPECT_DOUBLE_EQ((*s)->cycle_period_s, 0.001);
}

TEST_F(GatewayTest, RefusesMalformedTrajectoriesAndKeepsServing) {
  ASSERT_TRUE(command(cell_robot_CMD_HOME).has_value());
  // Wrong number of joints.
  motion::Plan bad;
  bad.trajectory = *trajectory::JointTrajectory::from_knots(
      {{0.0, trajectory::JointVector::Zero(6), trajectory::JointVector::Zero(6)}});
  motion::TrajectoryWire wire;
  motion::to_idl(bad, "ibm7545", "bad", "m", wire);
  auto reply = trajectories_.call(wire.message, 5s);
  ASSERT_THAT(reply, ::cell::testing::IsOk());
  EXPECT_FALSE((*reply)->status.accepted);
  EXPECT_THAT(bus::str((*reply)->status.reason), ::testing::HasSubstr("has 4 joints"));
  // A good one is accepted and executed.
  auto state = latest();
  ASSERT_TRUE(state.has_value());
  trajectory::JointVector q0(4);
  for (int j = 0; j < 4; ++j) {
    q0[j] = bus::span((*state)->position_rad_or_mm)[static_cast<std::size_t>(j)];
  }
  trajectory::JointVector q1 = q0;
  q1[2] = 50;  // Z down 50 mm
  motion::Planner planner(model_, {});
  auto plan = planner.move_joints(q0, q1, 1.0);
  ASSERT_THAT(plan, ::cell::testing::IsOk());
  motion::to_idl(*plan, "ibm7545", "good", "m", wire);
  reply = trajectories_.call(wire.message, 5s);
  ASSERT_THAT(reply, ::cell::testing::IsOk());
  EXPECT_TRUE((*reply)->status.accepted) << bus::str((*reply)->status.reason);
  ASSERT_TRUE(cell::testing::eventually(
      [&] {
        auto s = latest();
        return s && bus::str((*s)->trajectory_id) == "good" && !(*s)->moving &&
               std::abs(bus::span((*s)->position_rad_or_mm)[2] - 50.0) < 1e-9;
      },
      10s));
}

TEST_F(GatewayTest, AnswersEveryCommandAndIgnoresOtherRobots) {
  auto home = command(cell_robot_CMD_HOME);
  ASSERT_THAT(home, ::cell::testing::IsOk());
  EXPECT_TRUE((*home)->status.accepted);
  auto close = command(cell_robot_CMD_GRIPPER_CLOSE);
  ASSERT_THAT(close, ::cell::testing::IsOk());
  EXPECT_TRUE((*close)->status.accepted);
  ASSERT_TRUE(cell::testing::eventually(
      [&] {
        auto s = latest();
        return s && (*s)->gripper == cell_robot_GRIPPER_CLOSED && (*s)->homed;
      },
      5s));
  auto gains = command(cell_robot_CMD_SET_MODE);
  ASSERT_THAT(gains, ::cell::testing::IsOk());
  EXPECT_FALSE((*gains)->status.accepted);
  EXPECT_THAT(bus::str((*gains)->status.reason), ::testing::HasSubstr("not supported"));
  EXPECT_THAT(command(cell_robot_CMD_HOME, "excalibur"), ::cell::testing::IsErr(Errc::kTimeout));
}

// The supervisor watch: a heartbeat writer of another process (Cyclone leases only those),
// here cell-echo under the id "task", killed while the robot moves: the gateway stops the
// robot as a STOP command does and says why in a way the task service can recognise. Then a
// new supervisor, killed while the robot rests: stopped too (a move that ends within the lease
// must not leave the robot open to the next command of a cell that is gone).
TEST(GatewaySupervisor, StopsTheRobotMovingOrAtRestWhenEverySupervisorIsLostAndSaysWhy) {
  const std::uint32_t domain = cell::testing::test_domain_id();
  const std::string partition = cell::testing::unique_partition();
  GatewayConfig config = ideal_config();
  config.supervisors = {"task"};
  Harness gateway(domain, partition, config, "gateway");
  bus::Participant client(domain, partition);
  bus::Requester<cell_robot_RobotCommand, cell_robot_RobotCommandReply> commands(
      client, bus::topics::kRobotCommand, bus::topics::kRobotCommandReply, "test");
  bus::Requester<cell_motion_Trajectory, cell_robot_RobotCommandReply> trajectories(
      client, bus::topics::kTrajectory, bus::topics::kRobotCommandReply, "test-t");
  bus::Topic<cell_robot_RobotState> state_topic(client, bus::topics::kRobotState);
  bus::Reader<cell_robot_RobotState> states(client, state_topic, bus::topics::kRobotState);
  bus::Topic<cell_health_CellEvent> event_topic(client, bus::topics::kCellEvent);
  bus::Reader<cell_health_CellEvent> events(client, event_topic, bus::topics::kCellEvent);
  auto latest = [&] {
    std::optional<bus::Owned<cell_robot_RobotState>> last;
    const auto deadline = std::chrono::steady_clock::now() + 2s;
    while (!last && std::chrono::steady_clock::now() < deadline) {
      states.wait_for_data(100ms);
      for (auto& s : *states.take_copies(64)) {
        last = std::move(s);
      }
    }
    return last;
  };
  const std::string robot_id = "ibm7545";
  auto command = [&](cell_robot_RobotCommandKind kind) {
    cell_robot_RobotCommand c{};
    c.robot_id = bus::borrow(robot_id);
    c.kind = kind;
    return commands.call(c, 5s);
  };

  process::SpawnOptions options;
  options.executable = cell::testing::bin_path("cell-echo");
  options.args = {"--id", "task", "--config", cell::testing::source_dir() + "/config/echo.yaml"};
  options.env = cell::testing::bus_env(domain, partition);
  auto supervisor = process::Child::spawn(options);
  ASSERT_THAT(supervisor, ::cell::testing::IsOk());
  service::ServiceDirectory directory(client, "test");
  // Wait for the supervisor's heartbeat itself: a supervisor that never appeared is not lost
  // (by design), so killing one the gateway has not seen yet proves nothing. wait_settled
  // alone would return once the gateway's own heartbeat has been quiet for 300 ms, before a
  // slow child (a sanitizer build on a loaded host) has started.
  auto supervisor_serving = [&] {
    return cell::testing::eventually(
        [&] {
          auto entries = directory.snapshot();
          if (!entries) {
            return false;
          }
          for (const service::ServiceEntry& e : *entries) {
            if (e.service_id == "task" && !e.lost && e.state == cell_health_HEALTH_SERVING) {
              return true;
            }
          }
          return false;
        },
        20s);
  };
  ASSERT_TRUE(supervisor_serving()) << supervisor->output();

  auto home = command(cell_robot_CMD_HOME);
  ASSERT_THAT(home, ::cell::testing::IsOk());
  ASSERT_TRUE(cell::testing::eventually(
      [&] {
        auto s = latest();
        return s && (*s)->homed && (*s)->mode == cell_robot_MODE_IDLE;
      },
      10s));
  auto state = latest();
  ASSERT_TRUE(state.has_value());
  trajectory::JointVector q0(4);
  for (int j = 0; j < 4; ++j) {
    q0[j] = bus::span((*state)->position_rad_or_mm)[static_cast<std::size_t>(j)];
  }
  trajectory::JointVector q1 = q0;
  q1[2] = 150;  // Z down 150 mm, slowly: long enough to outlast the 3 s lease
  const kinematics::RobotModel model = *kinematics::load_robot(config.robot_config);
  motion::Planner planner(model, {});
  auto plan = planner.move_joints(q0, q1, 0.02);
  ASSERT_THAT(plan, ::cell::testing::IsOk());
  ASSERT_GT(plan->trajectory.duration_s(), 12.0);
  motion::TrajectoryWire wire;
  motion::to_idl(*plan, "ibm7545", "slow", "m", wire);
  auto reply = trajectories.call(wire.message, 5s);
  ASSERT_THAT(reply, ::cell::testing::IsOk());
  ASSERT_TRUE((*reply)->status.accepted) << bus::str((*reply)->status.reason);
  ASSERT_TRUE(cell::testing::eventually(
      [&] {
        auto s = latest();
        return s && (*s)->moving;
      },
      5s));

  const auto killed_at = std::chrono::steady_clock::now();
  ASSERT_EQ(::kill(supervisor->pid(), SIGKILL), 0);
  (void)supervisor->wait_for(5s);
  std::optional<bus::Owned<cell_robot_RobotState>> stopped;
  auto wait_stopped = [&] {
    return cell::testing::eventually(
        [&] {
          stopped = latest();
          return stopped && (*stopped)->mode == cell_robot_MODE_STOPPED;
        },
        10s);
  };
  ASSERT_TRUE(wait_stopped())
      << "the robot must be stopped once its only supervisor is lost";
  const double after_s =
      std::chrono::duration<double>(std::chrono::steady_clock::now() - killed_at).count();
  std::printf("stopped %.2f s after the supervisor was killed (lease 3 s)\n", after_s);
  EXPECT_LT(after_s, 8.0);
  EXPECT_EQ(bus::str((*stopped)->stop_code), "supervisor_lost");
  EXPECT_EQ(bus::str((*stopped)->fault_text), "stopped: supervisor 'task' lost");
  EXPECT_FALSE((*stopped)->moving);
  const double z_at_stop = bus::span((*stopped)->position_rad_or_mm)[2];
  EXPECT_LT(z_at_stop, 140.0) << "halted on the way, not at the end of the trajectory";
  bool event_seen = false;
  ASSERT_TRUE(cell::testing::eventually(
      [&] {
        for (auto& e : *events.take_copies(64)) {
          if (bus::str(e->code) == "gateway.supervisor_lost") {
            event_seen = true;
            EXPECT_EQ(e->severity, cell_health_SEVERITY_WARNING);
            EXPECT_THAT(std::string(bus::str(e->text)), ::testing::HasSubstr("'task'"));
          }
        }
        return event_seen;
      },
      5s));
  // It holds where it stopped, and a RESET clears the reason.
  std::this_thread::sleep_for(500ms);
  auto held = latest();
  ASSERT_TRUE(held.has_value());
  EXPECT_EQ((*held)->mode, cell_robot_MODE_STOPPED);
  EXPECT_NEAR(bus::span((*held)->position_rad_or_mm)[2], z_at_stop, 0.5);
  auto reset = command(cell_robot_CMD_RESET);
  ASSERT_THAT(reset, ::cell::testing::IsOk());
  EXPECT_TRUE((*reset)->status.accepted);
  ASSERT_TRUE(cell::testing::eventually(
      [&] {
        auto s = latest();
        return s && (*s)->mode == cell_robot_MODE_IDLE && bus::str((*s)->stop_code).empty() &&
               bus::str((*s)->fault_text).empty();
      },
      5s));

  // At rest: a supervisor comes back, and is lost again while nothing moves.
  auto second = process::Child::spawn(options);
  ASSERT_THAT(second, ::cell::testing::IsOk());
  ASSERT_TRUE(supervisor_serving());
  std::this_thread::sleep_for(300ms);  // the gateway reads the heartbeats at 10 Hz
  auto resting = latest();
  ASSERT_TRUE(resting.has_value());
  ASSERT_EQ((*resting)->mode, cell_robot_MODE_IDLE) << "back: no new stop";
  ASSERT_FALSE((*resting)->moving);
  const double z_resting = bus::span((*resting)->position_rad_or_mm)[2];
  ASSERT_EQ(::kill(second->pid(), SIGKILL), 0);
  (void)second->wait_for(5s);
  ASSERT_TRUE(wait_stopped())
      << "a robot at rest is stopped too once its only supervisor is lost";
  EXPECT_EQ(bus::str((*stopped)->stop_code), "supervisor_lost");
  EXPECT_EQ(bus::str((*stopped)->fault_text), "stopped: supervisor 'task' lost");
  EXPECT_NEAR(bus::span((*stopped)->position_rad_or_mm)[2], z_resting, 0.5);
}

TEST(GatewayConfig, SupervisorsAreServiceIdsAndNoneByDefault) {
  auto doc = config::load_string(
      "robot_config: x.yaml\nsupervisors: [task, '']\ndriver: {kind: ideal}\n", "g.yaml");
  ASSERT_TRUE(doc);
  auto config = load_config(*doc);
  ASSERT_FALSE(config);
  EXPECT_THAT(config.error().message, ::testing::HasSubstr("supervisors"));
  EXPECT_THAT(config.error().message, ::testing::HasSubstr("entry 1 is empty"));
  EXPECT_TRUE(ideal_config().supervisors.empty());
}

}  // namespace
}  // namespace cell::gateway
