#include "world_view.hpp"

#include <cstring>

#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include "cell/testing/matchers.hpp"
#include "world_fixtures.hpp"

namespace cell::camera {
namespace {

using ::cell::testing::IsErrWith;
using ::testing::HasSubstr;
using testing::resting;
using testing::WorldStateWire;

constexpr std::int64_t kSecond = 1'000'000'000;

TEST(WorldSnapshot, ConvertsPartsAndSkipsTheMalformedOnesSayingWhy) {
  WorldStateWire w;
  w.add_part("ic1", "dip14", cell_world_SHAPE_DIP, 19.05, 6.35, 3.81, 14, 0.1,
             resting(100, 500, 750, 30), "table");
  auto nan_pose = resting(0, 0, 750, 0);
  nan_pose.position_mm.x = NAN;
  w.add_part("p2", "rectangle", cell_world_SHAPE_RECTANGLE, 40, 20, 5, 0, 0.1, nan_pose, "table");
  // A shape this build does not know (a newer contract, or garbage on the wire).
  w.add_part("p3", "thing", cell_world_SHAPE_DISC, 10, 10, 5, 0, 0.1, resting(0, 0, 750, 0),
             "table");
  const int unknown_shape = 42;
  std::memcpy(&w.parts.back().shape, &unknown_shape, sizeof unknown_shape);
  w.add_part("p4", "dip13", cell_world_SHAPE_DIP, 19, 6.35, 3.81, 13, 0.1, resting(0, 0, 750, 0),
             "table");
  const WorldSnapshot s = snapshot_from_idl(w.finish(5 * kSecond, 7, 750.0));
  EXPECT_EQ(s.stamp_ns, 5 * kSecond);
  EXPECT_EQ(s.world_seq, 7U);
  EXPECT_DOUBLE_EQ(s.scene.table_height_mm, 750.0);
  ASSERT_EQ(s.scene.parts.size(), 1U);
  const render::Part& ic = s.scene.parts.front();
  EXPECT_EQ(ic.id, "ic1");
  EXPECT_EQ(ic.shape, render::Shape::kDip);
  EXPECT_EQ(ic.pins, 14);
  EXPECT_DOUBLE_EQ(ic.leads.row_spacing_mm, 7.62);
  EXPECT_NEAR(ic.world_T_part.translation().y(), 500.0, 1e-12);
  ASSERT_EQ(s.skipped.size(), 3U);
  EXPECT_THAT(s.skipped[0], HasSubstr("part 'p2': world_T_part: pose has non-finite values"));
  EXPECT_THAT(s.skipped[1], HasSubstr("part 'p3': unknown shape 42"));
  EXPECT_THAT(s.skipped[2], HasSubstr("part 'p4'"));
  EXPECT_THAT(s.skipped[2], HasSubstr("pins 13"));
}

TEST(WorldSnapshot, BeltPartsRideTheirBeltToTheExposure) {
  WorldStateWire w;
  w.add_belt("belt1", {1350, 600, 760}, {0, -1, 0}, 1500, 300, 2500.0, 5 * kSecond);
  w.add_part("la1", "la_part", cell_world_SHAPE_RECTANGLE, 80, 40, 8, 0, 0.8,
             resting(1350, 300, 760, -90), "belt/belt1");
  w.add_part("still", "disc", cell_world_SHAPE_DISC, 20, 20, 5, 0, 0.1,
             resting(1300, 300, 750, 0), "table");
  const WorldSnapshot s = snapshot_from_idl(w.finish(5 * kSecond, 1, 750.0));
  ASSERT_EQ(s.scene.belts.size(), 1U);
  ASSERT_EQ(s.scene.parts.size(), 2U);
  const render::Scene later = scene_at(s, 5 * kSecond + kSecond / 100);  // 10 ms later
  EXPECT_NEAR(later.parts[0].world_T_part.translation().y(), 300.0 - 25.0, 1e-9);
  EXPECT_NEAR(later.parts[0].velocity_mm_s.y(), -2500.0, 1e-12);
  EXPECT_NEAR(later.parts[1].world_T_part.translation().y(), 300.0, 1e-12);
  const render::Scene earlier = scene_at(s, 5 * kSecond - kSecond / 1000);
  EXPECT_NEAR(earlier.parts[0].world_T_part.translation().y(), 302.5, 1e-9);
}

cell_robot_RobotState robot_state(const std::string& id, std::int64_t stamp,
                                  std::vector<double>& q, bool halogen) {
  cell_robot_RobotState s{};
  s.robot_id = bus::borrow(id);
  s.header.stamp_ns = stamp;
  bus::borrow(s.position_rad_or_mm, q);
  s.halogen_on = halogen;
  s.fluorescent_on = true;
  return s;
}

TEST(RobotHistory, InterpolatesTheJointsAtTheExposure) {
  RobotHistory h;
  const std::string id = "ibm7545";
  std::vector<double> q0 = {0.0, 1.0, 10.0, 0.0};
  std::vector<double> q1 = {0.2, 1.0, 20.0, 0.0};
  EXPECT_THAT(h.at(kSecond, kSecond), IsErrWith(Errc::kNotReady, "no state"));
  ASSERT_TRUE(h.add(robot_state(id, 1 * kSecond, q0, false)));
  ASSERT_TRUE(h.add(robot_state(id, 2 * kSecond, q1, true)));
  const auto mid = h.at(kSecond + kSecond / 4, kSecond);
  ASSERT_TRUE(mid);
  EXPECT_NEAR(mid->q[0], 0.05, 1e-12);
  EXPECT_NEAR(mid->q[2], 12.5, 1e-12);
  const auto after = h.at(2 * kSecond + kSecond / 2, kSecond);
  ASSERT_TRUE(after);
  EXPECT_NEAR(after->q[2], 20.0, 1e-12);
  EXPECT_TRUE(after->halogen_on);
  EXPECT_THAT(h.at(4 * kSecond, kSecond), IsErrWith(Errc::kNotReady, "2.000 s older"));
  std::vector<double> bad = {0.0, NAN, 0.0, 0.0};
  EXPECT_THAT(h.add(robot_state(id, 3 * kSecond, bad, false)),
              IsErrWith(Errc::kInvalidArgument, "joint 1 is not finite"));
}

TEST(BeltHistory, LatchesTheCountAtTheExposure) {
  BeltHistory h;
  EXPECT_THAT(h.count_at(kSecond, kSecond), IsErrWith(Errc::kNotReady, "no belt state"));
  h.add({1 * kSecond, 0.0, 100.0, 1000});
  h.add({1 * kSecond + kSecond / 500, 0.2, 100.0, 1004});  // 2 ms later, 4 counts
  const auto between = h.count_at(1 * kSecond + kSecond / 1000, kSecond);
  ASSERT_TRUE(between);
  EXPECT_EQ(*between, 1002);
  const auto beyond = h.count_at(1 * kSecond + 3 * kSecond / 500, kSecond);  // 6 ms
  ASSERT_TRUE(beyond);
  EXPECT_EQ(*beyond, 1012);
  EXPECT_EQ(h.speed().value(), 100.0);
}

}  // namespace
}  // namespace cell::camera
