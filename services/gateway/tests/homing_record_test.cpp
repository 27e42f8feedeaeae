// The DPR 7545 master's homing record (homing_record.hpp): round trip, malformed files, and the
// rule that decides whether a restarted master may adopt it.
#include "homing_record.hpp"

#include <unistd.h>

#include <filesystem>
#include <fstream>

#include <fmt/format.h>
#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include "cell/testing/matchers.hpp"

namespace cell::gateway {
namespace {

using ::cell::testing::IsErrWith;
using ::cell::testing::IsOk;
using ::testing::HasSubstr;

class HomingRecordTest : public ::testing::Test {
 protected:
  ~HomingRecordTest() override {
    std::error_code ec;
    std::filesystem::remove_all(dir_, ec);
  }
  std::string dir_ = (std::filesystem::temp_directory_path() /
                      fmt::format("cell-homing-record-{}", ::getpid()))
                         .string();
  std::string path_ = dir_ + "/sub/record.json";
};

TEST_F(HomingRecordTest, RoundTripsAndAnAbsentRecordIsNone) {
  auto none = load_homing_record(path_);
  ASSERT_THAT(none, IsOk());
  EXPECT_FALSE(none->has_value());
  HomingRecord r;
  r.board_pid = 4242;
  r.counts = {1, -2, 30'000, -41'000};
  r.gripper = HomingRecord::Gripper::kClosed;
  r.lights = 3;
  ASSERT_THAT(save_homing_record(path_, r), IsOk());  // creates the directory
  auto back = load_homing_record(path_);
  ASSERT_THAT(back, IsOk());
  ASSERT_TRUE(back->has_value());
  EXPECT_EQ((*back)->board_pid, 4242U);
  EXPECT_EQ((*back)->counts, r.counts);
  EXPECT_EQ((*back)->gripper, HomingRecord::Gripper::kClosed);
  EXPECT_EQ((*back)->lights, 3);
  EXPECT_FALSE(std::filesystem::exists(path_ + ".tmp"));
}

TEST_F(HomingRecordTest, AMalformedRecordIsAnErrorNamingTheFile) {
  std::filesystem::create_directories(dir_ + "/sub");
  for (const char* text : {"not json", R"({"version": 2})",
                           R"({"version": 1, "board_pid": 1, "counts": [1, 2, 3],
                               "gripper": "open", "lights": 0})",
                           R"({"version": 1, "board_pid": 1, "counts": [1, 2, 3, 4],
                               "gripper": "ajar", "lights": 0})"}) {
    std::ofstream(path_) << text;
    auto r = load_homing_record(path_);
    EXPECT_THAT(r, IsErrWith(Errc::kInvalidArgument, path_)) << text;
  }
}

TEST(HomingRecordRule, AdoptsOnlyTheSameBoardWithinTheTolerance) {
  HomingRecord r;
  r.board_pid = 7;
  r.counts = {10'000, 2'000, 3'000, -500};
  const std::array<double, 4> tol = {100, 100, 100, 100};
  EXPECT_EQ(homing_record_refusal(r, 7, {10'050, 1'950, 3'000, -500}, tol), std::nullopt);
  auto other = homing_record_refusal(r, 8, r.counts, tol);
  ASSERT_TRUE(other.has_value());
  EXPECT_THAT(*other, HasSubstr("simulator pid 7"));
  auto reset = homing_record_refusal(r, 7, {0, 0, 0, 0}, tol);
  ASSERT_TRUE(reset.has_value());
  EXPECT_THAT(*reset, HasSubstr("the board was reset"));
  auto moved = homing_record_refusal(r, 7, {10'000, 2'000, 3'500, -500}, tol);
  ASSERT_TRUE(moved.has_value());
  EXPECT_THAT(*moved, HasSubstr("Z reads 3500 counts"));
  // An arm homed and left at home reads 0 everywhere: that is a match, not a reset.
  HomingRecord at_home;
  at_home.counts = {1, 0, -1, 0};
  EXPECT_EQ(homing_record_refusal(at_home, 0, {0, 0, 0, 0}, tol), std::nullopt);
}

}  // namespace
}  // namespace cell::gateway
