// The JSON the browser gets: units and names as the page expects them, and samples that would
// break a naive encoder (non-finite numbers, invalid UTF-8, bad quaternions) handled.
#include "codec.hpp"

#include <cmath>
#include <limits>
#include <numbers>

#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include "cell/bus/view.hpp"
#include "cell/geometry/idl_pose.hpp"
#include "cell/kinematics/robot_config.hpp"
#include "cell/testing/env.hpp"
#include "monitor_test_robots.hpp"

namespace cell::monitor {
namespace {

using nlohmann::json;
using ::testing::HasSubstr;

using test::robot;

TEST(Codec, NonFiniteNumbersBecomeNullAndBadUtf8IsReplacedNotThrown) {
  EXPECT_TRUE(number(std::nan("")).is_null());
  EXPECT_TRUE(number(std::numeric_limits<double>::infinity()).is_null());
  EXPECT_EQ(number(1.5), json(1.5));
  const json j{{"text", std::string("bad \xff\xfe utf8")}};
  EXPECT_THROW((void)j.dump(), json::type_error);  // what a plain dump() would do
  const std::string text = to_text(j);
  EXPECT_THAT(text, HasSubstr("bad "));
  EXPECT_EQ(text.find('\n'), std::string::npos);  // one line: an SSE data line
}

TEST(Codec, RobotStateCarriesJointsStampsAndNames) {
  const std::string id = "ibm7545";
  const std::string fault = "torques late \xc3";  // truncated UTF-8 from a controller
  std::vector<double> q{0.1, 0.2, 30.0, std::nan("")};
  std::vector<double> sp{0.1, 0.2, 31.0, 0.0};
  cell_robot_RobotState s{};
  s.robot_id = bus::borrow(id);
  s.header.stamp_ns = 123456789;
  s.header.seq = 42;
  bus::borrow(s.position_rad_or_mm, q);
  bus::borrow(s.setpoint_rad_or_mm, sp);
  s.base_T_tool = geometry::pose_to_idl(Eigen::Isometry3d(Eigen::Translation3d(1, 2, 3)));
  s.mode = cell_robot_MODE_MOVING;
  s.gripper = cell_robot_GRIPPER_CLOSED;
  s.fault_text = bus::borrow(fault);
  s.cycle_jitter_max_us = 12.5;
  const RobotSample sample = to_sample(s, 200000000);
  const json j = sample_json(sample);
  EXPECT_EQ(j["id"], "ibm7545");
  EXPECT_EQ(j["stamp_ns"], 123456789);
  EXPECT_EQ(j["received_ns"], 200000000);
  EXPECT_EQ(j["seq"], 42);
  EXPECT_EQ(j["mode"], "moving");
  EXPECT_EQ(j["gripper"], "closed");
  EXPECT_DOUBLE_EQ(j["q"][2].get<double>(), 30.0);
  EXPECT_TRUE(j["q"][3].is_null());
  EXPECT_DOUBLE_EQ(j["setpoint"][2].get<double>(), 31.0);
  EXPECT_DOUBLE_EQ(j["base_T_tool"]["p"][1].get<double>(), 2.0);
  EXPECT_DOUBLE_EQ(j["jitter_max_us"].get<double>(), 12.5);
  EXPECT_NO_THROW((void)to_text(j));

  // A quaternion that is no rotation: no tool pose rather than a made-up one.
  s.base_T_tool.orientation = {0.0, 0.0, 0.0, 0.0};
  EXPECT_TRUE(sample_json(to_sample(s, 0))["base_T_tool"].is_null());
}

TEST(Codec, RobotModelHasWhatTheBrowsersKinematicsNeeds) {
  const Eigen::Isometry3d world_T_base(Eigen::Translation3d(0, 0, 981.51));
  const json scara = robot_model_json(robot("ibm7545"), world_T_base);
  EXPECT_EQ(scara["kind"], "scara");
  EXPECT_EQ(scara["dof"], 4);
  EXPECT_EQ(scara["joints"][2]["type"], "prismatic");
  EXPECT_EQ(scara["joints"][2]["unit"], "mm");
  EXPECT_EQ(scara["joints"][0]["unit"], "deg");
  EXPECT_DOUBLE_EQ(scara["scara"]["link2_mm"].get<double>(), 250.0);
  EXPECT_EQ(scara["scara"]["z_down"], true);
  EXPECT_EQ(scara["scara"]["roll_world"], true);
  EXPECT_EQ(scara["scara"]["roll_clockwise"], true);
  EXPECT_DOUBLE_EQ(scara["world_T_base"]["p"][2].get<double>(), 981.51);
  EXPECT_TRUE(scara.contains("flange_T_tool"));
  const json arm = robot_model_json(robot("excalibur"), Eigen::Isometry3d::Identity());
  EXPECT_EQ(arm["kind"], "excalibur");
  EXPECT_DOUBLE_EQ(arm["excalibur"]["a2_mm"].get<double>(), 304.8);
  EXPECT_EQ(arm["branches"].size(), 8U);
}

TEST(Codec, WorldPartsHaveShapeNamesAndGraspPosesInTheWorld) {
  const std::string id = "ic8";
  const std::string cls = "dip20";
  const std::string support = "table";
  cell_world_WorldPart part{};
  part.part_id = bus::borrow(id);
  part.class_name = bus::borrow(cls);
  part.shape = cell_world_SHAPE_DIP;
  part.length_mm = 26.0;
  part.width_mm = 7.0;
  part.height_mm = 3.81;
  part.support = bus::borrow(support);
  Eigen::Isometry3d world_T_part(Eigen::Translation3d(134.39, 501.25, 750.0));
  world_T_part.rotate(Eigen::AngleAxisd(std::numbers::pi / 2, Eigen::Vector3d::UnitZ()));
  part.world_T_part = geometry::pose_to_idl(world_T_part);
  part.part_T_grasp = geometry::pose_to_idl(Eigen::Isometry3d(Eigen::Translation3d(0, 0, 3.81)));
  std::vector<cell_world_WorldPart> parts{part};
  cell_world_WorldState world{};
  world.table_height_mm = 750.0;
  world.world_seq = 3;
  bus::borrow(world.parts, parts);
  const json j = world_json(world);
  ASSERT_EQ(j["parts"].size(), 1U);
  EXPECT_EQ(j["parts"][0]["shape"], "dip");
  EXPECT_EQ(j["parts"][0]["support"], "table");
  EXPECT_NEAR(j["parts"][0]["grasp"]["p"][2].get<double>(), 753.81, 1e-9);
  EXPECT_NEAR(j["parts"][0]["grasp"]["p"][0].get<double>(), 134.39, 1e-9);
  EXPECT_DOUBLE_EQ(j["table_height_mm"].get<double>(), 750.0);
}

TEST(Codec, DetectionsAndEdgeWindowsForTheImageOverlay) {
  const std::string camera = "ibm7545_eye";
  const std::string cls = "dip14";
  cell_vision_Detection d{};
  d.id = 2;
  d.class_name = bus::borrow(cls);
  d.center_px = {100.0, 120.0};
  d.grip = cell_vision_GRIP_BLOCKED;
  d.grip_style = -1;
  d.has_base_pose = false;
  std::vector<cell_vision_Detection> items{d};
  cell_vision_Detections ds{};
  ds.camera_id = bus::borrow(camera);
  bus::borrow(ds.items, items);
  const json j = detections_json(ds);
  EXPECT_EQ(j["camera"], camera);
  EXPECT_EQ(j["items"][0]["grip"], "blocked");
  EXPECT_TRUE(j["items"][0]["base_pose"].is_null());
  EXPECT_DOUBLE_EQ(j["items"][0]["center_px"][1].get<double>(), 120.0);

  cell_vision_EdgeResult e{};
  e.camera_id = bus::borrow(camera);
  e.status.accepted = true;
  e.window_p1_px = {10, 20};
  e.window_p2_px = {30, 20};
  e.window_p3_px = {10, 80};
  e.start_px = {20, 25};
  e.end_px = {21, 75};
  const json edge = edge_result_json(e);
  EXPECT_EQ(edge["window_px"].size(), 3U);
  EXPECT_DOUBLE_EQ(edge["window_px"][2][1].get<double>(), 80.0);
  EXPECT_DOUBLE_EQ(edge["end_px"][0].get<double>(), 21.0);
}

// The job list's per-part results: every outcome in the words `cellctl job` uses, positions in
// mm and deg, reasons and counters as the task service sent them.
TEST(Codec, JobStatusCarriesEachPartsResultInCellctlsWords) {
  const std::string job = "job-7", cls = "ic_7x30", none, why = "robot is busy";
  std::vector<cell_task_PartResult> parts;
  const std::vector<std::pair<cell_task_PartOutcome, std::string>> outcomes{
      {cell_task_PART_PENDING, "pending"},
      {cell_task_PART_PLACED, "placed"},
      {cell_task_PART_SKIPPED_UNREACHABLE, "unreachable"},
      {cell_task_PART_SKIPPED_GRIP_BLOCKED, "grip_blocked"},
      {cell_task_PART_SKIPPED_OUTSIDE_WINDOW, "outside_window"},
      {cell_task_PART_LOCATE_FAILED, "locate_failed"},
      {cell_task_PART_MISSED, "missed"}};
  for (std::size_t i = 0; i < outcomes.size(); ++i) {
    cell_task_PartResult p{};
    p.index = static_cast<std::uint32_t>(i);
    p.class_name = bus::borrow(cls);
    p.outcome = outcomes[i].first;
    p.placed_at.x_mm = -310.0;
    p.placed_at.y_mm = 250.0 + 30.0 * static_cast<double>(i);
    p.placed_at.rz_rad = std::numbers::pi / 2;
    p.detail = bus::borrow(i == 2 ? why : none);
    parts.push_back(p);
  }
  std::vector<char*> reasons{const_cast<char*>(why.c_str())};
  cell_task_JobStatus st{};
  st.job_id = bus::borrow(job);
  st.state = cell_task_JOB_FAILED;
  st.kind = cell_task_JOB_TABLE_PICK_PLACE;
  st.parts_done = 1;
  st.parts_failed = 5;
  bus::borrow(st.parts, parts);
  st.reasons._buffer = reasons.data();
  st.reasons._length = st.reasons._maximum = 1;
  const json j = job_status_json(st);
  EXPECT_EQ(j["job_id"], job);
  EXPECT_EQ(j["state"], "failed");
  EXPECT_EQ(j["parts_done"], 1);
  EXPECT_EQ(j["parts_failed"], 5);
  EXPECT_EQ(j["reasons"], json::array({why}));
  ASSERT_EQ(j["parts"].size(), outcomes.size());
  for (std::size_t i = 0; i < outcomes.size(); ++i) {
    EXPECT_EQ(j["parts"][i]["outcome"], outcomes[i].second) << i;
    EXPECT_EQ(j["parts"][i]["index"], i);
    EXPECT_EQ(j["parts"][i]["class"], cls);
  }
  EXPECT_DOUBLE_EQ(j["parts"][3]["placed_at"]["y_mm"].get<double>(), 340.0);
  EXPECT_EQ(j["parts"][2]["detail"], why);
}

}  // namespace
}  // namespace cell::monitor
