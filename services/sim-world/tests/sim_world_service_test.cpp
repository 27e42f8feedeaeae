// cell-sim-world in-process on a private bus: config errors, every request kind, picks driven
// by RobotStates, and the photocell on the bus; as a process, a stall of its loop.
#include "sim_world_service.hpp"

#include <fmt/format.h>
#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include <chrono>
#include <csignal>
#include <fstream>
#include <string>
#include <thread>
#include <vector>

#include "cell/bus/request_reply.hpp"
#include "cell/bus/view.hpp"
#include "cell/process/child.hpp"
#include "cell/testing/env.hpp"
#include "cell/testing/matchers.hpp"
#include "cell/testing/service_harness.hpp"

namespace cell::sim_world {
namespace {

using ::cell::testing::eventually;
using ::cell::testing::IsErrWith;
using ::cell::testing::IsOk;
using ::testing::HasSubstr;
using namespace std::chrono_literals;

std::string scene_path(const std::string& name) {
  return cell::testing::source_dir() + "/config/scenes/" + name;
}

Result<SimWorldConfig> parse(const std::string& yaml) {
  auto doc = config::load_string(yaml, "sim-world.yaml");
  if (!doc) {
    return std::move(doc).error();
  }
  return load_config(*doc);
}

TEST(SimWorldConfig, TheShippedConfigLoads) {
  auto doc = config::load_file(cell::testing::source_dir() + "/config/sim-world.yaml");
  ASSERT_THAT(doc, IsOk());
  auto c = load_config(*doc);
  ASSERT_THAT(c, IsOk());
  EXPECT_DOUBLE_EQ(c->step_hz, 1000.0);
  EXPECT_DOUBLE_EQ(c->world_state_hz, 100.0);
  EXPECT_DOUBLE_EQ(c->belt_state_hz, 500.0);
  ASSERT_GE(c->world.robots.size(), 3U);
  EXPECT_EQ(c->world.robots[0].robot_id, "ibm7545");
  EXPECT_NEAR(c->world.robots[0].world_T_base.translation().z(), 981.51, 1e-9);
}

TEST(SimWorldConfig, ErrorsNameTheKeyAndTheSceneLine) {
  EXPECT_THAT(parse(fmt::format("scene: {}\nstep_hz: 5\nworld_state_hz: 2000\ncolour: red\n",
                                scene_path("table_ics.yaml"))),
              IsErrWith(Errc::kConfig,
                        "sim-world.yaml:2:10: key 'step_hz': must be in [10, "
                        "10000], got 5"));
  EXPECT_THAT(parse(fmt::format("scene: {}\ncolour: red\n", scene_path("table_ics.yaml"))),
              IsErrWith(Errc::kConfig, "unknown key 'colour'"));
  EXPECT_THAT(
      parse("scene: /nonexistent.yaml\n"),
      IsErrWith(Errc::kConfig, "sim-world.yaml:1:8: scene: /nonexistent.yaml: cannot open"));
  EXPECT_THAT(parse(fmt::format("scene: {}\nrobots:\n  - {{id: a, xyz_mm: [0, 0, 0]}}\n"
                                "  - {{id: a, xyz_mm: [1, 0, 0]}}\n",
                                scene_path("table_ics.yaml"))),
              IsErrWith(Errc::kConfig, "robot 'a' is mounted twice"));
  const std::string bad_scene = ::testing::TempDir() + "/bad_scene.yaml";
  {
    std::ofstream out(bad_scene);
    out << "parts:\n  - {class: dip14, x_mm: 0, y_mm: 0}\n  - {class: dip15, x_mm: 50, y_mm: 0}\n";
  }
  EXPECT_THAT(parse("scene: " + bad_scene + "\n"), IsErrWith(Errc::kConfig, bad_scene + ":3:"));
}

class SimWorldTest : public ::testing::Test {
 protected:
  static SimWorldConfig make_config(const std::string& scene) {
    SimWorldConfig c;
    c.common.service_id = "sim-world";
    c.scene = scene_path(scene);
    c.world.robots = {{"ibm7545", Eigen::Isometry3d(Eigen::Translation3d(0, 0, 981.51))},
                      {"scara_picker", Eigen::Isometry3d(Eigen::Translation3d(1000, 0, 960))}};
    return c;
  }

  explicit SimWorldTest(const std::string& scene = "table_ics.yaml")
      : domain_(cell::testing::test_domain_id()),
        partition_(cell::testing::unique_partition()),
        service_(domain_, partition_, make_config(scene), "sim-world"),
        client_(domain_, partition_),
        requester_(client_,
                   bus::topics::kWorldRequest,
                   bus::topics::kWorldReply,
                   bus::make_client_id("test")),
        robot_topic_(client_, bus::topics::kRobotState),
        robot_writer_(client_, robot_topic_, bus::topics::kRobotState) {}

  /// Sends `request` and returns the reply (fails the test on a timeout).
  bus::Owned<cell_world_WorldReply> call(cell_world_WorldRequest& request) {
    auto reply = requester_.call(request, 10s);
    EXPECT_THAT(reply, IsOk());
    if (!reply) {
      return {};
    }
    return std::move(reply).value();
  }

  bus::Owned<cell_world_WorldReply> query() {
    cell_world_WorldRequest r{};
    r.kind = cell_world_WORLD_QUERY;
    return call(r);
  }

  /// The part `id` in a reply, or nullptr.
  static const cell_world_WorldPart* part_in(const bus::Owned<cell_world_WorldReply>& reply,
                                             const std::string& id) {
    for (const auto& p : bus::span(reply->parts)) {
      if (bus::str(p.part_id) == id) {
        return &p;
      }
    }
    return nullptr;
  }

  /// Writes a RobotState of the 7545 with the tool at world_T_tool.
  void robot_state(const Eigen::Isometry3d& world_T_tool, cell_robot_GripperState gripper) {
    const Eigen::Isometry3d base_T_tool =
        Eigen::Isometry3d(Eigen::Translation3d(0, 0, -981.51)) * world_T_tool;
    const std::string id = "ibm7545";
    cell_robot_RobotState s{};
    s.robot_id = bus::borrow(id);
    s.base_T_tool = world::pose_to_idl(base_T_tool);
    s.gripper = gripper;
    ASSERT_THAT(robot_writer_.write(s), IsOk());
  }

  std::uint32_t domain_;
  std::string partition_;
  cell::testing::ServiceHarness<SimWorldConfig, SimWorldService> service_;
  bus::Participant client_;
  bus::Requester<cell_world_WorldRequest, cell_world_WorldReply> requester_;
  bus::Topic<cell_robot_RobotState> robot_topic_;
  bus::Writer<cell_robot_RobotState> robot_writer_;
};

TEST_F(SimWorldTest, QueryReturnsTheSceneAndWorldStateFlows) {
  const auto reply = query();
  ASSERT_TRUE(reply->status.accepted) << bus::str(reply->status.reason);
  EXPECT_EQ(bus::span(reply->parts).size(), 15U);
  const auto* ic8 = part_in(reply, "ic8");
  ASSERT_NE(ic8, nullptr);
  EXPECT_EQ(bus::str(ic8->class_name), "dip20");
  EXPECT_NEAR(ic8->world_T_part.position_mm.x, 134.39, 1e-9);
  // The state stream.
  bus::Topic<cell_world_WorldState> topic(client_, bus::topics::kWorldState);
  bus::Reader<cell_world_WorldState> reader(client_, topic, bus::topics::kWorldState);
  std::size_t parts = 0;
  ASSERT_TRUE(eventually(
      [&] {
        (void)reader.take_each([&](const cell_world_WorldState& s, const dds_sample_info_t&) {
          parts = bus::span(s.parts).size();
          EXPECT_DOUBLE_EQ(s.table_height_mm, 750.0);
        });
        return parts == 15U;
      },
      5s));
}

TEST_F(SimWorldTest, ABadResetIsRefusedWithItsLineAndKeepsTheWorld) {
  const std::string yaml =
      "table: {height_mm: 750}\n"
      "parts:\n"
      "  - {id: x, class: dip14, x_mm: 0, y_mm: 300}\n"
      "  - {id: y, class: dip15, x_mm: 50, y_mm: 300}\n";
  const std::string name = "my_scene.yaml";
  cell_world_WorldRequest r{};
  r.kind = cell_world_WORLD_RESET;
  r.scene_yaml = bus::borrow(yaml);
  r.scene_name = bus::borrow(name);
  auto reply = call(r);
  EXPECT_FALSE(reply->status.accepted);
  EXPECT_EQ(bus::str(reply->status.error_code), "config");
  EXPECT_THAT(std::string(bus::str(reply->status.reason)), HasSubstr("my_scene.yaml:4:"));
  EXPECT_THAT(std::string(bus::str(reply->status.reason)), HasSubstr("unknown part class 'dip15'"));
  EXPECT_EQ(bus::span(query()->parts).size(), 15U);
  // A good one replaces it, and world_seq keeps growing.
  const std::uint64_t seq = query()->world_seq;
  const std::string good = yaml.substr(0, yaml.find("  - {id: y"));
  r.scene_yaml = bus::borrow(good);
  reply = call(r);
  ASSERT_TRUE(reply->status.accepted) << bus::str(reply->status.reason);
  EXPECT_EQ(bus::span(reply->parts).size(), 1U);
  EXPECT_GT(reply->world_seq, seq);
  // An empty scene text reloads the configured scene.
  cell_world_WorldRequest again{};
  again.kind = cell_world_WORLD_RESET;
  reply = call(again);
  ASSERT_TRUE(reply->status.accepted);
  EXPECT_EQ(bus::span(reply->parts).size(), 15U);
}

TEST_F(SimWorldTest, SpawnRemoveAndScatterAreAllOrNothing) {
  // Spawn two: the second overlaps ic8, so neither is added.
  const std::string a = "new_a";
  const std::string b = "new_b";
  const std::string cls = "dip8";
  std::vector<cell_world_WorldPart> parts(2);
  parts[0].part_id = bus::borrow(a);
  parts[0].class_name = bus::borrow(cls);
  parts[0].world_T_part = world::pose_to_idl(Eigen::Isometry3d(Eigen::Translation3d(-300, 0, 0)));
  parts[1] = parts[0];
  parts[1].part_id = bus::borrow(b);
  parts[1].world_T_part =
      world::pose_to_idl(Eigen::Isometry3d(Eigen::Translation3d(134.39, 501.25, 0)));
  cell_world_WorldRequest r{};
  r.kind = cell_world_WORLD_SPAWN;
  bus::borrow(r.parts, parts);
  auto reply = call(r);
  EXPECT_FALSE(reply->status.accepted);
  EXPECT_EQ(bus::str(reply->status.error_code), "out_of_range");
  EXPECT_THAT(std::string(bus::str(reply->status.reason)),
              HasSubstr("spawn: part 1: part 'new_b' (dip8) overlaps part 'ic8'"));
  EXPECT_EQ(part_in(query(), "new_a"), nullptr);
  parts.resize(1);
  bus::borrow(r.parts, parts);
  reply = call(r);
  ASSERT_TRUE(reply->status.accepted) << bus::str(reply->status.reason);
  ASSERT_EQ(bus::span(reply->parts).size(), 1U);
  EXPECT_EQ(bus::str(reply->parts._buffer[0].support), "table");
  EXPECT_DOUBLE_EQ(reply->parts._buffer[0].world_T_part.position_mm.z, 750.0);
  // Remove it and a part that does not exist: refused, nothing removed.
  const std::string ghost = "ghost";
  std::vector<char*> ids = {bus::borrow(a), bus::borrow(ghost)};
  cell_world_WorldRequest rm{};
  rm.kind = cell_world_WORLD_REMOVE;
  bus::borrow(rm.part_ids, ids);
  reply = call(rm);
  EXPECT_FALSE(reply->status.accepted);
  EXPECT_THAT(std::string(bus::str(reply->status.reason)), HasSubstr("no part 'ghost'"));
  EXPECT_NE(part_in(query(), "new_a"), nullptr);
  ids.pop_back();
  bus::borrow(rm.part_ids, ids);
  EXPECT_TRUE(call(rm)->status.accepted);
  EXPECT_EQ(part_in(query(), "new_a"), nullptr);
  // Scatter with the scene's generator (the image window): a seed gives the same parts again.
  cell_world_WorldRequest sc{};
  sc.kind = cell_world_WORLD_SCATTER;
  sc.count = 3;
  sc.seed = 5;
  const std::string dip8 = "dip8";
  std::vector<char*> classes = {bus::borrow(dip8)};
  bus::borrow(sc.classes, classes);
  reply = call(sc);
  ASSERT_TRUE(reply->status.accepted) << bus::str(reply->status.reason);
  const auto first = bus::to_vector(reply->parts);
  ASSERT_EQ(first.size(), 3U);
  std::vector<std::string> scattered;
  for (const auto& p : first) {
    scattered.emplace_back(bus::str(p.part_id));
    EXPECT_EQ(bus::str(p.class_name), "dip8");
  }
  std::vector<cell_common_Vector3> positions;
  positions.reserve(first.size());
  for (const auto& p : first) {
    positions.push_back(p.world_T_part.position_mm);
  }
  std::vector<char*> scattered_ids;
  scattered_ids.reserve(scattered.size());
  for (const auto& id : scattered) {
    scattered_ids.push_back(bus::borrow(id));
  }
  bus::borrow(rm.part_ids, scattered_ids);
  ASSERT_TRUE(call(rm)->status.accepted);
  reply = call(sc);
  ASSERT_TRUE(reply->status.accepted);
  ASSERT_EQ(bus::span(reply->parts).size(), 3U);
  for (std::size_t i = 0; i < 3; ++i) {
    EXPECT_DOUBLE_EQ(reply->parts._buffer[i].world_T_part.position_mm.x, positions[i].x);
    EXPECT_DOUBLE_EQ(reply->parts._buffer[i].world_T_part.position_mm.y, positions[i].y);
  }
  // Too many for the window: refused, nothing added.
  const std::size_t before = bus::span(query()->parts).size();
  sc.count = 200;
  reply = call(sc);
  EXPECT_FALSE(reply->status.accepted);
  EXPECT_THAT(std::string(bus::str(reply->status.reason)), HasSubstr("found no free spot"));
  EXPECT_EQ(bus::span(query()->parts).size(), before);
  // Belt speed on a world without belts.
  cell_world_WorldRequest belt{};
  belt.kind = cell_world_WORLD_SET_BELT;
  const std::string belt_id = "belt1";
  belt.belt_id = bus::borrow(belt_id);
  belt.speed_mm_per_s = 100;
  reply = call(belt);
  EXPECT_FALSE(reply->status.accepted);
  EXPECT_THAT(std::string(bus::str(reply->status.reason)),
              HasSubstr("no belt 'belt1' in the world (belts: none)"));
}

// The must-hold pick, through the bus: the ideal robot's RobotStates at the true grasp point
// attach the part; 5 mm off they do not.
TEST_F(SimWorldTest, RobotStatesPickAtTheGraspPointAndMissFiveMillimetresOff) {
  auto reply = query();
  const auto* ic3 = part_in(reply, "ic3");
  const auto* ic7 = part_in(reply, "ic7");
  ASSERT_NE(ic3, nullptr);
  ASSERT_NE(ic7, nullptr);
  const Eigen::Isometry3d grasp3 =
      *world::pose_from_idl(ic3->world_T_part) * *world::pose_from_idl(ic3->part_T_grasp);
  Eigen::Isometry3d miss7 =
      *world::pose_from_idl(ic7->world_T_part) * *world::pose_from_idl(ic7->part_T_grasp);
  miss7.pretranslate(Eigen::Vector3d(5, 0, 0));
  ASSERT_TRUE(robot_writer_.wait_for_readers(1, 5s));
  // Miss first: open, then closed 5 mm off ic7.
  std::string support;
  robot_state(miss7, cell_robot_GRIPPER_OPEN);
  robot_state(miss7, cell_robot_GRIPPER_CLOSED);
  robot_state(miss7, cell_robot_GRIPPER_OPEN);
  // Then the true grasp point of ic3.
  robot_state(grasp3, cell_robot_GRIPPER_OPEN);
  ASSERT_TRUE(eventually(
      [&] {
        robot_state(grasp3, cell_robot_GRIPPER_CLOSED);
        reply = query();
        const auto* p = part_in(reply, "ic3");
        support = p != nullptr ? std::string(bus::str(p->support)) : "";
        return support == "robot/ibm7545";
      },
      5s))
      << support;
  reply = query();
  EXPECT_EQ(bus::str(part_in(reply, "ic7")->support), "table");
  // Carry it to the thesis's place slot 0 and open: it lies there on the table.
  Eigen::Isometry3d place = Eigen::Isometry3d::Identity();
  place.translation() = Eigen::Vector3d(-250, 250, 750 + 3.81);
  robot_state(place, cell_robot_GRIPPER_CLOSED);
  ASSERT_TRUE(eventually(
      [&] {
        robot_state(place, cell_robot_GRIPPER_OPENING);
        reply = query();
        const auto* p = part_in(reply, "ic3");
        return p != nullptr && bus::str(p->support) == "table";
      },
      5s));
  const auto* placed = part_in(reply, "ic3");
  EXPECT_NEAR(placed->world_T_part.position_mm.x, -250.0, 1e-6);
  EXPECT_NEAR(placed->world_T_part.position_mm.y, 250.0, 1e-6);
  EXPECT_NEAR(placed->world_T_part.position_mm.z, 750.0, 1e-6);
}

class SimWorldBeltTest : public SimWorldTest {
 protected:
  SimWorldBeltTest() : SimWorldTest("belt_conveyor.yaml") {}
};

TEST_F(SimWorldBeltTest, BeltStatesAndPhotocellEdgesAreOnTheBus) {
  bus::Topic<cell_world_PhotocellEvent> pc_topic(client_, bus::topics::kPhotocell);
  bus::Reader<cell_world_PhotocellEvent> pc_reader(client_, pc_topic, bus::topics::kPhotocell);
  bus::Topic<cell_world_BeltState> belt_topic(client_, bus::topics::kBeltState);
  bus::Reader<cell_world_BeltState> belt_reader(client_, belt_topic, bus::topics::kBeltState);
  // Only la1 (80 mm along the belt, at s 40..120) stays, upstream of the beam at s 300.
  const std::string r1 = "r1";
  const std::string d1 = "d1";
  std::vector<char*> ids = {bus::borrow(r1), bus::borrow(d1)};
  cell_world_WorldRequest rm{};
  rm.kind = cell_world_WORLD_REMOVE;
  bus::borrow(rm.part_ids, ids);
  ASSERT_TRUE(call(rm)->status.accepted);
  // Fast, so that it crosses soon.
  cell_world_WorldRequest r{};
  r.kind = cell_world_WORLD_SET_BELT;
  const std::string id = "belt1";
  r.belt_id = bus::borrow(id);
  r.speed_mm_per_s = 1000;
  ASSERT_TRUE(call(r)->status.accepted);
  std::vector<std::pair<bool, std::int64_t>> edges;
  ASSERT_TRUE(eventually(
      [&] {
        (void)pc_reader.take_each(
            [&](const cell_world_PhotocellEvent& e, const dds_sample_info_t&) {
              EXPECT_EQ(bus::str(e.belt_id), "belt1");
              edges.emplace_back(e.blocked, e.encoder_count);
            });
        return edges.size() >= 2;
      },
      10s));
  EXPECT_TRUE(edges[0].first);
  EXPECT_FALSE(edges[1].first);
  EXPECT_GT(edges[1].second, edges[0].second);
  // la1 spans 80 mm along the belt: 80 / 0.03835 counts between its edges.
  EXPECT_NEAR(static_cast<double>(edges[1].second - edges[0].second), 80.0 / 0.0383495, 2.0);
  bool saw_belt = false;
  ASSERT_TRUE(eventually(
      [&] {
        (void)belt_reader.take_each([&](const cell_world_BeltState& b, const dds_sample_info_t&) {
          saw_belt =
              bus::str(b.belt_id) == "belt1" && b.speed_mm_per_s == 1000.0 && b.encoder_count > 0;
        });
        return saw_belt;
      },
      5s));
}

// A loaded host may stall the simulator's loop (here SIGSTOP for 0.6 s). Its belt does not stop
// for that: every consumer extrapolates the belt and its parts by the stamps (the camera's
// exposure, ALTER), so the world's travel must stay on the wall clock. Before the coarse
// catch-up, the loop dropped all but 100 ms of such a backlog: 50 mm of travel lost here.
TEST(SimWorldProcess, AStalledLoopKeepsTheBeltOnTheWallClock) {
  const std::uint32_t domain = cell::testing::test_domain_id();
  const std::string partition = cell::testing::unique_partition();
  const std::string config = ::testing::TempDir() + "/sim-world-stall.yaml";
  std::ofstream(config) << "service: {id: sim-world}\nscene: " << scene_path("belt_conveyor.yaml")
                        << "\n";
  process::SpawnOptions options;
  options.executable = cell::testing::bin_path("cell-sim-world");
  options.args = {"--config", config};
  options.env = cell::testing::bus_env(domain, partition);
  auto world = process::Child::spawn(options);
  ASSERT_THAT(world, IsOk());
  bus::Participant client(domain, partition);
  bus::Topic<cell_world_BeltState> topic(client, bus::topics::kBeltState);
  bus::Reader<cell_world_BeltState> reader(client, topic, bus::topics::kBeltState);
  struct Sample {
    std::int64_t stamp_ns = 0;
    double travel_mm = 0;
    double speed_mm_s = 0;
  };
  auto latest = [&] {
    std::optional<Sample> last;
    (void)reader.take_each([&](const cell_world_BeltState& b, const dds_sample_info_t&) {
      if (bus::str(b.belt_id) == "belt1") {
        last = Sample{b.header.stamp_ns, b.travel_mm, b.speed_mm_per_s};
      }
    });
    return last;
  };
  std::optional<Sample> before;
  ASSERT_TRUE(eventually([&] { return (before = latest()).has_value(); }, 20s)) << world->output();
  std::this_thread::sleep_for(300ms);
  before = latest();
  ASSERT_TRUE(before.has_value());
  ASSERT_EQ(::kill(world->pid(), SIGSTOP), 0);
  std::this_thread::sleep_for(600ms);
  ASSERT_EQ(::kill(world->pid(), SIGCONT), 0);
  std::this_thread::sleep_for(300ms);
  (void)latest();  // what it published while catching up
  std::this_thread::sleep_for(200ms);
  std::optional<Sample> after = latest();
  ASSERT_TRUE(after.has_value());
  const double dt_s = static_cast<double>(after->stamp_ns - before->stamp_ns) * 1e-9;
  const double travel_mm = after->travel_mm - before->travel_mm;
  std::printf("over %.3f s with a 0.6 s stall: belt travel %.2f mm, the wall clock's %.2f mm\n",
              dt_s, travel_mm, before->speed_mm_s * dt_s);
  EXPECT_GT(dt_s, 0.9);
  EXPECT_NEAR(travel_mm, before->speed_mm_s * dt_s, 1.0);
  ASSERT_EQ(::kill(world->pid(), SIGTERM), 0);
  const std::optional<process::ExitInfo> exit = world->wait_for(10s);
  ASSERT_TRUE(exit.has_value()) << "no clean stop within 10 s of SIGTERM";
  EXPECT_TRUE(exit->exited && exit->code == 0) << world->output();
}

}  // namespace
}  // namespace cell::sim_world
