#include <fmt/format.h>
#include <gmock/gmock.h>
#include <gtest/gtest.h>
#include <unistd.h>

#include <chrono>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <numbers>

#include "cell/bus/reader.hpp"
#include "cell/bus/view.hpp"
#include "cell/geometry/angles.hpp"
#include "cell/kinematics/robot_config.hpp"
#include "cell/protocols/excalibur/serial_port.hpp"
#include "cell/testing/env.hpp"
#include "cell/testing/matchers.hpp"
#include "cell/testing/service_harness.hpp"
#include "sim_excalibur_service.hpp"

namespace cell::sim_excalibur {
namespace {

namespace pe = protocols::excalibur;
namespace fs = std::filesystem;
using namespace std::chrono_literals;
using ::cell::testing::IsErrWith;
using ::cell::testing::IsOk;
using ::testing::HasSubstr;
using Harness = cell::testing::ServiceHarness<SimExcaliburConfig, SimExcaliburService>;

using geometry::kDeg;

Result<SimExcaliburConfig> parse(const std::string& yaml) {
  auto doc = config::load_string(yaml, "sim.yaml");
  if (!doc) {
    return std::move(doc).error();
  }
  return load_config(*doc);
}

TEST(SimExcaliburConfig, LoadsTheShippedFileAndResolvesPaths) {
  auto doc = config::load_file(cell::testing::source_dir() + "/config/sim-excalibur.yaml");
  ASSERT_THAT(doc, IsOk());
  auto c = load_config(*doc);
  ASSERT_THAT(c, IsOk());
  EXPECT_EQ(c->robot_id, "excalibur.sim");
  EXPECT_TRUE(fs::path(c->link_path).is_absolute());
  EXPECT_THAT(c->link_path, ::testing::EndsWith("run/excalibur.pty"));
  EXPECT_DOUBLE_EQ(c->min_char_interval_ms, 1.2);
  EXPECT_EQ(c->realtime_priority, 45);
}

TEST(SimExcaliburConfig, ErrorsNameFileLineColumnAndKey) {
  auto c = parse(
      "baud: 0\ncontroller:\n  speed_scale: -1\n  limits_deg: {theta1: [90, -90], "
      "theta9: [0, 1]}\n  power_up_mode: asleep\nnoise: {probability_per_line: 2}\n"
      "colour: red\nrealtime_priority: 100\n");
  ASSERT_FALSE(c);
  const std::string& m = c.error().message;
  EXPECT_THAT(m, HasSubstr("sim.yaml:1:7: key 'baud': must be in [300, 4000000], got 0"));
  EXPECT_THAT(m, HasSubstr("key 'controller.speed_scale': must be in (0, 100], got -1"));
  EXPECT_THAT(m, HasSubstr("key 'controller.limits_deg.theta1': must be [lower, upper]"));
  EXPECT_THAT(m, HasSubstr("unknown key 'controller.limits_deg.theta9'"));
  EXPECT_THAT(m, HasSubstr("key 'controller.power_up_mode': must be host, manual"));
  EXPECT_THAT(m, HasSubstr("key 'noise.probability_per_line': must be a probability"));
  EXPECT_THAT(m, HasSubstr("unknown key 'colour'"));
  EXPECT_THAT(m, HasSubstr("key 'realtime_priority': must be 0 (none) or a SCHED_FIFO priority "
                           "1..99, got 100"));
}

TEST(SimExcaliburConfig, ControllerSettingsAreInTheControllersAngles) {
  auto c = parse(
      "controller: {initial_deg: [10, 30, -150, 5, 5, 5], speed_scale: 2, "
      "limits_deg: {theta1: [-90, 90]}}\n");
  ASSERT_THAT(c, IsOk());
  c->robot_config = cell::testing::source_dir() + "/config/robots/excalibur.yaml";
  auto model = kinematics::load_robot(c->robot_config);
  ASSERT_THAT(model, IsOk());
  auto s = controller_settings(*c, *model);
  ASSERT_THAT(s, IsOk());
  // Digest 001 case 9: (10, 30, -150, 5, 5, 5) is the controller's (10, 0, 0, 5, 5, 5).
  const pe::ControllerAngles expected = {10, 0, 0, 5, 5, 5};
  for (std::size_t j = 0; j < 6; ++j) {
    EXPECT_NEAR(s->initial_deg[j], expected[j], 1e-9) << j;
  }
  EXPECT_NEAR(s->lower_deg[0], -90.0, 1e-9);
  EXPECT_NEAR(s->lower_deg[1], -45.0 - 30.0, 1e-9);  // robot theta2 >= -45 -> theta2* >= -75
  EXPECT_NEAR(s->upper_deg[2], 90.0 + 150.0, 1e-9);  // robot theta3 <= 90 -> theta3* <= 240
  EXPECT_NEAR(s->speed_deg_s[0], 90.0, 1e-9);        // 45 deg/s x 2
}

class SimExcaliburServiceTest : public ::testing::Test {
 protected:
  SimExcaliburServiceTest()
      : dir_(fs::temp_directory_path() / fmt::format("cell-sim-excalibur-{}", ::getpid())),
        domain_(cell::testing::test_domain_id()),
        partition_(cell::testing::unique_partition()) {
    fs::create_directories(dir_);
    fs::remove(dir_ / "noise.yaml");
  }
  ~SimExcaliburServiceTest() override {
    std::error_code ec;
    fs::remove_all(dir_, ec);
  }
  SimExcaliburConfig config() const {
    auto c = parse(fmt::format(
        "robot_config: {0}/config/robots/excalibur.yaml\n"
        "dialect: {0}/config/controllers/excalibur.yaml\n"
        "link_path: {1}/excalibur.pty\nbaud: 115200\nstate_rate_hz: 50\n"
        "controller: {{initial_deg: [10, 30, -150, 5, 5, 5], min_char_interval_ms: 0.1, "
        "busy_after_line_ms: 1}}\n"
        "noise: {{control_file: {1}/noise.yaml}}\n",
        cell::testing::source_dir(), dir_.string()));
    EXPECT_THAT(c, IsOk());
    return *c;
  }

  fs::path dir_;
  std::uint32_t domain_;
  std::string partition_;
};

TEST_F(SimExcaliburServiceTest, ServesThePtyAndPublishesTheTrueAngles) {
  Harness harness(domain_, partition_, config(), "sim-excalibur");
  const std::string link = (dir_ / "excalibur.pty").string();
  ASSERT_TRUE(fs::is_symlink(link));
  EXPECT_EQ(fs::read_symlink(link).string(), harness.service().controller().slave_path());
  // The true angles on the bus, DH radians, robot_id excalibur.sim.
  bus::Participant client(domain_, partition_);
  bus::Topic<cell_robot_RobotState> topic(client, bus::topics::kRobotState);
  bus::Reader<cell_robot_RobotState> reader(client, topic, bus::topics::kRobotState);
  std::vector<double> q;
  ASSERT_TRUE(cell::testing::eventually(
      [&] {
        reader.wait_for_data(50ms);
        auto batch = reader.take_copies(64);
        for (auto& s : *batch) {
          if (bus::str(s->robot_id) == "excalibur.sim") {
            q = bus::to_vector(s->position_rad_or_mm);
          }
        }
        return q.size() == 6;
      },
      5s));
  const double expected[] = {10, 30, -150, 5, 5, 5};
  for (std::size_t j = 0; j < 6; ++j) {
    EXPECT_NEAR(q[j], expected[j] * kDeg, 1e-9) << j;
  }
  // The controller answers on its pty, in controller angles.
  const pe::Dialect dialect =
      *pe::Dialect::load(cell::testing::source_dir() + "/config/controllers/excalibur.yaml");
  pe::SerialOptions o;
  o.device = link;
  o.baud = 115200;
  o.emulate_baud = true;
  o.char_delay_s = dialect.timing().char_delay_s;  // the 6809 needs 0.1 ms per character here
  auto port =
      pe::SerialPort::open(o, [&](std::string_view l) { return dialect.looks_unsolicited(l); });
  ASSERT_THAT(port, IsOk());
  std::this_thread::sleep_for(50ms);
  (*port)->discard_replies();
  ASSERT_THAT((*port)->write_line(*dialect.format(pe::Command{}) + "\r"), IsOk());
  auto reply = (*port)->wait_reply(2s);
  ASSERT_THAT(reply, IsOk());
  auto m = dialect.parse(reply->text);
  ASSERT_THAT(m, IsOk());
  EXPECT_EQ(m->kind, pe::MessageKind::kJoints);
  EXPECT_EQ(m->angles_deg, (pe::ControllerAngles{10, 0, 0, 5, 5, 5}));
}

TEST_F(SimExcaliburServiceTest, TheControlFileSwitchesNoiseAtRunTime) {
  Harness harness(domain_, partition_, config(), "sim-excalibur");
  auto& sim = harness.service().controller();
  EXPECT_DOUBLE_EQ(sim.noise().probability_per_line, 0.0);
  {
    std::ofstream out(dir_ / "noise.yaml");
    out << "probability_per_line: 0.25\nmove_not_achieved_probability: 0.5\n";
  }
  EXPECT_TRUE(
      cell::testing::eventually([&] { return sim.noise().probability_per_line == 0.25; }, 3s));
  fs::remove(dir_ / "noise.yaml");
  EXPECT_TRUE(
      cell::testing::eventually([&] { return sim.noise().probability_per_line == 0.0; }, 3s));
  EXPECT_THAT(load_noise_control((dir_ / "missing.yaml").string()),
              IsErrWith(Errc::kConfig, "cannot open"));
}

}  // namespace
}  // namespace cell::sim_excalibur
