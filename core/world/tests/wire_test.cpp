// IDL conversions: a WorldState carries every part, belt and mesh; poses round-trip; a client
// rebuilds the part classes it draws.
#include "cell/world/wire.hpp"

#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include <cmath>

#include "cell/bus/view.hpp"
#include "cell/testing/env.hpp"
#include "cell/testing/matchers.hpp"

namespace cell::world {
namespace {

using ::cell::testing::IsErrWith;
using ::cell::testing::IsNearPose;
using ::cell::testing::IsOk;

World world_without_robots(const std::string& yaml) {
  const Catalogue cat = Catalogue::standard();
  auto scene = parse_scene(yaml, "wire.yaml", cat);
  EXPECT_THAT(scene, IsOk());
  auto world = World::create(*scene, cat, WorldOptions{});
  EXPECT_THAT(world, IsOk());
  return std::move(world).value();
}

const std::string kScene =
    "table: {height_mm: 750}\n"
    "classes:\n"
    "  - {name: chip, shape: dip, pins: 18, length_mm: 24, width_mm: 7.2}\n"
    "belts:\n"
    "  - {id: b1, origin_mm: [1000, 500, 760], direction_deg: -90, length_mm: 1000,\n"
    "     width_mm: 200, speed_mm_s: 50, mm_per_count: 0.04, photocell_at_mm: 200}\n"
    "parts:\n"
    "  - {id: a, class: dip14, x_mm: 10, y_mm: 20, yaw_deg: 45}\n"
    "  - {id: b3, class: rapt_b3, x_mm: -300, y_mm: 300}\n"
    "  - {id: c, class: chip, x_mm: 1000, y_mm: 300}\n";

TEST(Wire, AWorldStateCarriesEveryPartAndBelt) {
  World w = world_without_robots(kScene);
  WorldStateWire wire;
  fill_world_state(w, 123456789, 7, wire);
  const cell_world_WorldState& m = wire.message;
  EXPECT_EQ(m.header.stamp_ns, 123456789);
  EXPECT_EQ(bus::str(m.header.frame_id), "world");
  EXPECT_EQ(m.header.seq, 7U);
  EXPECT_EQ(m.world_seq, w.seq());
  EXPECT_DOUBLE_EQ(m.table_height_mm, 750.0);
  const auto parts = bus::span(m.parts);
  ASSERT_EQ(parts.size(), 3U);
  EXPECT_EQ(bus::str(parts[0].part_id), "a");
  EXPECT_EQ(bus::str(parts[0].class_name), "dip14");
  EXPECT_EQ(parts[0].shape, cell_world_SHAPE_DIP);
  EXPECT_EQ(parts[0].pins, 14U);
  EXPECT_DOUBLE_EQ(parts[0].length_mm, 19.05);
  EXPECT_EQ(bus::str(parts[0].support), "table");
  EXPECT_DOUBLE_EQ(parts[0].reflectance, 0.1);
  auto pose = pose_from_idl(parts[0].world_T_part);
  ASSERT_THAT(pose, IsOk());
  EXPECT_THAT(*pose, IsNearPose(w.find("a")->world_T_part, 1e-9));
  auto grasp = pose_from_idl(parts[0].part_T_grasp);
  ASSERT_THAT(grasp, IsOk());
  EXPECT_NEAR(grasp->translation().z(), 3.81, 1e-12);
  EXPECT_EQ(bus::span(parts[0].mesh.vertices_mm).size(), 0U);
  // The polyhedron carries its mesh.
  EXPECT_EQ(parts[1].shape, cell_world_SHAPE_POLYHEDRON);
  EXPECT_EQ(bus::span(parts[1].mesh.vertices_mm).size(), 16U);
  EXPECT_EQ(bus::span(parts[1].mesh.face_sizes).size(), 12U);
  std::size_t indices = 0;
  for (const auto n : bus::span(parts[1].mesh.face_sizes)) {
    indices += n;
  }
  EXPECT_EQ(bus::span(parts[1].mesh.face_indices).size(), indices);
  EXPECT_EQ(bus::str(parts[2].support), "belt/b1");
  // The belt.
  const auto belts = bus::span(m.belts);
  ASSERT_EQ(belts.size(), 1U);
  EXPECT_EQ(bus::str(belts[0].belt_id), "b1");
  EXPECT_DOUBLE_EQ(belts[0].speed_mm_per_s, 50.0);
  EXPECT_NEAR(belts[0].direction.y, -1.0, 1e-12);
  EXPECT_NEAR(belts[0].direction.x, 0.0, 1e-12);
  EXPECT_DOUBLE_EQ(belts[0].origin_mm.z, 760.0);
  EXPECT_DOUBLE_EQ(belts[0].photocell_at_mm, 200.0);
  EXPECT_EQ(belts[0].header.stamp_ns, 123456789);
}

TEST(Wire, BeltStateFollowsTheWorld) {
  World w = world_without_robots(kScene);
  std::vector<WorldEvent> events;
  for (int i = 0; i < 100; ++i) {
    w.step(0.01, events);
  }
  WorldStateWire wire;
  fill_belts(w, 1, 1, wire);
  ASSERT_EQ(wire.belts.size(), 1U);
  EXPECT_NEAR(wire.belts[0].travel_mm, 50.0, 1e-9);
  EXPECT_EQ(wire.belts[0].encoder_count, w.belts()[0].encoder_count);
  EXPECT_NEAR(static_cast<double>(wire.belts[0].encoder_count), 50.0 / 0.04, 1.0);
}

TEST(Wire, ClientsRebuildTheClassesTheyDraw) {
  World w = world_without_robots(kScene);
  WorldStateWire wire;
  fill_parts(w, wire);
  const Catalogue standard = Catalogue::standard();
  // A catalogue class comes back as the catalogue's.
  auto dip14 = class_from_idl(wire.parts[0], standard);
  ASSERT_THAT(dip14, IsOk());
  EXPECT_EQ(dip14->dip.pins, 14);
  EXPECT_DOUBLE_EQ(dip14->dip.row_spacing_mm, 7.62);
  // A mesh comes back whole and valid.
  auto b3 = class_from_idl(wire.parts[1], Catalogue{});
  ASSERT_THAT(b3, IsOk());
  EXPECT_THAT(b3->mesh.validate(), IsOk());
  EXPECT_EQ(b3->mesh.faces, w.find("b3")->cls->mesh.faces);
  // A scene's own DIP is rebuilt from shape, sizes and pins.
  auto chip = class_from_idl(wire.parts[2], standard);
  ASSERT_THAT(chip, IsOk());
  EXPECT_EQ(chip->shape, Shape::kDip);
  EXPECT_EQ(chip->dip.pins, 18);
  EXPECT_DOUBLE_EQ(chip->length_mm, 24.0);
  EXPECT_NEAR(chip->height_mm, w.find("c")->cls->height_mm, 1e-12);
  // Garbage is refused.
  cell_world_WorldPart bad = wire.parts[1];
  std::vector<std::uint32_t> sizes = {3, 3, 3, 300};
  bus::borrow(bad.mesh.face_sizes, sizes);
  EXPECT_THAT(class_from_idl(bad, Catalogue{}),
              IsErrWith(Errc::kInvalidArgument, "face_sizes ask for more indices"));
}

TEST(Wire, SpawnPlacementsFromWorldParts) {
  World w = world_without_robots(kScene);
  WorldStateWire wire;
  fill_parts(w, wire);
  auto p = placement_from_idl(wire.parts[0]);
  ASSERT_THAT(p, IsOk());
  EXPECT_EQ(p->id, "a");
  EXPECT_EQ(p->class_name, "dip14");
  EXPECT_FALSE(p->pose.has_value());
  EXPECT_NEAR(p->x_mm, 10.0, 1e-9);
  EXPECT_NEAR(p->y_mm, 20.0, 1e-9);
  EXPECT_NEAR(p->yaw, std::numbers::pi / 4, 1e-12);
  cell_world_WorldPart tilted = wire.parts[0];
  tilted.world_T_part.orientation = cell_common_Quaternion{std::cos(0.3), std::sin(0.3), 0, 0};
  auto t = placement_from_idl(tilted);
  ASSERT_THAT(t, IsOk());
  EXPECT_TRUE(t->pose.has_value());
  cell_world_WorldPart broken = wire.parts[0];
  broken.world_T_part.orientation = cell_common_Quaternion{0, 0, 0, 0};
  EXPECT_THAT(placement_from_idl(broken), IsErrWith(Errc::kInvalidArgument, "quaternion norm"));
  broken = wire.parts[0];
  broken.class_name = nullptr;
  EXPECT_THAT(placement_from_idl(broken), IsErrWith(Errc::kInvalidArgument, "class_name is empty"));
}

TEST(Wire, GripperStatesMap) {
  EXPECT_EQ(from_idl(cell_robot_GRIPPER_OPEN), GripperState::kOpen);
  EXPECT_EQ(from_idl(cell_robot_GRIPPER_CLOSING), GripperState::kClosing);
  EXPECT_EQ(from_idl(cell_robot_GRIPPER_CLOSED), GripperState::kClosed);
  EXPECT_EQ(from_idl(cell_robot_GRIPPER_OPENING), GripperState::kOpening);
  EXPECT_EQ(from_idl(static_cast<cell_robot_GripperState>(7)), GripperState::kUnknown);
  for (const Shape s : {Shape::kDip, Shape::kBox, Shape::kPolyhedron, Shape::kTriangle}) {
    EXPECT_EQ(*from_idl(to_idl(s)), s);
  }
  EXPECT_THAT(from_idl(static_cast<cell_world_PartShape>(7)),
              IsErrWith(Errc::kInvalidArgument, "unknown part shape 7"));
}

}  // namespace
}  // namespace cell::world
