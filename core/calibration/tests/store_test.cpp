// The versioned store: every version stays, one is current, rollback moves the pointer, and a
// failed calibration (one that never reaches add_*) never replaces the current one.
#include "cell/calibration/store.hpp"

#include <unistd.h>

#include <filesystem>
#include <fstream>

#include <fmt/format.h>
#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include "cell/testing/matchers.hpp"

namespace cell::calibration {
namespace {

using ::cell::testing::IsErrWith;
using ::cell::testing::IsOk;
using ::testing::HasSubstr;

CameraCalibration camera(double fx) {
  CameraCalibration c;
  c.camera_id = "belt_cam";
  c.source = fmt::format("intrinsics: test fx {}", fx);
  c.robot_id = "scara_picker";
  c.width_px = 1024;
  c.height_px = 1024;
  c.pinhole = {fx, 2004.0, 515.0, 509.0, {-0.05, 0.02, 0.0, 0.0, 0.0}};
  c.working_plane_z_mm = -200.0;
  c.quality = {0.28, 0.29, 0.05, 16};
  return c;
}

class StoreTest : public ::testing::Test {
 protected:
  StoreTest()
      : dir_(std::filesystem::temp_directory_path() /
             fmt::format("calib-store-{}-{}", ::getpid(), counter_++)),
        store_(dir_.string()) {}
  ~StoreTest() override {
    std::error_code ec;
    std::filesystem::remove_all(dir_, ec);
  }
  static inline int counter_ = 0;
  std::filesystem::path dir_;
  CalibrationStore store_;
};

TEST_F(StoreTest, VersionsAccumulateAndTheLatestIsCurrent) {
  EXPECT_THAT(store_.current_camera("belt_cam"), IsErrWith(Errc::kNotReady, "no camera calibration"));
  auto a = store_.add_camera(camera(2001.0), "views: []\n");
  ASSERT_THAT(a, IsOk());
  EXPECT_THAT(a->version, ::testing::EndsWith("#1"));
  EXPECT_FALSE(a->created_utc.empty());
  auto b = store_.add_camera(camera(2002.0));
  ASSERT_THAT(b, IsOk());
  EXPECT_THAT(b->version, ::testing::EndsWith("#2"));
  auto current = store_.current_camera("belt_cam");
  ASSERT_THAT(current, IsOk());
  EXPECT_EQ(current->pinhole.fx_px, 2002.0);
  EXPECT_EQ(current->version, b->version);
  EXPECT_TRUE(std::filesystem::exists(dir_ / "camera/belt_cam/0001.details.yaml"));
  auto list = store_.list();
  ASSERT_THAT(list, IsOk());
  ASSERT_EQ(list->size(), 2U);
  EXPECT_FALSE((*list)[0].current);
  EXPECT_TRUE((*list)[1].current);
  EXPECT_EQ((*list)[1].holdout_rms_px, 0.29);
  EXPECT_EQ(store_.devices(DeviceKind::kCamera), std::vector<std::string>{"belt_cam"});
}

TEST_F(StoreTest, RollbackMakesAnEarlierVersionCurrentAndKeepsTheLater) {
  ASSERT_THAT(store_.add_camera(camera(2001.0)), IsOk());
  ASSERT_THAT(store_.add_camera(camera(2002.0)), IsOk());
  auto r = store_.rollback(DeviceKind::kCamera, "belt_cam", "#1");
  ASSERT_THAT(r, IsOk());
  EXPECT_EQ(r->number, 1);
  EXPECT_EQ(store_.current_camera("belt_cam")->pinhole.fx_px, 2001.0);
  EXPECT_EQ(store_.list()->size(), 2U);
  EXPECT_EQ(store_.camera("belt_cam", "2")->pinhole.fx_px, 2002.0);
  EXPECT_THAT(store_.rollback(DeviceKind::kCamera, "belt_cam", "7"),
              IsErrWith(Errc::kInvalidArgument, "has no version '7' (known: "));
  // A new version after a rollback is numbered after every stored one.
  auto c = store_.add_camera(camera(2003.0));
  ASSERT_THAT(c, IsOk());
  EXPECT_THAT(c->version, ::testing::EndsWith("#3"));
}

TEST_F(StoreTest, AnInvalidCalibrationIsRefusedAndTheCurrentOneStays) {
  ASSERT_THAT(store_.add_camera(camera(2001.0)), IsOk());
  CameraCalibration bad = camera(-5.0);
  EXPECT_THAT(store_.add_camera(bad), IsErrWith(Errc::kInvalidArgument, "fx"));
  EXPECT_EQ(store_.current_camera("belt_cam")->pinhole.fx_px, 2001.0);
  EXPECT_EQ(store_.list()->size(), 1U);
  CameraCalibration evil = camera(2001.0);
  evil.camera_id = "../etc";
  EXPECT_THAT(store_.add_camera(evil), IsErrWith(Errc::kInvalidArgument, "must be letters"));
}

TEST_F(StoreTest, BeltsHaveTheirOwnVersions) {
  BeltCalibration b;
  b.belt_id = "belt1";
  b.robot_id = "scara_picker";
  b.mm_per_count = 0.0383;
  b.direction = Eigen::Vector3d(0, -1, 0);
  auto stored = store_.add_belt(b);
  ASSERT_THAT(stored, IsOk());
  EXPECT_THAT(stored->version, ::testing::EndsWith("#1"));
  EXPECT_EQ(store_.current_belt("belt1")->mm_per_count, 0.0383);
  EXPECT_EQ(store_.list(DeviceKind::kBelt)->size(), 1U);
  EXPECT_EQ(store_.list(DeviceKind::kCamera)->size(), 0U);
}

TEST_F(StoreTest, AnUnreadableCurrentFileNamesItself) {
  ASSERT_THAT(store_.add_camera(camera(2001.0)), IsOk());
  std::ofstream(dir_ / "camera/belt_cam/0001.yaml") << "camera_id: [broken\n";
  EXPECT_THAT(store_.current_camera("belt_cam"), IsErrWith(Errc::kConfig, "0001.yaml"));
}

}  // namespace
}  // namespace cell::calibration
