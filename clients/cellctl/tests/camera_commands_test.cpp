// cellctl camera grab against in-process services on a private bus: cell-sim-world (the
// thesis's table of 15 ICs), the 7545's gateway (ideal robot at the image-grab pose) and the
// 7545's simulated eye-in-hand camera.
#include <unistd.h>

#include <filesystem>
#include <fstream>
#include <thread>

#include <fmt/format.h>
#include <gmock/gmock.h>
#include <gtest/gtest.h>
#include <nlohmann/json.hpp>
#include <opencv2/imgcodecs.hpp>

#include "camera_service.hpp"
#include "cell/testing/env.hpp"
#include "cell/testing/service_harness.hpp"
#include "cli_run.hpp"
#include "gateway_service.hpp"
#include "session.hpp"
#include "sim_world_service.hpp"

namespace cell::cellctl {
namespace {

using nlohmann::json;
using testing::cellctl;
using testing::CliRun;
using ::testing::HasSubstr;

class CellctlCameraTest : public ::testing::Test {
 protected:
  static sim_world::SimWorldConfig world_config() {
    sim_world::SimWorldConfig c;
    c.common.service_id = "sim-world";
    c.scene = cell::testing::source_dir() + "/config/scenes/table_ics.yaml";
    c.world.robots = {{"ibm7545", Eigen::Isometry3d(Eigen::Translation3d(0, 0, 981.51))}};
    return c;
  }
  static gateway::GatewayConfig gateway_config() {
    const std::string yaml = fmt::format(
        "service: {{id: gateway.ibm7545}}\n"
        "robot_config: {}/config/robots/ibm7545.yaml\n"
        "driver: {{kind: ideal, initial_joints: [45, 105, 0, 0], gripper_time_s: 0.05}}\n",
        cell::testing::source_dir());
    return gateway::load_config(*config::load_string(yaml, "gateway.yaml")).value();
  }
  static camera::CameraConfig camera_config() {
    const std::string home = cell::testing::source_dir();
    const std::string yaml = fmt::format(
        "service: {{id: camera.ibm7545_eye}}\ncamera_id: ibm7545_eye\nsource: sim\n"
        "camera_file: {0}/config/cameras/ibm7545_eye.yaml\n"
        "sim: {{noise_sigma: 2.0, robot_config: {0}/config/robots/ibm7545.yaml}}\n",
        home);
    return camera::load_config(*config::load_string(yaml, "camera.yaml")).value();
  }

  CellctlCameraTest()
      : domain_(cell::testing::test_domain_id()),
        partition_(cell::testing::unique_partition()),
        dir_(std::filesystem::temp_directory_path() /
             fmt::format("cellctl-camera-{}-{}", getpid(), ++counter_)),
        world_(domain_, partition_, world_config(), "sim-world"),
        gateway_(domain_, partition_, gateway_config(), "gateway"),
        camera_(domain_, partition_, camera_config(), "camera") {
    std::filesystem::create_directories(dir_);
  }
  ~CellctlCameraTest() override {
    std::error_code ec;
    std::filesystem::remove_all(dir_, ec);
  }

  CliRun run(std::vector<std::string> args) {
    std::vector<std::string> all{"--domain", std::to_string(domain_), "--partition", partition_,
                                 "--timeout", "10"};
    all.insert(all.end(), args.begin(), args.end());
    return cellctl(all);
  }
  std::string file(const std::string& name) const { return (dir_ / name).string(); }

  static inline int counter_ = 0;
  std::uint32_t domain_;
  std::string partition_;
  std::filesystem::path dir_;
  cell::testing::ServiceHarness<sim_world::SimWorldConfig, sim_world::SimWorldService> world_;
  cell::testing::ServiceHarness<gateway::GatewayConfig, gateway::GatewayService> gateway_;
  cell::testing::ServiceHarness<camera::CameraConfig, camera::CameraService> camera_;
};

// Digest 000 §7: about 15 ICs fit in the window at the image-grab pose.
TEST_F(CellctlCameraTest, GrabSavesTheFrameAndTheTruthOfEveryVisiblePart) {
  // The 7545's relays start with every light off (digest 000 §2.5): switch the tubes on.
  const CliRun lights = run({"robot", "lights", "--robot", "ibm7545", "--fluorescent"});
  ASSERT_EQ(lights.code, kExitOk) << lights.err;
  std::this_thread::sleep_for(std::chrono::milliseconds(200));  // the state stream reports it
  const CliRun r = run({"--json", "camera", "grab", "--camera", "ibm7545_eye", "-o",
                        file("frame.png"), "--truth", file("truth.json")});
  ASSERT_EQ(r.code, kExitOk) << r.err;
  const json report = json::parse(r.out);
  EXPECT_EQ(report["camera"], "ibm7545_eye");
  EXPECT_EQ(report["width_px"], 512);
  EXPECT_EQ(report["height_px"], 484);
  EXPECT_EQ(report["encoding"], "mono8");
  EXPECT_EQ(report["robot_id"], "ibm7545");
  EXPECT_NEAR(report["robot_joints"][1]["value"].get<double>(), 105.0, 1e-6);  // deg
  EXPECT_EQ(report["parts"], 15);
  const cv::Mat image = cv::imread(file("frame.png"), cv::IMREAD_UNCHANGED);
  ASSERT_EQ(image.type(), CV_8UC1);
  ASSERT_EQ(image.cols, 512);
  // Under the tubes the white table stays above the thesis's threshold of 150.
  EXPECT_GT(cv::mean(image(cv::Rect(0, 0, 40, 40)))[0], 150.0);
  std::ifstream in(file("truth.json"));
  const json truth = json::parse(in);
  EXPECT_EQ(truth["camera_id"], "ibm7545_eye");
  EXPECT_EQ(truth["stamp_ns"], report["stamp_ns"]);
  EXPECT_NEAR(truth["true_camera"]["world_T_camera"]["z_mm"].get<double>(), 1170.0, 5.0);
  ASSERT_EQ(truth["parts"].size(), 15U);
  // Each part is where the truth says: its top centre is black IC body in the saved image,
  // and its corners are table-white just outside.
  for (const auto& p : truth["parts"]) {
    const int u = static_cast<int>(std::lround(p["center_px"]["u_px"].get<double>()));
    const int v = static_cast<int>(std::lround(p["center_px"]["v_px"].get<double>()));
    ASSERT_TRUE(u >= 0 && v >= 0 && u < 512 && v < 484) << p["part_id"];
    EXPECT_LT(image.at<std::uint8_t>(v, u), 60) << p["part_id"];
    EXPECT_EQ(p["corners_px"].size(), 4U);
    EXPECT_DOUBLE_EQ(p["visible_fraction"].get<double>(), 1.0) << p["part_id"];
    EXPECT_NEAR(p["world_T_part"]["z_mm"].get<double>(), 750.0, 1e-6);
  }
}

// The lights come from the gateway's RobotState: switched off, the next frame is dark. The
// camera learns a switch from the state stream (100 Hz), so each grab waits 0.2 s after it.
TEST_F(CellctlCameraTest, TheGatewaysLightsLightTheFrame) {
  auto background = [&](const std::string& name) {
    std::this_thread::sleep_for(std::chrono::milliseconds(200));
    const CliRun r = run({"camera", "grab", "--camera", "ibm7545_eye", "-o", file(name)});
    EXPECT_EQ(r.code, kExitOk) << r.err;
    return cv::mean(cv::imread(file(name), cv::IMREAD_UNCHANGED)(cv::Rect(0, 0, 40, 40)))[0];
  };
  ASSERT_EQ(run({"robot", "lights", "--robot", "ibm7545", "--fluorescent", "--halogen"}).code,
            kExitOk);
  const double both = background("both.png");
  ASSERT_EQ(run({"robot", "lights", "--robot", "ibm7545", "--fluorescent"}).code, kExitOk);
  const double tubes = background("tubes.png");
  ASSERT_EQ(run({"robot", "lights", "--robot", "ibm7545"}).code, kExitOk);
  const double dark = background("dark.png");
  EXPECT_GT(both, tubes + 5.0) << "both " << both << " tubes " << tubes << " dark " << dark;
  EXPECT_GT(tubes, 150.0);
  EXPECT_LT(dark, 40.0);
}

TEST_F(CellctlCameraTest, RefusalsAndBadArgumentsSayWhat) {
  CliRun r = run({"camera", "grab", "--camera", "nope", "-o", file("x.png")});
  EXPECT_EQ(r.code, kExitFailure);
  EXPECT_THAT(r.err, HasSubstr("unknown camera 'nope'"));
  r = run({"camera", "grab", "--camera", "ibm7545_eye", "-o", file("x.png"), "--trigger",
           "photocell"});
  EXPECT_EQ(r.code, kExitFailure);
  EXPECT_THAT(r.err, HasSubstr("has no photocell"));
  r = run({"camera", "grab", "--camera", "ibm7545_eye", "-o", file("x.doc")});
  EXPECT_EQ(r.code, kExitUsage);
  EXPECT_THAT(r.err, HasSubstr("cannot write this image format"));
  r = run({"camera", "grab", "--camera", "ibm7545_eye", "-o", file("x.png"), "--trigger", "soon"});
  EXPECT_EQ(r.code, kExitUsage);
  EXPECT_THAT(r.err, HasSubstr("--trigger must be now or photocell"));
  r = run({"camera", "grab", "-o", file("x.png")});
  EXPECT_EQ(r.code, kExitUsage);
  EXPECT_THAT(r.err, HasSubstr("--camera"));
  // Nobody on another partition.
  r = cellctl({"--domain", std::to_string(domain_), "--partition", partition_ + "-empty",
               "--timeout", "0.5", "camera", "grab", "--camera", "ibm7545_eye", "-o",
               file("x.png")});
  EXPECT_EQ(r.code, kExitFailure);
  EXPECT_THAT(r.err, HasSubstr("no camera service"));
}

}  // namespace
}  // namespace cell::cellctl
