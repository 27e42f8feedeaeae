// cellctl calibrate / calibration against an in-process cell-calibration on a private bus, with
// a store in a temporary directory and board images rendered through the 7545 camera's TRUE
// model (config/cameras/ibm7545_eye.yaml).
#include <unistd.h>

#include <filesystem>
#include <fstream>

#include <fmt/format.h>
#include <gmock/gmock.h>
#include <gtest/gtest.h>
#include <nlohmann/json.hpp>
#include <opencv2/imgcodecs.hpp>

#include "calibration_service.hpp"
#include "cell/render/camera_file.hpp"
#include "cell/render/renderer.hpp"
#include "cell/testing/env.hpp"
#include "cell/testing/service_harness.hpp"
#include "cli_run.hpp"
#include "session.hpp"

namespace cell::cellctl {
namespace {

using nlohmann::json;
using testing::cellctl;
using testing::CliRun;
using ::testing::HasSubstr;

/// `count` views of a 17 x 12 board of 6 mm squares (18 x 13 squares) held in front of the
/// camera at 420 mm, tilted every way, written as PNGs into `dir`.
void write_board_images(const std::filesystem::path& dir, int count, const std::string& prefix) {
  std::filesystem::create_directories(dir);
  const auto camera =
      render::load_camera(cell::testing::source_dir() + "/config/cameras/ibm7545_eye.yaml").value();
  auto renderer = render::Renderer::create(camera.truth.model, render::Lighting{}).value();
  for (int i = 0; i < count; ++i) {
    render::Chessboard board;
    board.id = "b";
    board.squares_x = 18;
    board.squares_y = 13;
    board.square_mm = 6.0;
    const double tx = (i % 2 == 0 ? 1 : -1) * (0.45 + 0.03 * (i % 5));
    const double ty = ((i / 2) % 2 == 0 ? 1 : -1) * (0.35 + 0.03 * (i % 3));
    const Eigen::Matrix3d facing = Eigen::Vector3d(1.0, -1.0, -1.0).asDiagonal();
    const Eigen::Matrix3d r =
        Eigen::AngleAxisd(0.2 * (i % 3 - 1), Eigen::Vector3d::UnitZ()).toRotationMatrix() *
        facing * Eigen::AngleAxisd(tx, Eigen::Vector3d::UnitX()).toRotationMatrix() *
        Eigen::AngleAxisd(ty, Eigen::Vector3d::UnitY()).toRotationMatrix();
    Eigen::Isometry3d camera_T_board = Eigen::Isometry3d::Identity();
    camera_T_board.linear() = r;
    camera_T_board.translation() = Eigen::Vector3d(6.0 * (i % 3 - 1), 5.0 * (i % 2), 420.0) -
                                   r * Eigen::Vector3d(54.0, 39.0, 0.0);
    board.world_T_board = camera_T_board;
    render::Scene scene;
    scene.table_height_mm = -5000.0;
    scene.lights.fluorescent_on = false;
    scene.targets.push_back(board);
    render::RenderOptions options;
    options.noise_sigma = 1.0;
    options.seed = static_cast<std::uint64_t>(i);
    cv::Mat image;
    ASSERT_TRUE(renderer.render(scene, Eigen::Isometry3d::Identity(), options, image));
    cv::imwrite((dir / fmt::format("{}{:02d}.png", prefix, i)).string(), image);
  }
}

class CellctlCalibrateTest : public ::testing::Test {
 protected:
  static calibration_service::CalibrationConfig config(const std::string& store) {
    const std::string yaml = fmt::format(
        "service: {{id: calibration}}\nstore_dir: {}\nrobots_dir: {}/config/robots\n"
        "cameras:\n  - {{camera_file: {}/config/cameras/ibm7545_eye.yaml, working_plane_z_mm: "
        "-231.51}}\n",
        store, cell::testing::source_dir(), cell::testing::source_dir());
    auto c = calibration_service::load_config(*config::load_string(yaml, "calibration.yaml"));
    EXPECT_TRUE(c) << c.error().message;
    return *c;
  }

  CellctlCalibrateTest()
      : domain_(cell::testing::test_domain_id()),
        partition_(cell::testing::unique_partition()),
        dir_(std::filesystem::temp_directory_path() /
             fmt::format("cellctl-calib-{}-{}", getpid(), ++counter_)),
        service_(domain_, partition_, config((dir_ / "store").string()), "calibration") {}
  ~CellctlCalibrateTest() override {
    std::error_code ec;
    std::filesystem::remove_all(dir_, ec);
  }

  CliRun run(std::vector<std::string> args) {
    std::vector<std::string> all{"--domain", std::to_string(domain_), "--partition", partition_,
                                 "--timeout", "10"};
    all.insert(all.end(), args.begin(), args.end());
    return cellctl(all);
  }

  static inline int counter_ = 0;
  std::uint32_t domain_;
  std::string partition_;
  std::filesystem::path dir_;
  cell::testing::ServiceHarness<calibration_service::CalibrationConfig,
                                calibration_service::CalibrationService>
      service_;
};

// The JSON: fx, fy, cx, cy [px], distortion, RMS and hold-out RMS [px], the views used
// and rejected (with the reason).
TEST_F(CellctlCalibrateTest, IntrinsicsJsonCarriesTheModelTheFiguresAndTheViews) {
  write_board_images(dir_ / "images", 12, "v");
  cv::imwrite((dir_ / "images" / "v05b_blank.png").string(),
              cv::Mat(484, 512, CV_8UC1, cv::Scalar(20)));
  const CliRun r = run({"--json", "calibrate", "intrinsics", "--images", (dir_ / "images").string(),
                        "--board", "17x12", "--square", "6", "--camera", "ibm7545_eye"});
  ASSERT_EQ(r.code, kExitOk) << r.err << r.out;
  const json j = json::parse(r.out);
  EXPECT_TRUE(j["accepted"]);
  EXPECT_TRUE(j["stored"]);
  EXPECT_THAT(j["version"].get<std::string>(), ::testing::EndsWith("#1"));
  // The truth: fx 1502.3, fy 1455.9 (12 views: 0.5 % is plenty).
  EXPECT_NEAR(j["fx_px"].get<double>(), 1502.3, 1502.3 * 0.005);
  EXPECT_NEAR(j["fy_px"].get<double>(), 1455.9, 1455.9 * 0.005);
  EXPECT_NEAR(j["cx_px"].get<double>(), 258.4, 10.0);
  EXPECT_NEAR(j["cy_px"].get<double>(), 237.2, 10.0);
  EXPECT_EQ(j["distortion_k1_k2_p1_p2_k3"].size(), 5U);
  EXPECT_NEAR(j["distortion_k1_k2_p1_p2_k3"][0].get<double>(), -0.12, 0.05);
  EXPECT_GT(j["rms_px"].get<double>(), 0.0);
  EXPECT_LT(j["rms_px"].get<double>(), 0.2);
  EXPECT_GT(j["holdout_rms_px"].get<double>(), 0.0);
  EXPECT_EQ(j["views"]["used"].size() + j["views"]["held_out"].size(), 12U);
  ASSERT_EQ(j["views"]["rejected"].size(), 1U);
  EXPECT_EQ(j["views"]["rejected"][0]["id"], "v05b_blank.png");
  EXPECT_THAT(j["views"]["rejected"][0]["reason"].get<std::string>(), HasSubstr("no chessboard"));
  // Human output and progress.
  const CliRun human = run({"calibrate", "intrinsics", "--images", (dir_ / "images").string(),
                            "--board", "17x12", "--square", "6", "--dry-run"});
  ASSERT_EQ(human.code, kExitOk) << human.err;
  EXPECT_THAT(human.out, HasSubstr("fx "));
  EXPECT_THAT(human.out, HasSubstr("not stored"));
  EXPECT_THAT(human.err, HasSubstr("detect"));
  EXPECT_THAT(human.err, HasSubstr("/13"));  // 13 files: a bar of 13 steps
}

// Bad input: a clear error, and the current calibration stays.
TEST_F(CellctlCalibrateTest, BadInputIsAClearErrorAndTheCurrentCalibrationStays) {
  write_board_images(dir_ / "good", 8, "g");
  ASSERT_EQ(run({"calibrate", "intrinsics", "--images", (dir_ / "good").string(), "--board",
                 "17x12", "--square", "6", "--camera", "ibm7545_eye"})
                .code,
            kExitOk);
  std::filesystem::create_directories(dir_ / "blank");
  for (int i = 0; i < 4; ++i) {
    cv::imwrite((dir_ / "blank" / fmt::format("b{}.png", i)).string(),
                cv::Mat(484, 512, CV_8UC1, cv::Scalar(60 + 30 * i)));
  }
  CliRun r = run({"calibrate", "intrinsics", "--images", (dir_ / "blank").string(), "--board",
                  "17x12", "--square", "6", "--camera", "ibm7545_eye"});
  EXPECT_EQ(r.code, kExitFailure);
  EXPECT_THAT(r.err, HasSubstr("no chessboard 17x12 inner corners, 6 mm squares found in any of "
                               "the 4 images"));
  EXPECT_THAT(r.err, HasSubstr("the current calibration stays"));
  write_board_images(dir_ / "few", 3, "f");
  r = run({"calibrate", "intrinsics", "--images", (dir_ / "few").string(), "--board", "17x12",
           "--square", "6", "--camera", "ibm7545_eye"});
  EXPECT_EQ(r.code, kExitFailure);
  EXPECT_THAT(r.err, HasSubstr("too few views: 3 given"));
  write_board_images(dir_ / "mixed", 3, "m");
  cv::imwrite((dir_ / "mixed" / "z_other.png").string(), cv::Mat(480, 640, CV_8UC1, cv::Scalar(90)));
  r = run({"calibrate", "intrinsics", "--images", (dir_ / "mixed").string(), "--board", "17x12",
           "--square", "6", "--camera", "ibm7545_eye"});
  EXPECT_EQ(r.code, kExitFailure);
  EXPECT_THAT(r.err, HasSubstr("inconsistent image sizes"));
  r = run({"calibrate", "intrinsics", "--images", (dir_ / "none").string(), "--board", "17x12",
           "--square", "6"});
  EXPECT_EQ(r.code, kExitFailure);
  EXPECT_THAT(r.err, HasSubstr("not a readable directory"));
  // Still version 1.
  const CliRun show = run({"--json", "calibration", "show", "--camera", "ibm7545_eye"});
  ASSERT_EQ(show.code, kExitOk) << show.err;
  EXPECT_THAT(json::parse(show.out)["version"].get<std::string>(), ::testing::EndsWith("#1"));
  // Usage errors exit 2 and say what was wrong.
  r = run({"calibrate", "intrinsics", "--images", (dir_ / "good").string(), "--board", "17by12",
           "--square", "6"});
  EXPECT_EQ(r.code, kExitUsage);
  EXPECT_THAT(r.err, HasSubstr("COLUMNSxROWS"));
  r = run({"calibrate", "hand-eye", "--camera", "no_such_cam"});
  EXPECT_EQ(r.code, kExitFailure);
  EXPECT_THAT(r.err, HasSubstr("unknown camera 'no_such_cam' (known: ibm7545_eye)"));
}

TEST_F(CellctlCalibrateTest, HandEyeOnNominalIntrinsicsIsRefusedWithTheWayOut) {
  CliRun r = run({"calibrate", "hand-eye", "--camera", "ibm7545_eye", "--images",
                  (dir_ / "data").string(), "--board", "9x6", "--square", "10"});
  EXPECT_EQ(r.code, kExitFailure);
  EXPECT_THAT(r.err, HasSubstr("nominal intrinsics: calibrate them first"));
  r = run({"calibrate", "hand-eye", "--camera", "ibm7545_eye"});
  EXPECT_EQ(r.code, kExitFailure);
  EXPECT_THAT(r.err, HasSubstr("no guided procedure for camera 'ibm7545_eye'"));
  const CliRun c = run({"calibration", "cancel"});
  EXPECT_EQ(c.code, kExitFailure);
  EXPECT_THAT(c.err, HasSubstr("nothing is running"));
}

TEST_F(CellctlCalibrateTest, ListShowAndRollback) {
  write_board_images(dir_ / "a", 8, "a");
  write_board_images(dir_ / "b", 10, "b");
  ASSERT_EQ(run({"calibrate", "intrinsics", "--images", (dir_ / "a").string(), "--board", "17x12",
                 "--square", "6", "--camera", "ibm7545_eye"})
                .code,
            kExitOk);
  ASSERT_EQ(run({"calibrate", "intrinsics", "--images", (dir_ / "b").string(), "--board", "17x12",
                 "--square", "6", "--camera", "ibm7545_eye"})
                .code,
            kExitOk);
  CliRun list = run({"--json", "calibration", "list"});
  ASSERT_EQ(list.code, kExitOk) << list.err;
  json l = json::parse(list.out);
  ASSERT_EQ(l.size(), 2U);
  EXPECT_FALSE(l[0]["current"]);
  EXPECT_TRUE(l[1]["current"]);
  const std::string first = l[0]["version"];
  const CliRun back = run({"calibration", "rollback", "--camera", "ibm7545_eye", "--version", "1"});
  ASSERT_EQ(back.code, kExitOk) << back.err;
  EXPECT_THAT(back.out, HasSubstr("is back at " + first));
  const CliRun show = run({"--json", "calibration", "show", "--camera", "ibm7545_eye"});
  EXPECT_EQ(json::parse(show.out)["version"], first);
  list = run({"calibration", "list", "--camera", "ibm7545_eye"});
  EXPECT_THAT(list.out, HasSubstr("*"));
  EXPECT_THAT(list.out, HasSubstr("2 stored calibration versions"));
  const CliRun bad = run({"calibration", "rollback", "--camera", "ibm7545_eye", "--version", "9"});
  EXPECT_EQ(bad.code, kExitFailure);
  EXPECT_THAT(bad.err, HasSubstr("has no version '9'"));
}

}  // namespace
}  // namespace cell::cellctl
