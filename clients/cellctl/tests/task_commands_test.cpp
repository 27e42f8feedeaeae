// cellctl task record|play|show|delete|move|rename against an in-process gateway (ideal IBM
// 7545) and motion service on a private bus, and cellctl completion bash run through bash.
#include <unistd.h>

#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <sstream>

#include <fmt/format.h>
#include <gmock/gmock.h>
#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

#include "cell/testing/env.hpp"
#include "cell/testing/service_harness.hpp"
#include "cli_run.hpp"
#include "gateway_service.hpp"
#include "motion_service.hpp"
#include "session.hpp"

namespace cell::cellctl {
namespace {

using ::testing::HasSubstr;
using nlohmann::json;
using testing::CliRun;
using testing::cellctl;
using testing::value_of;

// The gateway's start tolerance (config/gateway-*.yaml start_tolerance_deg / _mm: 0.5): a
// played-back pose is reached when the robot is this close to the recorded joints.
constexpr double kTolDeg = 0.5;
constexpr double kTolMm = 0.5;


class CellctlTaskTest : public ::testing::Test {
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

  CellctlTaskTest()
      : domain_(cell::testing::test_domain_id()),
        partition_(cell::testing::unique_partition()),
        dir_(::testing::TempDir() + "/cellctl-task-" + partition_),
        gateway_(domain_, partition_, gateway_config(), "gateway"),
        motion_(domain_, partition_, motion_config(), "motion") {
    std::filesystem::create_directories(dir_);
  }
  ~CellctlTaskTest() override { std::filesystem::remove_all(dir_); }

  CliRun run(std::vector<std::string> args) {
    std::vector<std::string> all{"--domain", std::to_string(domain_), "--partition", partition_,
                                 "--timeout", "5"};
    all.insert(all.end(), args.begin(), args.end());
    return cellctl(all);
  }

  json state() {
    const CliRun r = run({"--json", "robot", "state", "--robot", "ibm7545"});
    EXPECT_EQ(r.code, kExitOk) << r.err;
    return json::parse(r.out, nullptr, false);
  }

  void move_to(const std::string& joints) {
    const CliRun r = run({"move", "joints", "--robot", "ibm7545", "--joints", joints});
    ASSERT_EQ(r.code, kExitOk) << r.err;
  }

  std::uint32_t domain_;
  std::string partition_;
  std::string dir_;
  cell::testing::ServiceHarness<gateway::GatewayConfig, gateway::GatewayService> gateway_;
  cell::testing::ServiceHarness<motion_service::MotionConfig, motion_service::MotionService>
      motion_;
};

TEST_F(CellctlTaskTest, RecordsTheLivePosesAndPlaysThemBackToThoseJoints) {
  ASSERT_EQ(run({"robot", "home", "--robot", "ibm7545"}).code, kExitOk);
  const std::string file = dir_ + "/pick.yaml";
  // A new file needs the robot.
  CliRun r = run({"task", "record", file});
  EXPECT_EQ(r.code, kExitUsage);
  EXPECT_THAT(r.err, HasSubstr("does not exist: give --robot"));
  // Teach: three poses with a gripper step and a wait between them.
  move_to("40,100,150,30");
  r = run({"task", "record", file, "--robot", "ibm7545", "--name", "above"});
  ASSERT_EQ(r.code, kExitOk) << r.err;
  EXPECT_THAT(r.out, HasSubstr("step 1 of 1: pose 'above' at j1=40.000 deg"));
  move_to("40,100,200,30");
  ASSERT_EQ(run({"task", "record", file, "--move", "line"}).code, kExitOk);  // named p2
  ASSERT_EQ(run({"task", "record", file, "--gripper", "close"}).code, kExitOk);
  ASSERT_EQ(run({"task", "record", file, "--wait-s", "0.2"}).code, kExitOk);
  move_to("100,60,120,-15");
  r = run({"--json", "task", "record", file, "--name", "slot"});
  ASSERT_EQ(r.code, kExitOk) << r.err;
  EXPECT_EQ(json::parse(r.out)["steps"], 5);
  // The live pose, as RobotState says it: the arm at its target to the state's last sample
  // (micro-degrees on a loaded machine), the same 1e-3 as the state checks below.
  EXPECT_NEAR(value_of(json::parse(r.out)["recorded"]["joints"], "r"), -15.0, 1e-3);

  // The file is plain YAML with the units in its keys, and loads back.
  std::ifstream in(file);
  std::stringstream text;
  text << in.rdbuf();
  // (The values are the live ones, to the 1e-3 above: a pose recorded a moment before the
  // arm settled to the micro-degree reads 149.999805 mm, so the file is checked for its keys
  // and the values after loading it back.)
  EXPECT_THAT(text.str(), HasSubstr("joints: {j1_deg: "));
  EXPECT_THAT(text.str(), HasSubstr(", z_mm: "));
  EXPECT_THAT(text.str(), HasSubstr("gripper: close"));
  r = run({"--json", "task", "show", file});
  ASSERT_EQ(r.code, kExitOk) << r.err;
  const json shown = json::parse(r.out);
  ASSERT_EQ(shown["steps"].size(), 5U);
  EXPECT_NEAR(value_of(shown["steps"][0]["joints"], "j1"), 40.0, 1e-3);
  EXPECT_NEAR(value_of(shown["steps"][0]["joints"], "z"), 150.0, 1e-3);
  EXPECT_NEAR(value_of(shown["steps"][1]["joints"], "z"), 200.0, 1e-3);
  EXPECT_EQ(shown["steps"][1]["name"], "p2");
  EXPECT_EQ(shown["steps"][1]["move"], "line");
  EXPECT_EQ(shown["steps"][3]["wait_s"], 0.2);

  // Off line: planned, timed, and the arm does not move.
  r = run({"--json", "task", "play", file, "--preview"});
  ASSERT_EQ(r.code, kExitOk) << r.err;
  const json preview = json::parse(r.out);
  EXPECT_GT(preview["duration_s"].get<double>(), 1.0);
  EXPECT_NEAR(value_of(preview["steps"][4]["joints"], "j1"), 100.0, 1e-3);
  EXPECT_NEAR(value_of(state()["joints"], "j1"), 100.0, 1e-3);  // still where it was

  // On the robot, from somewhere else: it ends on the recorded poses.
  move_to("150,30,10,90");
  r = run({"--json", "task", "play", file, "--to", "2"});
  ASSERT_EQ(r.code, kExitOk) << r.err;
  json s = state();
  EXPECT_NEAR(value_of(s["joints"], "j1"), 40.0, kTolDeg);
  EXPECT_NEAR(value_of(s["joints"], "z"), 200.0, kTolMm);
  r = run({"--json", "task", "play", file, "--from", "3"});
  ASSERT_EQ(r.code, kExitOk) << r.err;
  const json report = json::parse(r.out);
  EXPECT_TRUE(report["ok"].get<bool>());
  EXPECT_EQ(report["steps_done"], 3);
  s = state();
  EXPECT_EQ(s["gripper"], "closed");
  EXPECT_NEAR(value_of(s["joints"], "j1"), 100.0, kTolDeg);
  EXPECT_NEAR(value_of(s["joints"], "j2"), 60.0, kTolDeg);
  EXPECT_NEAR(value_of(s["joints"], "z"), 120.0, kTolMm);
  EXPECT_NEAR(value_of(s["joints"], "r"), -15.0, kTolDeg);
  // And backward: undoes the steps, so the arm returns to the first pose, the gripper open.
  r = run({"task", "play", file, "--backward"});
  ASSERT_EQ(r.code, kExitOk) << r.err;
  s = state();
  EXPECT_EQ(s["gripper"], "open");
  EXPECT_NEAR(value_of(s["joints"], "z"), 150.0, kTolMm);
}

TEST_F(CellctlTaskTest, EditsAndMistakesNameWhatWasWrong) {
  const std::string file = dir_ + "/edit.yaml";
  // No gateway homing needed: gripper steps and waits need no robot state.
  ASSERT_EQ(run({"task", "record", file, "--robot", "ibm7545", "--gripper", "open"}).code,
            kExitOk);
  ASSERT_EQ(run({"task", "record", file, "--wait-s", "1"}).code, kExitOk);
  ASSERT_EQ(run({"task", "record", file, "--gripper", "close", "--at", "1"}).code, kExitOk);
  CliRun r = run({"--json", "task", "show", file});
  ASSERT_EQ(r.code, kExitOk) << r.err;
  EXPECT_EQ(json::parse(r.out)["steps"][0]["action"], "close");
  ASSERT_EQ(run({"task", "move", file, "1", "3"}).code, kExitOk);
  r = run({"--json", "task", "show", file});
  EXPECT_EQ(json::parse(r.out)["steps"][2]["action"], "close");
  ASSERT_EQ(run({"task", "delete", file, "2"}).code, kExitOk);
  r = run({"--json", "task", "show", file});
  EXPECT_EQ(json::parse(r.out)["steps"].size(), 2U);

  r = run({"task", "delete", file, "9"});
  EXPECT_EQ(r.code, kExitUsage);
  EXPECT_THAT(r.err, HasSubstr("step 9 is out of range: the task has 2 steps"));
  r = run({"task", "rename", file, "1", "x"});
  EXPECT_EQ(r.code, kExitUsage);
  EXPECT_THAT(r.err, HasSubstr("not a pose: only poses have names"));
  r = run({"task", "record", file, "--gripper", "squeeze"});
  EXPECT_EQ(r.code, kExitUsage);
  EXPECT_THAT(r.err, HasSubstr("--gripper must be open or close, got 'squeeze'"));
  r = run({"task", "record", file, "--robot", "excalibur", "--wait-s", "1"});
  EXPECT_EQ(r.code, kExitUsage);
  EXPECT_THAT(r.err, HasSubstr("is a task for robot 'ibm7545', not 'excalibur'"));
  r = run({"task", "play", dir_ + "/missing.yaml"});
  EXPECT_EQ(r.code, kExitUsage);
  r = run({"task", "play", file, "--from", "3"});
  EXPECT_EQ(r.code, kExitUsage);
  EXPECT_THAT(r.err, HasSubstr("is not a range"));
  // A pose with no gateway answering for its robot: a failure that says which robot.
  const std::string other = dir_ + "/other.yaml";
  r = run({"--timeout", "1", "task", "record", other, "--robot", "excalibur"});
  EXPECT_EQ(r.code, kExitFailure);
  EXPECT_THAT(r.err, HasSubstr("no state from robot 'excalibur'"));
  EXPECT_FALSE(std::filesystem::exists(other));
  // A hand-edited file with a typo: file:line:col and the key.
  std::ofstream(dir_ + "/typo.yaml") << "task: t\nrobot: ibm7545\nsteps:\n  - gripper: clsoe\n";
  r = run({"task", "show", dir_ + "/typo.yaml"});
  EXPECT_EQ(r.code, kExitUsage);
  EXPECT_THAT(r.err, HasSubstr("typo.yaml:4:"));
  EXPECT_THAT(r.err, HasSubstr("must be open or close, got 'clsoe'"));
}

/// Completes `line` (the cursor at its end) with the script of `cellctl completion bash`.
std::string complete(const std::string& script, const std::string& line) {
  const std::string path = ::testing::TempDir() + "/cellctl-completion-" +
                           std::to_string(::getpid()) + ".bash";
  std::ofstream(path) << script;
  const std::string cmd = fmt::format(
      "bash -c 'source {}; COMP_WORDS=({}); [[ \"{}\" == *\" \" ]] && COMP_WORDS+=(\"\"); "
      "COMP_CWORD=$((${{#COMP_WORDS[@]}} - 1)); _cellctl; echo \"${{COMPREPLY[*]}}\"'",
      path, line, line);
  std::string out;
  if (FILE* p = ::popen(cmd.c_str(), "r")) {
    char buf[4096];
    while (std::fgets(buf, sizeof buf, p) != nullptr) {
      out += buf;
    }
    ::pclose(p);
  }
  std::remove(path.c_str());
  return out;
}

TEST(CellctlCompletion, BashCompletesCommandsOptionsAndTheirValuesFromTheTree) {
  const CliRun r = cellctl({"completion", "bash"});
  ASSERT_EQ(r.code, kExitOk) << r.err;
  EXPECT_THAT(r.out, HasSubstr("complete -F _cellctl cellctl"));
  EXPECT_EQ(complete(r.out, "cellctl ta"), "task\n");
  EXPECT_EQ(complete(r.out, "cellctl task pl"), "play\n");
  EXPECT_THAT(complete(r.out, "cellctl task record x.yaml --ro"), HasSubstr("--robot"));
  EXPECT_THAT(complete(r.out, "cellctl --json move "), HasSubstr("joints"));
  // An option's value is not taken for a command: `--robot move` stays under `robot`.
  EXPECT_THAT(complete(r.out, "cellctl robot home --robot move --"), HasSubstr("--robot"));
  EXPECT_THAT(complete(r.out, "cellctl completion "), HasSubstr("bash"));
  // Every command group is there.
  for (const char* group : {"ping", "kin", "move", "robot", "world", "camera", "rapt", "task"}) {
    EXPECT_THAT(complete(r.out, "cellctl "), HasSubstr(group)) << group;
  }
}

}  // namespace
}  // namespace cell::cellctl
