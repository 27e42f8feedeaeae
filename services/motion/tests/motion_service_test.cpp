#include "motion_service.hpp"

#include <numbers>

#include <fmt/format.h>
#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include "cell/bus/request_reply.hpp"
#include "cell/bus/view.hpp"
#include "cell/common/time.hpp"
#include "cell/motion/wire.hpp"
#include "cell/testing/env.hpp"
#include "cell/testing/matchers.hpp"
#include "cell/testing/service_harness.hpp"
#include "gateway_service.hpp"

namespace cell::motion_service {
namespace {

using namespace std::chrono_literals;
using ::cell::testing::IsOk;
using ::testing::HasSubstr;

double deg(double d) { return d * std::numbers::pi / 180; }

MotionConfig motion_config() {
  MotionConfig c;
  c.common.service_id = "motion";
  c.robots.push_back({"ibm7545", cell::testing::source_dir() + "/config/robots/ibm7545.yaml"});
  c.planner.gripper_dwell_s = 0.1;
  return c;
}

gateway::GatewayConfig gateway_config() {
  const std::string yaml = fmt::format(
      "service: {{id: gateway.ibm7545}}\n"
      "robot_config: {}/config/robots/ibm7545.yaml\n"
      "driver: {{kind: ideal, initial_joints: [45, 105, 0, 0], gripper_time_s: 0.05}}\n",
      cell::testing::source_dir());
  return gateway::load_config(*config::load_string(yaml, "gateway.yaml")).value();
}

bool terminal(const cell_motion_MotionStatus& s) {
  return s.state == cell_motion_MOTION_REFUSED || s.state == cell_motion_MOTION_DONE ||
         s.state == cell_motion_MOTION_FAILED || s.state == cell_motion_MOTION_PREVIEW;
}

class MotionServiceTest : public ::testing::Test {
 protected:
  MotionServiceTest()
      : domain_(cell::testing::test_domain_id()),
        partition_(cell::testing::unique_partition()),
        gateway_(domain_, partition_, gateway_config(), "gateway"),
        motion_(domain_, partition_, motion_config(), "motion"),
        client_(domain_, partition_),
        requests_(client_, bus::topics::kMotionRequest, bus::topics::kMotionStatus, "test"),
        commands_(client_, bus::topics::kRobotCommand, bus::topics::kRobotCommandReply, "test-c"),
        state_topic_(client_, bus::topics::kRobotState),
        states_(client_, state_topic_, bus::topics::kRobotState) {
    cell_robot_RobotCommand home{};
    const std::string robot = "ibm7545";
    home.robot_id = bus::borrow(robot);
    home.kind = cell_robot_CMD_HOME;
    auto r = commands_.call(home, 5s);
    EXPECT_TRUE(r && (*r)->status.accepted);
    // HOME is accepted before it is done: wait until the robot says it is homed (a loaded host
    // ran a move before, which the gateway rightly refused: "robot is not homed").
    EXPECT_TRUE(cell::testing::eventually(
        [&] {
          states_.wait_for_data(100ms);
          bool homed = false;
          for (auto& s : *states_.take_copies(64)) {
            homed = s->homed;
          }
          return homed;
        },
        10s));
    // The motion service plans only from a fresh robot state: wait until a preview stops
    // being refused for want of one.
    EXPECT_TRUE(cell::testing::eventually(
        [&] {
          auto probe = request(cell_motion_MOTION_MOVE_JOINTS);
          bus::borrow(probe.joints_rad_or_mm, grab_pose_);
          probe.preview_only = true;
          return send(probe, 5s)->state == cell_motion_MOTION_PREVIEW;
        },
        10s));
  }

  /// Sends a request and returns its terminal status (refused, done, failed or preview).
  bus::Owned<cell_motion_MotionStatus> send(cell_motion_MotionRequest& request,
                                            std::chrono::seconds timeout = 20s) {
    request.motion_id = bus::borrow(next_id_ = "m" + std::to_string(++counter_));
    auto seq = requests_.send(request, 5s);
    EXPECT_THAT(seq, IsOk());
    auto status = requests_.wait_reply(*seq, std::chrono::steady_clock::now() + timeout,
                                       [](const cell_motion_MotionStatus& s) { return terminal(s); });
    EXPECT_THAT(status, IsOk());
    return std::move(*status);
  }

  cell_motion_MotionRequest request(cell_motion_MotionKind kind) {
    cell_motion_MotionRequest r{};
    r.robot_id = bus::borrow(robot_);
    r.kind = kind;
    return r;
  }

  std::vector<double> joints_now() {
    std::vector<double> q;
    cell::testing::eventually(
        [&] {
          states_.wait_for_data(100ms);
          for (auto& s : *states_.take_copies(64)) {
            q = bus::to_vector(s->position_rad_or_mm);
          }
          return !q.empty();
        },
        3s);
    return q;
  }

  std::uint32_t domain_;
  std::string partition_;
  cell::testing::ServiceHarness<gateway::GatewayConfig, gateway::GatewayService> gateway_;
  cell::testing::ServiceHarness<MotionConfig, MotionService> motion_;
  bus::Participant client_;
  bus::Requester<cell_motion_MotionRequest, cell_motion_MotionStatus> requests_;
  bus::Requester<cell_robot_RobotCommand, cell_robot_RobotCommandReply> commands_;
  bus::Topic<cell_robot_RobotState> state_topic_;
  bus::Reader<cell_robot_RobotState> states_;
  std::string robot_ = "ibm7545";
  std::vector<double> grab_pose_{deg(45), deg(105), 0.0, 0.0};
  std::string next_id_;
  int counter_ = 0;
};

TEST_F(MotionServiceTest, MoveJointsRunsToDone) {
  const std::vector<double> target{deg(60), deg(90), 100.0, deg(30)};
  auto r = request(cell_motion_MOTION_MOVE_JOINTS);
  bus::borrow(r.joints_rad_or_mm, target);
  auto status = send(r);
  ASSERT_EQ(status->state, cell_motion_MOTION_DONE) << bus::str(status->reason);
  EXPECT_DOUBLE_EQ(status->progress, 1.0);
  EXPECT_GT(status->duration_s, 0.5);
  // The robot rests exactly at the target (the state stream may still hold samples from the
  // last cycles of the motion: wait for the resting one).
  std::vector<double> q;
  EXPECT_TRUE(cell::testing::eventually(
      [&] {
        q = joints_now();
        if (q.size() != 4) {
          return false;
        }
        for (std::size_t j = 0; j < 4; ++j) {
          if (std::abs(q[j] - target[j]) > 1e-9) {
            return false;
          }
        }
        return true;
      },
      3s));
}

TEST_F(MotionServiceTest, UnreachableTargetIsRefusedAndTheServiceKeepsServing) {
  auto r = request(cell_motion_MOTION_MOVE_POSE);
  Eigen::Isometry3d far = Eigen::Isometry3d::Identity();
  far.translation() = Eigen::Vector3d(900, 0, -100);
  r.target = motion::to_idl(far);
  auto refused = send(r);
  EXPECT_EQ(refused->state, cell_motion_MOTION_REFUSED);
  EXPECT_EQ(bus::str(refused->error_code), "out_of_range");
  EXPECT_THAT(bus::str(refused->reason), HasSubstr("target"));

  auto garbage = request(cell_motion_MOTION_MOVE_JOINTS);
  const std::vector<double> nan_joints{NAN, 0, 0, 0};
  bus::borrow(garbage.joints_rad_or_mm, nan_joints);
  auto refused2 = send(garbage);
  EXPECT_EQ(refused2->state, cell_motion_MOTION_REFUSED);
  EXPECT_THAT(bus::str(refused2->reason), HasSubstr("not finite"));

  auto unknown = request(cell_motion_MOTION_DEPART);
  const std::string nobody = "puma560";
  unknown.robot_id = bus::borrow(nobody);
  auto refused3 = send(unknown);
  EXPECT_THAT(bus::str(refused3->reason), HasSubstr("unknown robot 'puma560'"));

  auto ok = request(cell_motion_MOTION_MOVE_JOINTS);
  const std::vector<double> target{deg(50), deg(100), 20.0, 0.0};
  bus::borrow(ok.joints_rad_or_mm, target);
  EXPECT_EQ(send(ok)->state, cell_motion_MOTION_DONE);
}

TEST_F(MotionServiceTest, PreviewPlansWithoutMoving) {
  const auto before = joints_now();
  ASSERT_EQ(before.size(), 4U);
  auto r = request(cell_motion_MOTION_PICK);
  Eigen::Isometry3d grasp = Eigen::Isometry3d::Identity();
  grasp.translation() = Eigen::Vector3d(134.39, 501.25, -227.7);
  r.target = motion::to_idl(grasp);
  r.distance_mm = 27.7;
  r.preview_only = true;
  auto preview = send(r);
  ASSERT_EQ(preview->state, cell_motion_MOTION_PREVIEW) << bus::str(preview->reason);
  const auto path = bus::span(preview->path);
  ASSERT_GT(path.size(), 10U);
  auto last = motion::from_idl(path.back());
  ASSERT_TRUE(last);
  EXPECT_NEAR(last->translation().z(), -227.7 + 27.7, 1e-6);  // ends above the grasp
  std::this_thread::sleep_for(300ms);
  EXPECT_EQ(joints_now(), before);
}

TEST_F(MotionServiceTest, PickClosesTheGripperAndASecondRequestMeanwhileIsRefused) {
  auto r = request(cell_motion_MOTION_PICK);
  Eigen::Isometry3d grasp = Eigen::Isometry3d::Identity();
  grasp.translation() = Eigen::Vector3d(134.39, 501.25, -227.7);
  r.target = motion::to_idl(grasp);
  r.distance_mm = 27.7;
  r.motion_id = bus::borrow(next_id_ = "pick");
  auto seq = requests_.send(r, 5s);
  ASSERT_THAT(seq, IsOk());
  auto accepted = requests_.wait_reply(*seq, std::chrono::steady_clock::now() + 5s);
  ASSERT_THAT(accepted, IsOk());
  EXPECT_EQ((*accepted)->state, cell_motion_MOTION_ACCEPTED);

  auto busy = request(cell_motion_MOTION_DEPART);
  auto refused = send(busy);
  EXPECT_EQ(refused->state, cell_motion_MOTION_REFUSED);
  EXPECT_THAT(bus::str(refused->reason), HasSubstr("busy with motion 'pick'"));

  auto done = requests_.wait_reply(*seq, std::chrono::steady_clock::now() + 20s,
                                   [](const cell_motion_MotionStatus& s) { return terminal(s); });
  ASSERT_THAT(done, IsOk());
  EXPECT_EQ((*done)->state, cell_motion_MOTION_DONE) << bus::str((*done)->reason);
  ASSERT_TRUE(cell::testing::eventually(
      [&] {
        states_.wait_for_data(100ms);
        bool closed = false;
        for (auto& s : *states_.take_copies(64)) {
          closed = s->gripper == cell_robot_GRIPPER_CLOSED;
        }
        return closed;
      },
      3s));
}

}  // namespace
}  // namespace cell::motion_service

namespace cell::motion_service {
namespace {

// A track of a moving target (a part on a belt): the service says where and when the robot
// meets it, in the preview and in every status of the motion; a stale stamp and a window the
// robot cannot make are refused with the reason.
TEST_F(MotionServiceTest, ATrackOfAMovingTargetSaysWhereAndWhenItIsMet) {
  auto track = [&](double speed_mm_s, std::int64_t stamp_ns, double to_mm, bool preview) {
    auto r = request(cell_motion_MOTION_TRACK);
    Eigen::Isometry3d at = Eigen::Isometry3d::Identity();
    at.translation() = Eigen::Vector3d(150, 560, -200);
    r.target = motion::to_idl(at);
    r.target_velocity_mm_per_s = {0, -speed_mm_s, 0};
    r.target_stamp_ns = stamp_ns;
    r.meet_margin_s = 0.02;
    r.meet_from_mm = 0;
    r.meet_to_mm = to_mm;
    r.alter_world_frame = true;
    r.track_joint_interpolated = true;
    r.preview_only = preview;
    return r;
  };
  const std::int64_t stamp = wall_time_ns();
  auto r = track(100, stamp, 300, true);
  auto preview = send(r);
  ASSERT_EQ(preview->state, cell_motion_MOTION_PREVIEW) << bus::str(preview->reason);
  auto meet = motion::from_idl(preview->meet_target);
  ASSERT_TRUE(meet);
  const double meet_s = static_cast<double>(preview->meet_stamp_ns - stamp) * 1e-9;
  EXPECT_GT(meet_s, preview->duration_s);  // the robot is there before the target
  EXPECT_NEAR(meet->translation().y(), 560 - 100 * meet_s, 1e-3);
  EXPECT_NEAR(meet->translation().x(), 150, 1e-9);
  EXPECT_LE(560 - meet->translation().y(), 300 + 1e-6);  // inside the window
  // The real one: the meeting comes with ACCEPTED and stays in the final status.
  r = track(100, wall_time_ns(), 300, false);
  auto done = send(r);
  ASSERT_EQ(done->state, cell_motion_MOTION_DONE) << bus::str(done->reason);
  EXPECT_GT(done->meet_stamp_ns, 0);
  // Stale, and too fast for the window: refused with why.
  auto stale = track(100, wall_time_ns() - 10'000'000'000, 300, true);
  auto refused = send(stale);
  EXPECT_EQ(refused->state, cell_motion_MOTION_REFUSED);
  EXPECT_THAT(bus::str(refused->reason), HasSubstr("target_stamp_ns is 10.0"));
  auto fast = track(5000, wall_time_ns(), 600, true);
  refused = send(fast);
  EXPECT_EQ(refused->state, cell_motion_MOTION_REFUSED);
  EXPECT_EQ(bus::str(refused->error_code), "out_of_range");
  EXPECT_THAT(bus::str(refused->reason), HasSubstr("cannot meet the target at 5000 mm/s"));
  EXPECT_THAT(bus::str(refused->reason), HasSubstr("ms late"));
  auto gone = track(5000, wall_time_ns(), 50, true);  // out of the window before it starts
  EXPECT_THAT(bus::str(send(gone)->reason), HasSubstr("before the robot can start"));
  auto garbage = track(100, wall_time_ns(), 300, true);
  garbage.target_velocity_mm_per_s.x = NAN;
  EXPECT_THAT(bus::str(send(garbage)->reason), HasSubstr("not finite"));
}

}  // namespace
}  // namespace cell::motion_service
