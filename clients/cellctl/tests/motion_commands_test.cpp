// cellctl kin / robot / move against the real kinematics and, for robot and move, an
// in-process gateway (ideal robot) and motion service on a private bus.
#include <sstream>

#include <fmt/format.h>
#include <gmock/gmock.h>
#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

#include "cell/testing/env.hpp"
#include "cell/testing/service_harness.hpp"
#include "gateway_service.hpp"
#include "motion_service.hpp"
#include "cli_run.hpp"
#include "session.hpp"

namespace cell::cellctl {
namespace {

using ::testing::HasSubstr;
using nlohmann::json;

using testing::CliRun;
using testing::cellctl;
using testing::value_of;


// Digest 000 §9.2 case 2: the grab pose (45 deg, 105 deg) puts the tool at (66.37, 407.88) mm
// (the digest rounds the derived values).
TEST(CellctlKin, ForwardOfTheThesisGrabPose) {
  const CliRun run = cellctl({"--json", "kin", "fk", "--robot", "ibm7545", "--joints", "45,105,0,0"});
  ASSERT_EQ(run.code, kExitOk) << run.err;
  const json doc = json::parse(run.out);
  EXPECT_NEAR(doc["pose"]["x_mm"].get<double>(), 66.37, 0.05);
  EXPECT_NEAR(doc["pose"]["y_mm"].get<double>(), 407.88, 0.05);
  EXPECT_EQ(doc["joints"][2]["unit"], "mm");
  EXPECT_EQ(doc["joints"][0]["unit"], "deg");
  EXPECT_TRUE(doc["within_limits"].get<bool>());
}

TEST(CellctlKin, InverseListsEveryBranchByName) {
  const CliRun run = cellctl(
      {"--json", "kin", "ik", "--robot", "excalibur", "--pose", "500,200,300,0,90,0", "--all"});
  ASSERT_EQ(run.code, kExitOk) << run.err;
  const json doc = json::parse(run.out);
  ASSERT_EQ(doc["branches"].size(), 8U);
  EXPECT_EQ(doc["branches"][0]["branch"], "shoulder_front/elbow_up/wrist_noflip");
  // Each branch's joints, fed back through fk, reach the pose.
  for (const auto& b : doc["branches"]) {
    std::string joints;
    for (const auto& j : b["joints"]) {
      joints += fmt::format("{}{:.12f}", joints.empty() ? "" : ",", j["value"].get<double>());
    }
    const CliRun fk = cellctl({"--json", "kin", "fk", "--robot", "excalibur", "--joints", joints});
    ASSERT_EQ(fk.code, kExitOk) << fk.err;
    const json pose = json::parse(fk.out)["pose"];
    EXPECT_NEAR(pose["x_mm"].get<double>(), 500, 1e-6) << b["branch"];
    EXPECT_NEAR(pose["y_mm"].get<double>(), 200, 1e-6) << b["branch"];
    EXPECT_NEAR(pose["z_mm"].get<double>(), 300, 1e-6) << b["branch"];
  }
}

TEST(CellctlKin, BadInputIsAUsageErrorNamingWhatWasWrong) {
  CliRun run = cellctl({"kin", "fk", "--robot", "ibm7545", "--joints", "45,105"});
  EXPECT_EQ(run.code, kExitUsage);
  EXPECT_THAT(run.err, HasSubstr("2 values given; robot 'ibm7545' has 4 joints: j1 [deg], j2 "
                                 "[deg], z [mm], r [deg]"));
  run = cellctl({"kin", "fk", "--robot", "ibm7545", "--joints", "45,abc,0,0"});
  EXPECT_EQ(run.code, kExitUsage);
  EXPECT_THAT(run.err, HasSubstr("element 1 ('abc') is not a number"));
  run = cellctl({"kin", "ik", "--robot", "puma560", "--pose", "0,0,0,0,0,0"});
  EXPECT_EQ(run.code, kExitUsage);
  EXPECT_THAT(run.err, HasSubstr("unknown robot 'puma560'"));
  run = cellctl({"kin", "ik", "--robot", "ibm7545", "--pose", "900,0,-100,0,0,0"});
  EXPECT_EQ(run.code, kExitFailure);
  EXPECT_THAT(run.err, HasSubstr("x = 900.000 mm is outside cartesian_limits.x_mm"));
}

class CellctlMotionTest : public ::testing::Test {
 protected:
  static gateway::GatewayConfig gateway_config() {
    const std::string yaml = fmt::format(
        "service: {{id: gateway.ibm7545}}\n"
        "robot_config: {}/config/robots/ibm7545.yaml\n"
        "driver: {{kind: ideal, initial_joints: [45, 105, 0, 0], gripper_time_s: 0.05}}\n",
        cell::testing::source_dir());
    return gateway::load_config(*config::load_string(yaml, "gateway.yaml")).value();
  }
  static motion_service::MotionConfig motion_config() {
    motion_service::MotionConfig c;
    c.common.service_id = "motion";
    c.robots.push_back({"ibm7545", cell::testing::source_dir() + "/config/robots/ibm7545.yaml"});
    c.planner.gripper_dwell_s = 0.1;
    return c;
  }

  CellctlMotionTest()
      : domain_(cell::testing::test_domain_id()),
        partition_(cell::testing::unique_partition()),
        gateway_(domain_, partition_, gateway_config(), "gateway"),
        motion_(domain_, partition_, motion_config(), "motion") {}

  CliRun run(std::vector<std::string> args) {
    std::vector<std::string> all{"--domain", std::to_string(domain_), "--partition", partition_,
                                 "--timeout", "5"};
    all.insert(all.end(), args.begin(), args.end());
    return cellctl(all);
  }

  std::uint32_t domain_;
  std::string partition_;
  cell::testing::ServiceHarness<gateway::GatewayConfig, gateway::GatewayService> gateway_;
  cell::testing::ServiceHarness<motion_service::MotionConfig, motion_service::MotionService>
      motion_;
};

TEST_F(CellctlMotionTest, HomeMoveAndReadTheState) {
  CliRun r = run({"--json", "move", "joints", "--robot", "ibm7545", "--joints", "60,90,100,30"});
  EXPECT_EQ(r.code, kExitFailure);
  EXPECT_THAT(r.out + r.err, HasSubstr("not homed"));
  r = run({"robot", "home", "--robot", "ibm7545"});
  ASSERT_EQ(r.code, kExitOk) << r.err;
  r = run({"--json", "move", "joints", "--robot", "ibm7545", "--joints", "60,90,100,30"});
  ASSERT_EQ(r.code, kExitOk) << r.err;
  const json done = json::parse(r.out);
  EXPECT_EQ(done["state"], "done");
  EXPECT_NEAR(value_of(done["final_joints"], "z"), 100.0, 1e-9);
  r = run({"--json", "robot", "state", "--robot", "ibm7545"});
  ASSERT_EQ(r.code, kExitOk) << r.err;
  const json state = json::parse(r.out);
  EXPECT_TRUE(state["homed"].get<bool>());
  EXPECT_NEAR(value_of(state["joints"], "j1"), 60.0, 1e-3);  // deg; the state may be a cycle old
  EXPECT_NEAR(value_of(state["joints"], "r"), 30.0, 1e-3);
  // The servo's counters (the ideal gateway: cycles run, none late by its own clock); no
  // simulated board here ("board" is null).
  EXPECT_GT(state["cycle_count"].get<std::uint64_t>(), 100U);
  EXPECT_NEAR(state["cycle_period_s"].get<double>(), 0.001, 1e-9);
  EXPECT_TRUE(state["cycle_overruns"].is_number_unsigned());
  EXPECT_TRUE(state["board"].is_null());
  r = run({"robot", "state", "--robot", "ibm7545"});
  ASSERT_EQ(r.code, kExitOk) << r.err;
  EXPECT_THAT(r.out, ::testing::ContainsRegex("servo  [0-9]+ cycles of 1.0 ms, [0-9]+ late"));
}

TEST_F(CellctlMotionTest, RefusalsComeBackWithTheReason) {
  ASSERT_EQ(run({"robot", "home", "--robot", "ibm7545"}).code, kExitOk);
  CliRun r = run({"--json", "move", "pose", "--robot", "ibm7545", "--pose", "900,0,-50,0,0,0"});
  EXPECT_EQ(r.code, kExitFailure);
  const json doc = json::parse(r.out);
  EXPECT_EQ(doc["state"], "refused");
  EXPECT_EQ(doc["error_code"], "out_of_range");
  EXPECT_THAT(doc["reason"].get<std::string>(), HasSubstr("900"));
  r = run({"move", "joints", "--robot", "ibm7545", "--joints", "60,90,100,30", "--speed", "3"});
  EXPECT_EQ(r.code, kExitUsage);
  EXPECT_THAT(r.err, HasSubstr("--speed must be in (0, 1]"));
}

}  // namespace
}  // namespace cell::cellctl
