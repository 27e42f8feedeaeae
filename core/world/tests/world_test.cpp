// The world model: picks by an ideal robot (at the grasp point and 5 mm off), release, belts
// (travel, encoder), photocell edges, falling off a belt, edits, scatter, determinism.
#include "cell/world/world.hpp"

#include <fmt/format.h>
#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include <cmath>
#include <numbers>

#include "cell/geometry/angles.hpp"
#include "cell/testing/env.hpp"
#include "cell/testing/matchers.hpp"
#include "cell/testing/tolerances.hpp"

namespace cell::world {
namespace {

using ::cell::testing::IsErrWith;
using ::cell::testing::IsNearPose;
using ::cell::testing::IsOk;
using geometry::deg_to_rad;
using ::testing::HasSubstr;

using ::cell::testing::kTolMm;
constexpr double kTableZ = 750.0;

Eigen::Isometry3d translation(double x, double y, double z) {
  return Eigen::Isometry3d(Eigen::Translation3d(x, y, z));
}

Eigen::Isometry3d planar(double x, double y, double z, double yaw) {
  Eigen::Isometry3d t = translation(x, y, z);
  t.linear() = Eigen::AngleAxisd(yaw, Eigen::Vector3d::UnitZ()).toRotationMatrix();
  return t;
}

/// The 7545 as config/sim-world.yaml mounts it, and a belt picker.
WorldOptions options() {
  WorldOptions o;
  o.robots = {{"ibm7545", translation(0, 0, 981.51)}, {"picker", translation(1000, 0, 960)}};
  return o;
}

World make_world(const std::string& yaml, const WorldOptions& opts = options()) {
  const Catalogue cat = Catalogue::standard();
  auto scene = parse_scene(yaml, "test.yaml", cat);
  EXPECT_THAT(scene, IsOk());
  auto world = World::create(*scene, cat, opts);
  EXPECT_THAT(world, IsOk());
  return std::move(world).value();
}

/// One dip14 on the table, in the 7545's image window.
World table_world() {
  return make_world(
      "table: {height_mm: 750}\n"
      "parts:\n"
      "  - {id: ic, class: dip14, x_mm: 100, y_mm: 480, yaw_deg: 30}\n"
      "  - {id: other, class: dip8, x_mm: 160, y_mm: 520, yaw_deg: -45}\n");
}

/// A belt along world +x at z 760 (x from 0 to 2000), photocell at 500 mm.
World belt_world(const std::string& parts = "", double speed = 100.0, int sign = 1) {
  return make_world(fmt::format(
      "table: {{height_mm: 750}}\n"
      "belts:\n"
      "  - {{id: b1, origin_mm: [0, 0, 760], direction_deg: 0, length_mm: 2000, width_mm: 300,\n"
      "     speed_mm_s: {}, mm_per_count: 0.05, encoder_sign: {}, photocell_at_mm: 500}}\n"
      "{}",
      speed, sign, parts.empty() ? "" : "parts:\n" + parts));
}

/// The base_T_tool that puts the 7545's tool point at `world_T_tool`.
Eigen::Isometry3d base_T(const World& w,
                         const std::string& robot,
                         const Eigen::Isometry3d& world_T_tool) {
  for (const auto& r : w.options().robots) {
    if (r.robot_id == robot) {
      return r.world_T_base.inverse() * world_T_tool;
    }
  }
  ADD_FAILURE() << "no robot " << robot;
  return Eigen::Isometry3d::Identity();
}

/// An ideal robot's pick: open at the target, close (closing, then closed) there.
std::vector<WorldEvent> close_at(World& w,
                                 const std::string& robot,
                                 const Eigen::Isometry3d& world_T_tool) {
  std::vector<WorldEvent> events;
  const Eigen::Isometry3d b = base_T(w, robot, world_T_tool);
  EXPECT_THAT(w.update_robot(robot, b, GripperState::kOpen, events), IsOk());
  EXPECT_THAT(w.update_robot(robot, b, GripperState::kClosing, events), IsOk());
  EXPECT_THAT(w.update_robot(robot, b, GripperState::kClosed, events), IsOk());
  return events;
}

std::vector<WorldEvent> open_at(World& w,
                                const std::string& robot,
                                const Eigen::Isometry3d& world_T_tool) {
  std::vector<WorldEvent> events;
  const Eigen::Isometry3d b = base_T(w, robot, world_T_tool);
  EXPECT_THAT(w.update_robot(robot, b, GripperState::kClosed, events), IsOk());
  EXPECT_THAT(w.update_robot(robot, b, GripperState::kOpening, events), IsOk());
  EXPECT_THAT(w.update_robot(robot, b, GripperState::kOpen, events), IsOk());
  return events;
}

std::vector<WorldEvent> of_kind(const std::vector<WorldEvent>& events, WorldEvent::Kind kind) {
  std::vector<WorldEvent> out;
  for (const auto& e : events) {
    if (e.kind == kind) {
      out.push_back(e);
    }
  }
  return out;
}

TEST(WorldPick, AtTheTrueGraspPointAttaches) {
  World w = table_world();
  const Part* ic = w.find("ic");
  ASSERT_NE(ic, nullptr);
  const Eigen::Isometry3d grasp = ic->world_T_grasp();
  EXPECT_NEAR(grasp.translation().z(), kTableZ + 3.81, kTolMm);
  const std::uint64_t seq = w.seq();
  const auto events = close_at(w, "ibm7545", grasp);
  const auto attached = of_kind(events, WorldEvent::Kind::kAttached);
  ASSERT_EQ(attached.size(), 1U);
  EXPECT_EQ(attached[0].part_id, "ic");
  EXPECT_EQ(attached[0].robot_id, "ibm7545");
  EXPECT_EQ(w.find("ic")->support_name, "robot/ibm7545");
  EXPECT_EQ(w.find("other")->support_name, "table");
  EXPECT_GT(w.seq(), seq);
  // The 7545's tool z is up; turned by half a turn the parallel grip is the same.
  World w2 = table_world();
  const auto turned = close_at(
      w2, "ibm7545",
      grasp * Eigen::Isometry3d(Eigen::AngleAxisd(std::numbers::pi, Eigen::Vector3d::UnitZ())));
  EXPECT_EQ(of_kind(turned, WorldEvent::Kind::kAttached).size(), 1U);
}

TEST(WorldPick, FiveMillimetresOffIsAMiss) {
  for (const Eigen::Vector3d& offset :
       {Eigen::Vector3d(5, 0, 0), Eigen::Vector3d(0, -5, 0), Eigen::Vector3d(0, 0, 5)}) {
    SCOPED_TRACE(offset.transpose());
    World w = table_world();
    const Eigen::Isometry3d part_before = w.find("ic")->world_T_part;
    Eigen::Isometry3d target = w.find("ic")->world_T_grasp();
    target.pretranslate(offset);
    const auto events = close_at(w, "ibm7545", target);
    EXPECT_TRUE(of_kind(events, WorldEvent::Kind::kAttached).empty());
    const auto missed = of_kind(events, WorldEvent::Kind::kMissed);
    ASSERT_EQ(missed.size(), 1U);
    EXPECT_EQ(missed[0].part_id, "ic");
    EXPECT_THAT(missed[0].detail, HasSubstr("is 5.00 mm away (tolerance 2.00 mm;"));
    // Which way the part was, from the tool: what a tracking lag or a calibration offset shows.
    const Eigen::Vector3d to_part = Eigen::Vector3d::Zero() - offset;
    EXPECT_THAT(missed[0].detail, HasSubstr(fmt::format("from the tool: {:.2f}, {:.2f}, {:.2f} mm",
                                                        to_part.x(), to_part.y(), to_part.z())));
    EXPECT_EQ(w.find("ic")->support_name, "table");
    EXPECT_THAT(w.find("ic")->world_T_part, IsNearPose(part_before, 0.0));
    // Opening again releases nothing.
    EXPECT_TRUE(of_kind(open_at(w, "ibm7545", target), WorldEvent::Kind::kReleased).empty());
  }
}

TEST(WorldPick, TheYawAndTiltOfTheToolCount) {
  World w = table_world();
  const Eigen::Isometry3d grasp = w.find("ic")->world_T_grasp();
  const auto events = close_at(
      w, "ibm7545",
      grasp * Eigen::Isometry3d(Eigen::AngleAxisd(deg_to_rad(20), Eigen::Vector3d::UnitZ())));
  const auto missed = of_kind(events, WorldEvent::Kind::kMissed);
  ASSERT_EQ(missed.size(), 1U);
  EXPECT_THAT(missed[0].detail, HasSubstr("20.0 deg off in yaw"));
  // A 6-axis arm's tool z points down into the part: fine.
  World w2 = table_world();
  const auto down = close_at(
      w2, "ibm7545",
      grasp * Eigen::Isometry3d(Eigen::AngleAxisd(std::numbers::pi, Eigen::Vector3d::UnitX())));
  EXPECT_EQ(of_kind(down, WorldEvent::Kind::kAttached).size(), 1U);
  // Tilted by 30 deg: not a grip.
  World w3 = table_world();
  const auto tilted = close_at(
      w3, "ibm7545",
      grasp * Eigen::Isometry3d(Eigen::AngleAxisd(deg_to_rad(30), Eigen::Vector3d::UnitX())));
  ASSERT_EQ(of_kind(tilted, WorldEvent::Kind::kMissed).size(), 1U);
  EXPECT_THAT(of_kind(tilted, WorldEvent::Kind::kMissed)[0].detail,
              HasSubstr("30.0 deg from the vertical"));
}

/// The tool at the part's grasp point, turned by `yaw_deg` about the grasp z axis.
Eigen::Isometry3d turned_grasp(const World& w, const std::string& part, double yaw_deg) {
  return w.find(part)->world_T_grasp() *
         Eigen::Isometry3d(Eigen::AngleAxisd(deg_to_rad(yaw_deg), Eigen::Vector3d::UnitZ()));
}

// A parallel-jaw gripper takes a DIP across its body (0 deg) or on its ends (+-90 deg: fingers
// closing along the part's x), config/vision.yaml's "across" and "ends"; half-way is neither.
TEST(WorldPick, ADipIsTakenAcrossItsBodyOrOnItsEnds) {
  for (const double yaw_deg : {90.0, -90.0, 0.0, 180.0, 95.0}) {
    SCOPED_TRACE(yaw_deg);
    World w = table_world();
    const auto events = close_at(w, "ibm7545", turned_grasp(w, "ic", yaw_deg));
    const auto attached = of_kind(events, WorldEvent::Kind::kAttached);
    ASSERT_EQ(attached.size(), 1U);
    EXPECT_EQ(attached[0].part_id, "ic");
    EXPECT_EQ(w.find("ic")->support_name, "robot/ibm7545");
  }
  World w = table_world();
  const auto events = close_at(w, "ibm7545", turned_grasp(w, "ic", 45.0));
  EXPECT_TRUE(of_kind(events, WorldEvent::Kind::kAttached).empty());
  const auto missed = of_kind(events, WorldEvent::Kind::kMissed);
  ASSERT_EQ(missed.size(), 1U);
  EXPECT_EQ(missed[0].part_id, "ic");
  EXPECT_THAT(missed[0].detail, HasSubstr("45.0 deg off in yaw (tolerance 10.0 deg)"));
  EXPECT_THAT(missed[0].detail, HasSubstr("from the tool: 0.00, 0.00, 0.00 mm in the world"));
  EXPECT_EQ(w.find("ic")->support_name, "table");
  // 70 deg: 20 deg from the ends, the smaller error is reported.
  World w2 = table_world();
  const auto missed70 =
      of_kind(close_at(w2, "ibm7545", turned_grasp(w2, "ic", 70.0)), WorldEvent::Kind::kMissed);
  ASSERT_EQ(missed70.size(), 1U);
  EXPECT_THAT(missed70[0].detail, HasSubstr("-20.0 deg off in yaw"));
}

TEST(WorldPick, AClassGraspedOnlyAcrossMissesOnItsEnds) {
  const std::string scene =
      "table: {height_mm: 750}\n"
      "classes:\n"
      "  - {name: across_only, shape: dip, pins: 14, length_mm: 19.05, width_mm: 6.35,\n"
      "     grasp_yaws_deg: [0]}\n"
      "parts:\n"
      "  - {id: ic, class: across_only, x_mm: 100, y_mm: 480, yaw_deg: 30}\n";
  World w = make_world(scene);
  ASSERT_NE(w.find("ic"), nullptr);
  const auto events = close_at(w, "ibm7545", turned_grasp(w, "ic", 90.0));
  EXPECT_TRUE(of_kind(events, WorldEvent::Kind::kAttached).empty());
  const auto missed = of_kind(events, WorldEvent::Kind::kMissed);
  ASSERT_EQ(missed.size(), 1U);
  EXPECT_THAT(missed[0].detail, HasSubstr("90.0 deg off in yaw"));
  EXPECT_EQ(w.find("ic")->support_name, "table");
  // Across, and half a turn from it: still taken.
  for (const double yaw_deg : {0.0, 180.0}) {
    SCOPED_TRACE(yaw_deg);
    World w2 = make_world(scene);
    EXPECT_EQ(of_kind(close_at(w2, "ibm7545", turned_grasp(w2, "ic", yaw_deg)),
                      WorldEvent::Kind::kAttached)
                  .size(),
              1U);
  }
}

// A square's 4-fold symmetry alone decides (its grasp yaws are {0}): 90 deg is taken, 45 is
// the largest possible miss.
TEST(WorldPick, ASquareKeepsItsFourFoldSymmetry) {
  const std::string scene =
      "table: {height_mm: 750}\n"
      "parts:\n"
      "  - {id: sq, class: square, x_mm: 100, y_mm: 480, yaw_deg: 10}\n";
  for (const double yaw_deg : {0.0, 90.0, -90.0, 180.0, 8.0}) {
    SCOPED_TRACE(yaw_deg);
    World w = make_world(scene);
    EXPECT_EQ(
        of_kind(close_at(w, "ibm7545", turned_grasp(w, "sq", yaw_deg)), WorldEvent::Kind::kAttached)
            .size(),
        1U);
  }
  World w = make_world(scene);
  const auto missed =
      of_kind(close_at(w, "ibm7545", turned_grasp(w, "sq", 45.0)), WorldEvent::Kind::kMissed);
  ASSERT_EQ(missed.size(), 1U);
  EXPECT_THAT(missed[0].detail, HasSubstr("45.0 deg off in yaw"));
}

TEST(WorldPick, AHeldPartFollowsTheToolAndLandsWhereReleased) {
  World w = table_world();
  ASSERT_EQ(
      of_kind(close_at(w, "ibm7545", w.find("ic")->world_T_grasp()), WorldEvent::Kind::kAttached)
          .size(),
      1U);
  // Carried up and over (thesis place slot 0, digest 000 §6: (-250, 250) mm, R = 0).
  const Eigen::Isometry3d above = planar(-250, 250, kTableZ + 60, 0.0);
  std::vector<WorldEvent> events;
  ASSERT_THAT(w.update_robot("ibm7545", base_T(w, "ibm7545", above), GripperState::kClosed, events),
              IsOk());
  EXPECT_NEAR(w.find("ic")->world_T_part.translation().z(), kTableZ + 60 - 3.81, kTolMm);
  EXPECT_EQ(w.find("ic")->support_name, "robot/ibm7545");
  // Down to the table and open: the part rests where the tool put it, flat, on the table.
  const Eigen::Isometry3d place = planar(-250, 250, kTableZ + 3.81, 0.0);
  events = open_at(w, "ibm7545", place);
  const auto released = of_kind(events, WorldEvent::Kind::kReleased);
  ASSERT_EQ(released.size(), 1U);
  EXPECT_EQ(released[0].support, "table");
  const Part* ic = w.find("ic");
  EXPECT_EQ(ic->support_name, "table");
  EXPECT_THAT(ic->world_T_part, IsNearPose(planar(-250, 250, kTableZ, 0.0), 1e-9));
  // Released from higher up, it drops flat onto the table all the same.
  ASSERT_EQ(
      of_kind(close_at(w, "ibm7545", ic->world_T_grasp()), WorldEvent::Kind::kAttached).size(), 1U);
  open_at(w, "ibm7545", planar(-250, 280, kTableZ + 40, deg_to_rad(10)));
  EXPECT_THAT(w.find("ic")->world_T_part,
              IsNearPose(planar(-250, 280, kTableZ, deg_to_rad(10)), 1e-9));
}

TEST(WorldPick, AnOffsetGripCarriesItsOffset) {
  World w = table_world();
  Eigen::Isometry3d grip = w.find("ic")->world_T_grasp();
  grip.pretranslate(Eigen::Vector3d(1.5, 0, 0));  // within the 2 mm tolerance
  ASSERT_EQ(of_kind(close_at(w, "ibm7545", grip), WorldEvent::Kind::kAttached).size(), 1U);
  open_at(w, "ibm7545", planar(-250, 310, kTableZ + 3.81, 0.0));
  // The part lands 1.5 mm off the tool point along the world x it was offset by (turned by
  // the tool's change of yaw: the tool kept yaw 30 deg -> 0 deg).
  const Eigen::Isometry3d tool_T_part = grip.inverse() * planar(100, 480, kTableZ, deg_to_rad(30));
  const Eigen::Isometry3d expected = planar(-250, 310, kTableZ + 3.81, 0.0) * tool_T_part;
  EXPECT_THAT(w.find("ic")->world_T_part, IsNearPose(expected, 1e-9));
}

TEST(WorldPick, TheFirstObservationOnlyRecordsTheGripper) {
  World w = table_world();
  std::vector<WorldEvent> events;
  const Eigen::Isometry3d b = base_T(w, "ibm7545", w.find("ic")->world_T_grasp());
  ASSERT_THAT(w.update_robot("ibm7545", b, GripperState::kClosed, events), IsOk());
  ASSERT_THAT(w.update_robot("ibm7545", b, GripperState::kUnknown, events), IsOk());
  ASSERT_THAT(w.update_robot("ibm7545", b, GripperState::kClosed, events), IsOk());
  EXPECT_TRUE(events.empty());
  EXPECT_EQ(w.find("ic")->support_name, "table");
  ASSERT_THAT(w.update_robot("ibm7545", b, GripperState::kOpening, events), IsOk());
  ASSERT_THAT(w.update_robot("ibm7545", b, GripperState::kClosing, events), IsOk());
  EXPECT_EQ(of_kind(events, WorldEvent::Kind::kAttached).size(), 1U);
}

TEST(WorldPick, UnknownRobotsAndBadPosesAreRefused) {
  World w = table_world();
  std::vector<WorldEvent> events;
  EXPECT_THAT(w.update_robot("puma", Eigen::Isometry3d::Identity(), GripperState::kOpen, events),
              IsErrWith(Errc::kInvalidArgument,
                        "robot 'puma' has no mount in the world "
                        "(mounted: ibm7545, picker)"));
  Eigen::Isometry3d bad = Eigen::Isometry3d::Identity();
  bad.linear()(0, 0) = 2.0;
  EXPECT_THAT(w.update_robot("ibm7545", bad, GripperState::kOpen, events),
              IsErrWith(Errc::kInvalidArgument, "base_T_tool"));
  EXPECT_FALSE(w.world_T_tool("ibm7545").has_value());
}

TEST(WorldBelt, AdvancesSpeedTimesTimeAndCountsPerMmTimesDistance) {
  for (const double speed : {100.0, 3000.0, -250.0}) {
    SCOPED_TRACE(speed);
    World w = belt_world("  - {id: p, class: dip14, x_mm: 1000, y_mm: 0}\n", speed);
    const Eigen::Vector3d start = w.find("p")->world_T_part.translation();
    EXPECT_EQ(w.find("p")->support_name, "belt/b1");
    EXPECT_DOUBLE_EQ(start.z(), 760.0);
    std::vector<WorldEvent> events;
    constexpr int kSteps = 300;
    constexpr double kDt = 0.001;
    for (int i = 0; i < kSteps; ++i) {
      w.step(kDt, events);
    }
    const double distance = speed * kSteps * kDt;  // mm
    const Belt& b = w.belts()[0];
    EXPECT_NEAR(b.travel_mm, distance, 1e-9);
    EXPECT_NEAR(w.time_s(), kSteps * kDt, 1e-12);
    EXPECT_EQ(b.encoder_count, static_cast<std::int64_t>(std::floor(b.travel_mm / 0.05)));
    EXPECT_NEAR(static_cast<double>(b.encoder_count), distance * (1.0 / 0.05), 1.0);
    const Eigen::Vector3d moved = w.find("p")->world_T_part.translation() - start;
    EXPECT_NEAR(moved.x(), distance, 1e-9);
    EXPECT_NEAR(moved.y(), 0.0, kTolMm);
    EXPECT_NEAR(moved.z(), 0.0, kTolMm);
  }
}

// A feeder puts a part on the belt every period_s; the same seed gives the same stream; a part
// that would land on one still at the feed point is not fed but counted as jammed.
TEST(WorldFeeder, FeedsAtItsPeriodDeterministicallyAndCountsJams) {
  auto run = [&](double speed, double lateral = 50.0) {
    const std::string feeder = fmt::format(
        "feeders:\n  - {{belt: b1, classes: [dip14, dip8], period_s: 0.5, start_mm: 40, "
        "lateral_mm: {}, yaw_deg: [-30, 30], seed: 7}}\n",
        lateral);
    World w = make_world(fmt::format(
        "table: {{height_mm: 750}}\nbelts:\n  - {{id: b1, origin_mm: [0, 0, 760], "
        "direction_deg: 0, length_mm: 2000, width_mm: 300, speed_mm_s: {}, mm_per_count: 0.05, "
        "photocell_at_mm: 500}}\n{}",
        speed, feeder));
    std::vector<WorldEvent> events;
    for (int i = 0; i < 2050; ++i) {  // 2.05 s: feeds at 0.5, 1.0, 1.5 and 2.0 s
      w.step(0.001, events);
    }
    return std::pair{std::move(w), std::move(events)};
  };
  auto [w, events] = run(500.0);
  EXPECT_EQ(w.feeder_counts("b1"), (std::pair<std::uint32_t, std::uint64_t>{4, 0}));
  ASSERT_EQ(w.parts().size(), 4U);
  for (const Part& p : w.parts()) {
    EXPECT_EQ(p.support_name, "belt/b1");
    EXPECT_LE(std::abs(p.world_T_part.translation().y()), 50.0 + 1e-9);
  }
  // The first part, fed at 0.5 s 40 mm along, has travelled 1.55 s x 500 mm/s since.
  EXPECT_NEAR(w.parts()[0].world_T_part.translation().x(), 40.0 + 1.55 * 500.0, 1.0);
  auto again = run(500.0);
  for (std::size_t i = 0; i < 4; ++i) {
    EXPECT_TRUE(again.first.parts()[i].world_T_part.isApprox(w.parts()[i].world_T_part, 1e-12));
  }
  // A stopped belt, every part fed on the centre line: each later one would land on the first.
  auto [stopped, stopped_events] = run(0.0, 0.0);
  EXPECT_EQ(stopped.feeder_counts("b1").first, 1U);
  EXPECT_EQ(stopped.feeder_counts("b1").second, 3U);
  int jams = 0;
  for (const auto& e : stopped_events) {
    jams += e.kind == WorldEvent::Kind::kFed && e.part_id.empty() ? 1 : 0;
  }
  EXPECT_EQ(jams, 3);
}

TEST(WorldFeeder, ABadFeederIsRefusedWithItsLine) {
  const Catalogue catalogue = Catalogue::standard();
  auto scene = parse_scene(
      "table: {height_mm: 750}\nfeeders:\n  - {belt: b9, classes: [dip99], period_s: 0}\n",
      "s.yaml", catalogue);
  ASSERT_FALSE(scene);
  EXPECT_THAT(scene.error().message, HasSubstr("s.yaml:3:"));
  EXPECT_THAT(scene.error().message, HasSubstr("unknown part class 'dip99'"));
}

TEST(WorldBelt, TheEncoderSignFollowsTheConfig) {
  World w = belt_world("", 100.0, -1);
  std::vector<WorldEvent> events;
  for (int i = 0; i < 100; ++i) {
    w.step(0.001, events);
  }
  EXPECT_EQ(w.belts()[0].encoder_count,
            -static_cast<std::int64_t>(std::floor(w.belts()[0].travel_mm / 0.05)));
  EXPECT_LT(w.belts()[0].encoder_count, -190);
}

// A 19.05 mm dip14 starting at x = 400 crosses the beam at 500: blocked when its leading end
// (409.525) reaches it, cleared when its trailing end (390.475) does; the count is latched at
// the edge (interpolated inside the step), not at the step.
TEST(WorldBelt, PhotocellEdgesLatchTheCount) {
  World w = belt_world("  - {id: p, class: dip14, x_mm: 400, y_mm: 0}\n");
  std::vector<WorldEvent> events;
  for (int i = 0; i < 2000; ++i) {
    w.step(0.001, events);
  }
  const auto edges = of_kind(events, WorldEvent::Kind::kPhotocell);
  ASSERT_EQ(edges.size(), 2U);
  EXPECT_TRUE(edges[0].blocked);
  EXPECT_FALSE(edges[1].blocked);
  EXPECT_EQ(edges[0].part_id, "p");
  EXPECT_EQ(edges[0].belt_id, "b1");
  EXPECT_NEAR(static_cast<double>(edges[0].encoder_count), (500.0 - 409.525) / 0.05, 1.0);
  EXPECT_NEAR(static_cast<double>(edges[1].encoder_count), (500.0 - 390.475) / 0.05, 1.0);
  EXPECT_NEAR(edges[0].time_s, 0.90475, 1e-6);
  EXPECT_NEAR(edges[1].time_s, 1.09525, 1e-6);
  EXPECT_FALSE(w.belts()[0].photocell_blocked);
}

TEST(WorldBelt, OverlappingShadowsGiveOneBlockedSpan) {
  // Side by side across the belt, their spans along it overlap: one blocked span. A third,
  // far upstream, gives its own pair of edges.
  World w = belt_world(
      "  - {id: a, class: dip14, x_mm: 400, y_mm: -50}\n"
      "  - {id: b, class: dip14, x_mm: 415, y_mm: 50}\n"
      "  - {id: c, class: dip14, x_mm: 300, y_mm: 0}\n");
  std::vector<WorldEvent> events;
  for (int i = 0; i < 3000; ++i) {
    w.step(0.001, events);
  }
  const auto edges = of_kind(events, WorldEvent::Kind::kPhotocell);
  ASSERT_EQ(edges.size(), 4U);
  EXPECT_EQ(edges[0].part_id, "b");
  EXPECT_TRUE(edges[0].blocked);
  EXPECT_EQ(edges[1].part_id, "a");
  EXPECT_FALSE(edges[1].blocked);
  EXPECT_NEAR(static_cast<double>(edges[0].encoder_count), (500.0 - 424.525) / 0.05, 1.0);
  EXPECT_NEAR(static_cast<double>(edges[1].encoder_count), (500.0 - 390.475) / 0.05, 1.0);
  EXPECT_EQ(edges[2].part_id, "c");
  EXPECT_TRUE(edges[2].blocked);
  EXPECT_FALSE(edges[3].blocked);
}

TEST(WorldBelt, APartPutOnTheBeamBlocksItAtTheNextStep) {
  World w = belt_world("", 0.0);
  std::vector<WorldEvent> events;
  w.step(0.001, events);
  ASSERT_TRUE(events.empty());
  ASSERT_THAT(w.spawn(PartPlacement{.id = "q", .class_name = "dip8", .x_mm = 500, .y_mm = 20}),
              IsOk());
  w.step(0.001, events);
  ASSERT_EQ(events.size(), 1U);
  EXPECT_TRUE(events[0].blocked);
  EXPECT_EQ(events[0].part_id, "q");
  ASSERT_THAT(w.remove("q"), IsOk());
  w.step(0.001, events);
  ASSERT_EQ(events.size(), 2U);
  EXPECT_FALSE(events[1].blocked);
}

TEST(WorldBelt, APartPastTheEndFallsToTheFloor) {
  World w = belt_world("  - {id: p, class: dip14, x_mm: 1990, y_mm: 30}\n", 1000.0);
  std::vector<WorldEvent> events;
  for (int i = 0; i < 20; ++i) {
    w.step(0.001, events);
  }
  const auto fell = of_kind(events, WorldEvent::Kind::kFellOffBelt);
  ASSERT_EQ(fell.size(), 1U);
  EXPECT_EQ(fell[0].part_id, "p");
  EXPECT_EQ(fell[0].support, "floor");
  const Part* p = w.find("p");
  EXPECT_EQ(p->support_name, "floor");
  EXPECT_DOUBLE_EQ(p->world_T_part.translation().z(), 0.0);
  EXPECT_GT(p->world_T_part.translation().x(), 2000.0);
  EXPECT_LT(p->world_T_part.translation().x(), 2002.0);
  EXPECT_NEAR(p->world_T_part.translation().y(), 30.0, kTolMm);
  // It stays there.
  const Eigen::Isometry3d there = p->world_T_part;
  w.step(0.1, events);
  EXPECT_THAT(w.find("p")->world_T_part, IsNearPose(there, 0.0));
}

TEST(WorldBelt, ReleasedOverTheBeltThePartRidesAlong) {
  World w = belt_world("  - {id: p, class: rectangle, x_mm: 1000, y_mm: -80}\n", 0.0);
  // Picked from the belt by the picker, put down 100 mm further across.
  ASSERT_EQ(
      of_kind(close_at(w, "picker", w.find("p")->world_T_grasp()), WorldEvent::Kind::kAttached)
          .size(),
      1U);
  open_at(w, "picker", planar(1100, 60, 760 + 5, 0.0));
  EXPECT_EQ(w.find("p")->support_name, "belt/b1");
  ASSERT_THAT(w.set_belt_speed("b1", 200.0), IsOk());
  std::vector<WorldEvent> events;
  for (int i = 0; i < 100; ++i) {
    w.step(0.001, events);
  }
  EXPECT_NEAR(w.find("p")->world_T_part.translation().x(), 1120.0, 1e-9);
  EXPECT_THAT(w.set_belt_speed("b2", 1.0),
              IsErrWith(Errc::kInvalidArgument, "no belt 'b2' in the world (belts: b1)"));
  EXPECT_THAT(w.set_belt_speed("b1", NAN), IsErrWith(Errc::kInvalidArgument, "finite"));
}

// A robot state is stamped when its joints were read and reaches the world later: the capture
// compares the tool with the part where it was at that instant, not where the belt has moved
// it since (a tool tracking a 2 m/s belt exactly, seen 1.5 ms late, is 3 mm behind its part).
TEST(WorldBelt, ACaptureComparesTheToolWithThePartAtTheStatesInstant) {
  const std::string parts = "  - {id: p, class: rectangle, x_mm: 1000, y_mm: -80}\n";
  for (const bool with_age : {true, false}) {
    World w = belt_world(parts, 2000.0);
    std::vector<WorldEvent> events;
    for (int i = 0; i < 100; ++i) {
      w.step(0.001, events);
    }
    const Eigen::Isometry3d now = w.find("p")->world_T_grasp();
    EXPECT_NEAR(now.translation().x(), 1200.0, 1e-9);
    // 1.5 ms before the world's present the part, and the tool on it, were 3 mm upstream.
    const double age_s = with_age ? 0.0015 : 0.0;
    const Eigen::Isometry3d tool = Eigen::Translation3d(-3.0, 0, 0) * now;
    const Eigen::Isometry3d b = base_T(w, "picker", tool);
    events.clear();
    for (const GripperState g : {GripperState::kOpen, GripperState::kClosing}) {
      ASSERT_THAT(w.update_robot("picker", b, g, events, age_s), IsOk());
    }
    if (with_age) {
      const auto attached = of_kind(events, WorldEvent::Kind::kAttached);
      ASSERT_EQ(attached.size(), 1U);
      EXPECT_THAT(attached[0].detail, HasSubstr("(0.00 mm from its grasp point;"));
      // Held as it was then: the next state, 1 ms later and 2 mm on, carries it exactly.
      ASSERT_THAT(w.update_robot("picker", base_T(w, "picker", Eigen::Translation3d(2, 0, 0) * tool),
                                 GripperState::kClosed, events, 0.0005),
                  IsOk());
      EXPECT_THAT(w.find("p")->world_T_grasp(),
                  IsNearPose(Eigen::Translation3d(-1.0, 0, 0) * now, 1e-9));
    } else {
      const auto missed = of_kind(events, WorldEvent::Kind::kMissed);
      ASSERT_EQ(missed.size(), 1U);
      EXPECT_THAT(missed[0].detail, HasSubstr("is 3.00 mm away (tolerance 2.00 mm;"));
    }
  }
  World w = belt_world(parts, 2000.0);
  std::vector<WorldEvent> events;
  EXPECT_THAT(w.update_robot("picker", Eigen::Isometry3d::Identity(), GripperState::kOpen, events,
                             2.0),
              IsErrWith(Errc::kInvalidArgument, "age 2 s is outside +-1 s"));
}

TEST(WorldEdit, SpawnRemoveAndTheirErrors) {
  World w = table_world();
  const std::uint64_t seq = w.seq();
  auto id = w.spawn(PartPlacement{.class_name = "dip16", .x_mm = 0, .y_mm = 300, .yaw = 0.2});
  ASSERT_THAT(id, IsOk());
  EXPECT_EQ(*id, "p1");
  EXPECT_EQ(w.seq(), seq + 1);
  EXPECT_THAT(w.spawn(PartPlacement{.id = "x", .class_name = "dip16", .x_mm = 3, .y_mm = 302}),
              IsErrWith(Errc::kOutOfRange,
                        "part 'x' (dip16) overlaps part 'p1' (dip16) on the "
                        "table"));
  EXPECT_THAT(w.spawn(PartPlacement{.class_name = "dip99", .x_mm = 0, .y_mm = 0}),
              IsErrWith(Errc::kInvalidArgument, "unknown part class 'dip99' (known: "));
  EXPECT_THAT(w.spawn(PartPlacement{.id = "ic", .class_name = "dip8", .x_mm = -300, .y_mm = 0}),
              IsErrWith(Errc::kInvalidArgument, "part id 'ic' is already in the world"));
  EXPECT_THAT(w.spawn(PartPlacement{.class_name = "dip8", .x_mm = NAN, .y_mm = 0}),
              IsErrWith(Errc::kInvalidArgument, "finite"));
  EXPECT_EQ(w.parts().size(), 3U);
  ASSERT_THAT(w.remove("p1"), IsOk());
  EXPECT_EQ(w.parts().size(), 2U);
  EXPECT_THAT(w.remove("p1"), IsErrWith(Errc::kInvalidArgument, "no part 'p1'"));
  // Off the table: the part lies on the floor.
  auto floor = w.spawn(PartPlacement{.class_name = "dip8", .x_mm = 2000, .y_mm = 0});
  ASSERT_THAT(floor, IsOk());
  EXPECT_EQ(w.find(*floor)->support_name, "floor");
}

TEST(WorldScatter, IsSeparatedInsideItsRegionAndDeterministic) {
  ScatterSpec spec;
  spec.count = 40;
  spec.classes = {"dip14", "dip8", "ic_7x30", "disc"};
  spec.x_min_mm = -200;
  spec.x_max_mm = 200;
  spec.y_min_mm = 0;
  spec.y_max_mm = 400;
  spec.min_separation_mm = 5.7;
  spec.seed = 42;
  World a = table_world();
  World b = table_world();
  auto ids_a = a.scatter(spec);
  auto ids_b = b.scatter(spec);
  ASSERT_THAT(ids_a, IsOk());
  ASSERT_THAT(ids_b, IsOk());
  EXPECT_EQ(*ids_a, *ids_b);
  ASSERT_EQ(a.parts().size(), 42U);
  for (std::size_t i = 0; i < a.parts().size(); ++i) {
    const Part& p = a.parts()[i];
    EXPECT_EQ(p.id, b.parts()[i].id);
    EXPECT_EQ(p.cls->name, b.parts()[i].cls->name);
    EXPECT_TRUE(p.world_T_part.matrix() == b.parts()[i].world_T_part.matrix()) << p.id;
    if (i >= 2) {
      EXPECT_GE(p.world_T_part.translation().x(), -200.0);
      EXPECT_LE(p.world_T_part.translation().x(), 200.0);
      EXPECT_GE(p.world_T_part.translation().y(), 0.0);
      EXPECT_LE(p.world_T_part.translation().y(), 400.0);
    }
    for (std::size_t j = 2; j < i; ++j) {
      EXPECT_GE(distance(p.footprint, a.parts()[j].footprint), 5.7) << p.id << " " << j;
    }
  }
  // Another seed, another world.
  spec.seed = 43;
  World c = table_world();
  ASSERT_THAT(c.scatter(spec), IsOk());
  EXPECT_FALSE(c.parts()[2].world_T_part.matrix() == a.parts()[2].world_T_part.matrix());
  // All or nothing.
  spec.count = 5000;
  spec.max_attempts_per_part = 20;
  const std::size_t before = c.parts().size();
  EXPECT_THAT(c.scatter(spec), IsErrWith(Errc::kOutOfRange, "of 5000 parts"));
  EXPECT_EQ(c.parts().size(), before);
  spec.classes = {"nothing"};
  EXPECT_THAT(c.scatter(spec), IsErrWith(Errc::kInvalidArgument, "unknown part class 'nothing'"));
}

// Same scene, same seed, same inputs: the same world, bit for bit.
TEST(WorldDeterminism, SameSceneAndSeedGiveTheSameWorld) {
  const Catalogue cat = Catalogue::standard();
  auto run = [&]() {
    auto scene =
        load_scene_file(cell::testing::source_dir() + "/config/scenes/belt_conveyor.yaml", cat);
    EXPECT_THAT(scene, IsOk());
    scene->scatter[0].count = 12;
    WorldOptions opts = options();
    auto world = World::create(*scene, cat, opts);
    EXPECT_THAT(world, IsOk());
    World w = std::move(world).value();
    std::vector<WorldEvent> events;
    for (int i = 0; i < 1500; ++i) {
      w.step(0.001, events);
      if (i == 700) {
        (void)w.set_belt_speed("belt1", 250.0);
      }
    }
    return std::make_pair(std::move(w), std::move(events));
  };
  const auto [a, ea] = run();
  const auto [b, eb] = run();
  ASSERT_EQ(a.parts().size(), 15U);
  ASSERT_EQ(a.parts().size(), b.parts().size());
  for (std::size_t i = 0; i < a.parts().size(); ++i) {
    EXPECT_EQ(a.parts()[i].id, b.parts()[i].id);
    EXPECT_TRUE(a.parts()[i].world_T_part.matrix() == b.parts()[i].world_T_part.matrix());
    EXPECT_EQ(a.parts()[i].support_name, b.parts()[i].support_name);
  }
  EXPECT_EQ(a.belts()[0].encoder_count, b.belts()[0].encoder_count);
  EXPECT_EQ(a.seq(), b.seq());
  ASSERT_EQ(ea.size(), eb.size());
  EXPECT_FALSE(ea.empty());  // parts crossed the photocell
  for (std::size_t i = 0; i < ea.size(); ++i) {
    EXPECT_EQ(ea[i].kind, eb[i].kind);
    EXPECT_EQ(ea[i].encoder_count, eb[i].encoder_count);
    EXPECT_EQ(ea[i].part_id, eb[i].part_id);
  }
}

}  // namespace
}  // namespace cell::world
