#pragma once

#include <Eigen/Geometry>
#include <cstdint>
#include <map>
#include <memory>
#include <string>
#include <vector>

#include "cell/bus/idl_types.hpp"
#include "cell/common/result.hpp"
#include "cell/geometry/idl_pose.hpp"
#include "cell/world/part_class.hpp"
#include "cell/world/scene.hpp"
#include "cell/world/world.hpp"

/// Conversions between core/world and the bus contract (idl/world.idl, idl/robot.idl). The C
/// structs idlc generates hold raw pointers; the *Wire structs below own the storage those
/// pointers point into, or borrow from the World (bus::borrow semantics): keep the wire AND
/// the world unchanged while the message is written.
namespace cell::world {

/// IDL enum <-> Shape.
cell_world_PartShape to_idl(Shape shape) noexcept;
Result<Shape> from_idl(cell_world_PartShape shape);

/// IDL gripper state -> ours (unknown values become kUnknown).
GripperState from_idl(cell_robot_GripperState gripper) noexcept;

/// IDL Pose <-> Isometry3d (cell/geometry/idl_pose.hpp).
using geometry::pose_from_idl;
using geometry::pose_to_idl;

/// A whole WorldState (or the parts of a WorldReply) ready to write. Meshes are converted once
/// per class and cached in the wire, so reuse one wire across publishes.
struct WorldStateWire {
  cell_world_WorldState message{};
  std::string frame_id = "world";
  std::vector<cell_world_WorldPart> parts;
  std::vector<cell_world_BeltState> belts;
  /// Converted meshes by class (vertices, face sizes, face indices). Holding the class keeps
  /// its address from being reused by another; entries no part uses any more are pruned.
  struct MeshStorage {
    std::vector<cell_common_Vector3> vertices;
    std::vector<std::uint32_t> face_sizes;
    std::vector<std::uint32_t> face_indices;
  };
  std::map<std::shared_ptr<const PartClass>, MeshStorage> meshes;
};

/// Fills `wire.parts` from `world`'s parts (strings borrowed from the world).
void fill_parts(const World& world, WorldStateWire& wire);

/// Fills `wire.belts` from `world`'s belts with `stamp_ns` (strings borrowed from the world).
void fill_belts(const World& world, std::int64_t stamp_ns, std::uint64_t seq, WorldStateWire& wire);

/// Fills the whole WorldState: header {stamp_ns, "world", seq}, world_seq, table height, parts,
/// belts. `wire.message` points into `wire` and `world`.
void fill_world_state(const World& world,
                      std::int64_t stamp_ns,
                      std::uint64_t header_seq,
                      WorldStateWire& wire);

/// One WorldPart for `part` (strings borrowed from the part, mesh from `wire`'s cache).
cell_world_WorldPart part_to_idl(const Part& part, WorldStateWire& wire);

/// A spawn placement from a received WorldPart: class_name and part_id as given; the planar
/// x, y, yaw of world_T_part when its z axis is vertical (within 1 deg; z is ignored: the part
/// drops onto what is below), else the full pose. Errors: kInvalidArgument (bad pose, empty
/// class name).
Result<PartPlacement> placement_from_idl(const cell_world_WorldPart& part);

/// A part class from a received WorldPart, for clients that draw parts (the renderer): the
/// catalogue's entry when `catalogue` knows class_name and its sizes agree within 0.01 mm,
/// else a class rebuilt from shape, sizes, pins, reflectance and mesh (DIP leads get the
/// standard 0.3"/0.6" package by width). Errors: kInvalidArgument for bad sizes or mesh.
Result<PartClass> class_from_idl(const cell_world_WorldPart& part, const Catalogue& catalogue);

}  // namespace cell::world
