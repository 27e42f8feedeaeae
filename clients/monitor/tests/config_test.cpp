// config/monitor.yaml: the shipped file loads and agrees with the world simulator's robot
// placement; mistakes are reported with file:line:col and the key.
#include "monitor_config.hpp"

#include <cstdio>
#include <fstream>

#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include "cell/testing/env.hpp"
#include "cell/testing/matchers.hpp"

namespace cell::monitor {
namespace {

using ::cell::testing::IsErrWith;
using ::testing::HasSubstr;

Result<MonitorConfig> from_text(const std::string& text) {
  auto doc = config::load_string(text, "monitor.yaml");
  if (!doc) {
    return std::move(doc).error();
  }
  return load_config(*doc);
}

TEST(MonitorConfig, TheShippedFileLoadsAndPlacesRobotsAsTheWorldSimulatorDoes) {
  auto doc = config::load_file(cell::testing::source_dir() + "/config/monitor.yaml");
  ASSERT_TRUE(doc) << doc.error().message;
  auto config = load_config(*doc);
  ASSERT_TRUE(config) << config.error().message;
  EXPECT_EQ(config->bind_address, "127.0.0.1");  // localhost only by default
  EXPECT_GT(config->port, 0);
  ASSERT_FALSE(config->robots.empty());
  ASSERT_FALSE(config->job_templates.empty());
  for (const auto& t : config->job_templates) {
    EXPECT_FALSE(t.kind.empty()) << t.name;
    EXPECT_FALSE(t.spec_yaml.empty()) << t.name;
  }
  // Each robot where config/sim-world.yaml puts it.
  auto world = config::load_file(cell::testing::source_dir() + "/config/sim-world.yaml");
  ASSERT_TRUE(world);
  for (const auto& robot : config->robots) {
    bool found = false;
    for (const auto& r : world->root["robots"]) {
      if (r["id"].as<std::string>() != robot.id) {
        continue;
      }
      found = true;
      const auto xyz = r["xyz_mm"].as<std::vector<double>>();
      for (int i = 0; i < 3; ++i) {
        EXPECT_NEAR(robot.world_T_base.translation()[i], xyz[static_cast<std::size_t>(i)], 1e-9)
            << robot.id;
      }
    }
    EXPECT_TRUE(found) << robot.id << " is not in config/sim-world.yaml";
  }
}

TEST(MonitorConfig, ReportsEveryMistakeWithItsLocation) {
  auto c = from_text(
      "http: {port: 70000, bind: 127.0.0.1, colour: red}\n"
      "stream: {robot_hz: 0}\n"
      "auth:\n"
      "  users:\n"
      "    - {name: ada, role: admin, password_hash: plain}\n"
      "robots:\n"
      "  - {id: ibm7545, xyz_mm: [0, 0]}\n"
      "job_templates:\n"
      "  - {name: t, kind: juggling}\n");
  ASSERT_FALSE(c);
  const std::string& m = c.error().message;
  EXPECT_EQ(c.error().code, Errc::kConfig);
  EXPECT_THAT(m, HasSubstr("monitor.yaml:1:"));
  EXPECT_THAT(m, HasSubstr("port"));
  EXPECT_THAT(m, HasSubstr("colour"));
  EXPECT_THAT(m, HasSubstr("robot_hz"));
  EXPECT_THAT(m, HasSubstr("must be operator or viewer"));
  EXPECT_THAT(m, HasSubstr("cell-monitor --hash-password"));
  EXPECT_THAT(m, HasSubstr("xyz_mm"));
  EXPECT_THAT(m, HasSubstr("juggling"));
}

TEST(MonitorConfig, AJobTemplateTakesItsKindAndRobotFromItsJobFile) {
  const std::string path = ::testing::TempDir() + "/monitor_config_test_job.yaml";
  std::ofstream(path) << "kind: table_pick_place\nrobot: ibm7545\ncamera: ibm7545_eye\n"
                         "max_parts: 3\n";
  auto c = from_text(
      "robots: [{id: ibm7545, xyz_mm: [0, 0, 981.51]}]\n"
      "job_templates:\n"
      "  - {name: ics, spec_file: " + path + "}\n"
      "  - {name: missing, spec_file: /nonexistent/no_such_job.yaml}\n");
  ASSERT_FALSE(c);
  EXPECT_THAT(c.error().message, HasSubstr("no_such_job.yaml"));
  auto ok = from_text(
      "robots: [{id: ibm7545, xyz_mm: [0, 0, 981.51]}]\n"
      "job_templates:\n"
      "  - {name: ics, spec_file: " + path + "}\n");
  ASSERT_TRUE(ok) << ok.error().message;
  const JobTemplate& t = ok->job_templates.at(0);
  EXPECT_EQ(t.kind, "table_pick_place");
  EXPECT_EQ(t.robot_id, "ibm7545");
  EXPECT_EQ(t.camera_id, "ibm7545_eye");
  EXPECT_THAT(t.spec_yaml, HasSubstr("max_parts: 3"));
  std::remove(path.c_str());
}

}  // namespace
}  // namespace cell::monitor
