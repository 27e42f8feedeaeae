#include "cell/world/wire.hpp"

#include <fmt/format.h>

#include <cmath>

#include "cell/bus/view.hpp"
#include "cell/geometry/pose.hpp"

namespace cell::world {
namespace {

// A part within 1 deg of upright is spawned by x, y and yaw (cos 1 deg).
constexpr double kSpawnUprightCos = 0.99984769515639127;
constexpr double kSizeTolMm = 0.01;

const WorldStateWire::MeshStorage& mesh_of(const std::shared_ptr<const PartClass>& cls,
                                           WorldStateWire& wire) {
  auto it = wire.meshes.find(cls);
  if (it != wire.meshes.end()) {
    return it->second;
  }
  WorldStateWire::MeshStorage m;
  for (const auto& v : cls->mesh.vertices) {
    m.vertices.push_back(cell_common_Vector3{v.x(), v.y(), v.z()});
  }
  for (const auto& f : cls->mesh.faces) {
    m.face_sizes.push_back(static_cast<std::uint32_t>(f.size()));
    m.face_indices.insert(m.face_indices.end(), f.begin(), f.end());
  }
  return wire.meshes.emplace(cls, std::move(m)).first->second;
}

}  // namespace

cell_world_PartShape to_idl(Shape shape) noexcept {
  switch (shape) {
    case Shape::kDip:
      return cell_world_SHAPE_DIP;
    case Shape::kRectangle:
      return cell_world_SHAPE_RECTANGLE;
    case Shape::kSquare:
      return cell_world_SHAPE_SQUARE;
    case Shape::kDisc:
      return cell_world_SHAPE_DISC;
    case Shape::kTriangle:
      return cell_world_SHAPE_TRIANGLE;
    case Shape::kBox:
      return cell_world_SHAPE_BOX;
    case Shape::kPolyhedron:
      return cell_world_SHAPE_POLYHEDRON;
  }
  return cell_world_SHAPE_RECTANGLE;
}

Result<Shape> from_idl(cell_world_PartShape shape) {
  switch (shape) {
    case cell_world_SHAPE_DIP:
      return Shape::kDip;
    case cell_world_SHAPE_RECTANGLE:
      return Shape::kRectangle;
    case cell_world_SHAPE_SQUARE:
      return Shape::kSquare;
    case cell_world_SHAPE_DISC:
      return Shape::kDisc;
    case cell_world_SHAPE_TRIANGLE:
      return Shape::kTriangle;
    case cell_world_SHAPE_BOX:
      return Shape::kBox;
    case cell_world_SHAPE_POLYHEDRON:
      return Shape::kPolyhedron;
  }
  return Error{Errc::kInvalidArgument,
               fmt::format("unknown part shape {}", static_cast<int>(shape))};
}

GripperState from_idl(cell_robot_GripperState gripper) noexcept {
  switch (gripper) {
    case cell_robot_GRIPPER_OPEN:
      return GripperState::kOpen;
    case cell_robot_GRIPPER_CLOSED:
      return GripperState::kClosed;
    case cell_robot_GRIPPER_OPENING:
      return GripperState::kOpening;
    case cell_robot_GRIPPER_CLOSING:
      return GripperState::kClosing;
    default:
      return GripperState::kUnknown;
  }
}

cell_world_WorldPart part_to_idl(const Part& part, WorldStateWire& wire) {
  const PartClass& cls = *part.cls;
  cell_world_WorldPart out{};
  out.part_id = bus::borrow(part.id);
  out.class_name = bus::borrow(cls.name);
  out.shape = to_idl(cls.shape);
  out.length_mm = cls.length_mm;
  out.width_mm = cls.width_mm;
  out.height_mm = cls.height_mm;
  out.pins = static_cast<std::uint32_t>(cls.dip.pins);
  out.reflectance = cls.reflectance;
  out.world_T_part = pose_to_idl(part.world_T_part);
  out.part_T_grasp = pose_to_idl(cls.part_T_grasp);
  out.support = bus::borrow(part.support_name);
  if (cls.shape == Shape::kPolyhedron) {
    const auto& m = mesh_of(part.cls, wire);
    bus::borrow(out.mesh.vertices_mm, m.vertices);
    bus::borrow(out.mesh.face_sizes, m.face_sizes);
    bus::borrow(out.mesh.face_indices, m.face_indices);
  }
  return out;
}

void fill_parts(const World& world, WorldStateWire& wire) {
  wire.parts.clear();
  wire.parts.reserve(world.parts().size());
  for (const auto& part : world.parts()) {
    wire.parts.push_back(part_to_idl(part, wire));
  }
  for (auto it = wire.meshes.begin(); it != wire.meshes.end();) {
    it = it->first.use_count() == 1 ? wire.meshes.erase(it) : std::next(it);
  }
}

void fill_belts(const World& world,
                std::int64_t stamp_ns,
                std::uint64_t seq,
                WorldStateWire& wire) {
  wire.belts.clear();
  wire.belts.reserve(world.belts().size());
  for (const auto& b : world.belts()) {
    const BeltSpec& s = b.spec;
    const Eigen::Vector3d dir = s.direction();
    cell_world_BeltState out{};
    out.belt_id = bus::borrow(s.id);
    out.header.stamp_ns = stamp_ns;
    out.header.frame_id = bus::borrow(wire.frame_id);
    out.header.seq = seq;
    out.travel_mm = b.travel_mm;
    out.speed_mm_per_s = s.speed_mm_s;
    out.encoder_count = b.encoder_count;
    out.photocell_blocked = b.photocell_blocked;
    out.origin_mm = cell_common_Vector3{s.origin_mm.x(), s.origin_mm.y(), s.origin_mm.z()};
    out.direction = cell_common_Vector3{dir.x(), dir.y(), dir.z()};
    out.length_mm = s.length_mm;
    out.width_mm = s.width_mm;
    out.photocell_at_mm = s.photocell_at_mm;
    wire.belts.push_back(out);
  }
}

void fill_world_state(const World& world,
                      std::int64_t stamp_ns,
                      std::uint64_t header_seq,
                      WorldStateWire& wire) {
  fill_parts(world, wire);
  fill_belts(world, stamp_ns, header_seq, wire);
  wire.message = cell_world_WorldState{};
  wire.message.header.stamp_ns = stamp_ns;
  wire.message.header.frame_id = bus::borrow(wire.frame_id);
  wire.message.header.seq = header_seq;
  wire.message.world_seq = world.seq();
  wire.message.table_height_mm = world.table().height_mm;
  bus::borrow(wire.message.parts, wire.parts);
  bus::borrow(wire.message.belts, wire.belts);
}

Result<PartPlacement> placement_from_idl(const cell_world_WorldPart& part) {
  PartPlacement p;
  p.id = std::string(bus::str(part.part_id));
  p.class_name = std::string(bus::str(part.class_name));
  if (p.class_name.empty()) {
    return Error{Errc::kInvalidArgument, fmt::format("part '{}': class_name is empty", p.id)};
  }
  auto pose = pose_from_idl(part.world_T_part);
  if (!pose) {
    return with_context(std::move(pose).error(), fmt::format("part '{}' world_T_part", p.id));
  }
  if (pose->linear()(2, 2) >= kSpawnUprightCos) {
    p.x_mm = pose->translation().x();
    p.y_mm = pose->translation().y();
    p.yaw = std::atan2(pose->linear()(1, 0), pose->linear()(0, 0));
  } else {
    p.pose = *pose;
  }
  return p;
}

Result<PartClass> class_from_idl(const cell_world_WorldPart& part, const Catalogue& catalogue) {
  const std::string name(bus::str(part.class_name));
  if (auto known = catalogue.find(name); known != nullptr &&
                                         std::abs(known->length_mm - part.length_mm) < kSizeTolMm &&
                                         std::abs(known->width_mm - part.width_mm) < kSizeTolMm &&
                                         std::abs(known->height_mm - part.height_mm) < kSizeTolMm) {
    return *known;
  }
  auto shape = from_idl(part.shape);
  if (!shape) {
    return std::move(shape).error();
  }
  PartClass c;
  if (*shape == Shape::kDip) {
    const double rows = part.width_mm > 10.0 ? 15.24 : (part.width_mm > 7.5 ? 10.16 : 7.62);
    c = make_dip(name, static_cast<int>(part.pins), part.length_mm, part.width_mm, rows);
    c.dip.body_thickness_mm = part.height_mm - c.dip.standoff_mm;
    c.height_mm = part.height_mm;
  } else if (*shape == Shape::kPolyhedron) {
    c.name = name;
    c.shape = Shape::kPolyhedron;
    c.length_mm = part.length_mm;
    c.width_mm = part.width_mm;
    c.height_mm = part.height_mm;
    for (const auto& v : bus::span(part.mesh.vertices_mm)) {
      c.mesh.vertices.emplace_back(v.x, v.y, v.z);
    }
    const auto sizes = bus::span(part.mesh.face_sizes);
    const auto indices = bus::span(part.mesh.face_indices);
    std::size_t next = 0;
    for (const std::uint32_t n : sizes) {
      if (n > indices.size() - next) {
        return Error{Errc::kInvalidArgument,
                     fmt::format("part class '{}': mesh face_sizes ask for more indices than "
                                 "the {} given",
                                 name, indices.size())};
      }
      c.mesh.faces.emplace_back(indices.begin() + static_cast<std::ptrdiff_t>(next),
                                indices.begin() + static_cast<std::ptrdiff_t>(next + n));
      next += n;
    }
  } else {
    c = make_prism(name, *shape, part.length_mm, part.width_mm, part.height_mm, part.reflectance);
  }
  c.reflectance = part.reflectance;
  auto grasp = pose_from_idl(part.part_T_grasp);
  if (!grasp) {
    return with_context(std::move(grasp).error(),
                        fmt::format("part class '{}' part_T_grasp", name));
  }
  c.part_T_grasp = *grasp;
  c.finalize();
  CELL_TRY(c.validate());
  return c;
}

}  // namespace cell::world
