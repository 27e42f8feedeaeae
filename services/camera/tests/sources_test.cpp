#include "sources.hpp"

#include <unistd.h>

#include <filesystem>
#include <fstream>

#include <fmt/format.h>
#include <gmock/gmock.h>
#include <gtest/gtest.h>
#include <opencv2/imgcodecs.hpp>

#include "cell/config/yaml.hpp"
#include "cell/testing/env.hpp"
#include "cell/testing/matchers.hpp"
#include "config_fixtures.hpp"

namespace cell::camera {
namespace {

using ::cell::testing::IsErrWith;
using ::testing::HasSubstr;

/// A fresh temporary directory, removed afterwards.
class TempDir {
 public:
  TempDir() {
    path_ = std::filesystem::temp_directory_path() /
            fmt::format("camera-test-{}-{}", getpid(), counter_++);
    std::filesystem::create_directories(path_);
  }
  ~TempDir() {
    std::error_code ec;
    std::filesystem::remove_all(path_, ec);
  }
  std::string file(const std::string& name) const { return (path_ / name).string(); }
  std::string path() const { return path_.string(); }

 private:
  static inline int counter_ = 0;
  std::filesystem::path path_;
};

using testing::config_from;

TEST(FileSource, ReplaysTheDirectoryInNameOrderAsMono8) {
  TempDir dir;
  cv::imwrite(dir.file("b.png"), cv::Mat(20, 30, CV_8UC3, cv::Scalar(0, 0, 255)));  // red
  cv::imwrite(dir.file("a.png"), cv::Mat(20, 30, CV_8UC1, cv::Scalar(77)));
  cv::imwrite(dir.file("c.png"), cv::Mat(10, 10, CV_16UC1, cv::Scalar(65535)));
  std::ofstream(dir.file("notes.txt")) << "not an image: ignored\n";
  auto source = FileSource::create({dir.path(), true});
  ASSERT_TRUE(source) << source.error().message;
  EXPECT_EQ((*source)->size(), 3U);
  GrabContext ctx;
  ctx.exposure_ns = 123;
  const auto a = (*source)->grab(ctx);
  ASSERT_TRUE(a) << a.error().message;
  EXPECT_EQ(a->image.type(), CV_8UC1);
  EXPECT_EQ(a->image.at<std::uint8_t>(0, 0), 77);
  EXPECT_EQ(a->exposure_ns, 123);
  const auto b = (*source)->grab(ctx);
  ASSERT_TRUE(b);
  EXPECT_EQ(b->image.at<std::uint8_t>(0, 0), 76);  // red in BT.601 grey: 0.299 * 255
  const auto c = (*source)->grab(ctx);
  ASSERT_TRUE(c);
  EXPECT_EQ(c->image.at<std::uint8_t>(0, 0), 255);
  const auto again = (*source)->grab(ctx);  // loops
  ASSERT_TRUE(again);
  EXPECT_EQ(again->image.at<std::uint8_t>(0, 0), 77);
  EXPECT_FALSE((*source)->has_truth());

  auto once = FileSource::create({dir.path(), false});
  ASSERT_TRUE(once);
  for (int i = 0; i < 3; ++i) {
    ASSERT_TRUE((*once)->grab(ctx));
  }
  EXPECT_THAT((*once)->grab(ctx), IsErrWith(Errc::kNotReady, "all 3 files replayed"));
}

TEST(FileSource, AnEmptyOrMissingDirectoryIsRefusedAtSetup) {
  TempDir dir;
  EXPECT_THAT(FileSource::create({dir.path(), true}), IsErrWith(Errc::kIo, "no images"));
  EXPECT_THAT(FileSource::create({dir.file("nope"), true}), IsErrWith(Errc::kIo, "nope"));
}

TEST(DeviceSource, ReadsThroughVideoCaptureAndReportsAMissingDevice) {
  TempDir dir;
  for (int i = 0; i < 3; ++i) {
    cv::imwrite(dir.file(fmt::format("frame_{:02d}.png", i)),
                cv::Mat(24, 32, CV_8UC3, cv::Scalar(10 * i, 10 * i, 10 * i)));
  }
  // An image sequence stands in for a camera (OpenCV's CAP_IMAGES backend).
  auto source = DeviceSource::create({-1, dir.file("frame_%02d.png")});
  ASSERT_TRUE(source) << source.error().message;
  GrabContext ctx;
  const auto first = (*source)->grab(ctx);
  ASSERT_TRUE(first) << first.error().message;
  EXPECT_EQ(first->image.type(), CV_8UC1);
  EXPECT_EQ(first->image.cols, 32);
  EXPECT_GT(first->exposure_ns, 0);
  const auto second = (*source)->grab(ctx);
  ASSERT_TRUE(second);
  EXPECT_EQ(second->image.at<std::uint8_t>(0, 0), 10);
  (void)(*source)->grab(ctx);
  EXPECT_THAT((*source)->grab(ctx), IsErrWith(Errc::kIo, "no frame"));
  EXPECT_THAT(DeviceSource::create({-1, dir.file("missing.avi")}),
              IsErrWith(Errc::kIo, "cannot open"));
}

TEST(SimSource, RendersTheTrueCameraAndNeedsItsRobotsJoints) {
  const std::string home = cell::testing::source_dir();
  CameraConfig c = config_from(fmt::format(
      "camera_id: ibm7545_eye\nsource: sim\ncamera_file: {}/config/cameras/ibm7545_eye.yaml\n"
      "sim: {{noise_sigma: 0, robot_config: {}/config/robots/ibm7545.yaml}}\n",
      home, home));
  auto source = SimSource::create(c);
  ASSERT_TRUE(source) << source.error().message;
  EXPECT_EQ((*source)->mount_robot_id(), "ibm7545");
  render::Scene scene;
  scene.table_height_mm = 750.0;
  GrabContext ctx;
  ctx.scene = &scene;
  EXPECT_THAT((*source)->grab(ctx), IsErrWith(Errc::kNotReady, "no joints of robot 'ibm7545'"));
  kinematics::JointVector q(4);
  q << 0.785398, 1.832596, 0.0, 0.0;  // the grab pose, 45 and 105 deg
  ctx.joints = q;
  ctx.want_truth = true;
  const auto frame = (*source)->grab(ctx);
  ASSERT_TRUE(frame) << frame.error().message;
  EXPECT_EQ(frame->image.cols, 512);
  EXPECT_EQ(frame->image.rows, 484);
  ASSERT_TRUE(frame->truth);
  EXPECT_NEAR(frame->truth->world_T_camera.translation().z(), 750.0 + 420.0, 5.0);
  EXPECT_DOUBLE_EQ(frame->truth->model.fx_px(), 1502.3);
  ctx.scene = nullptr;
  EXPECT_THAT((*source)->grab(ctx), IsErrWith(Errc::kNotReady, "no world state"));
}

TEST(SimSource, RefusesACameraFileForAnotherCamera) {
  const std::string home = cell::testing::source_dir();
  CameraConfig c = config_from(fmt::format(
      "camera_id: other\nsource: sim\ncamera_file: {}/config/cameras/belt_cam.yaml\n", home));
  EXPECT_THAT(SimSource::create(c), IsErrWith(Errc::kConfig, "describes camera 'belt_cam'"));
}

TEST(CameraConfig, BadKeysAreNamedWithTheirLine) {
  auto doc = config::load_string(
      "camera_id: c\nsource: film\ntrigger: {mode: photocell, rate_hz: -2, delay_s: 1, "
      "delay_mm: 5}\nsim: {noise_sigma: 100}\n",
      "camera-c.yaml");
  ASSERT_TRUE(doc);
  const auto c = load_config(*doc);
  ASSERT_FALSE(c);
  const std::string& m = c.error().message;
  EXPECT_THAT(m, HasSubstr("camera-c.yaml:2"));
  EXPECT_THAT(m, HasSubstr("must be sim, files or device, got 'film'"));
  EXPECT_THAT(m, HasSubstr("rate_hz"));
  EXPECT_THAT(m, HasSubstr("give delay_s or delay_mm, not both"));
  EXPECT_THAT(m, HasSubstr("needs the belt whose photocell fires it"));
  EXPECT_THAT(m, HasSubstr("noise_sigma"));
}

}  // namespace
}  // namespace cell::camera
