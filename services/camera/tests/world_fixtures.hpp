#pragma once

#include <cmath>
#include <cstdint>
#include <numbers>
#include <string>
#include <vector>

#include <Eigen/Geometry>

#include "cell/bus/idl_types.hpp"
#include "cell/bus/view.hpp"
#include "world_view.hpp"

/// Building bus samples of the world (as cell-sim-world publishes them) in tests.
namespace cell::camera::testing {

/// A part resting on a surface at height z, turned by yaw_deg.
inline cell_common_Pose resting(double x, double y, double z, double yaw_deg) {
  Eigen::Isometry3d pose = Eigen::Isometry3d::Identity();
  pose.translation() = Eigen::Vector3d(x, y, z);
  pose.linear() = Eigen::AngleAxisd(yaw_deg * std::numbers::pi / 180.0, Eigen::Vector3d::UnitZ())
                      .toRotationMatrix();
  return pose_to_idl(pose);
}

/// Storage for a WorldState sample (the C struct borrows from here).
struct WorldStateWire {
  std::vector<std::string> strings;  // reserve()d: pointers into it stay valid
  std::vector<cell_world_WorldPart> parts;
  std::vector<cell_world_BeltState> belts;
  cell_world_WorldState message{};
  std::string frame = "world";
  std::string empty;

  WorldStateWire() { strings.reserve(256); }

  char* keep(const std::string& s) {
    strings.push_back(s);
    return bus::borrow(strings.back());
  }

  cell_world_WorldPart& add_part(const std::string& id, const std::string& cls,
                                 cell_world_PartShape shape, double length, double width,
                                 double height, std::uint32_t pins, double reflectance,
                                 const cell_common_Pose& pose, const std::string& support) {
    cell_world_WorldPart p{};
    p.part_id = keep(id);
    p.class_name = keep(cls);
    p.shape = shape;
    p.length_mm = length;
    p.width_mm = width;
    p.height_mm = height;
    p.pins = pins;
    p.reflectance = reflectance;
    p.world_T_part = pose;
    p.part_T_grasp.orientation.w = 1.0;
    p.support = keep(support);
    parts.push_back(p);
    return parts.back();
  }

  cell_world_BeltState& add_belt(const std::string& id, const Eigen::Vector3d& origin,
                                 const Eigen::Vector3d& direction, double length, double width,
                                 double speed, std::int64_t stamp_ns) {
    cell_world_BeltState b{};
    b.belt_id = keep(id);
    b.header.stamp_ns = stamp_ns;
    b.header.frame_id = bus::borrow(frame);
    b.speed_mm_per_s = speed;
    b.origin_mm = {origin.x(), origin.y(), origin.z()};
    b.direction = {direction.x(), direction.y(), direction.z()};
    b.length_mm = length;
    b.width_mm = width;
    belts.push_back(b);
    return belts.back();
  }

  /// The message, pointing into this wire.
  const cell_world_WorldState& finish(std::int64_t stamp_ns, std::uint64_t world_seq,
                                      double table_height_mm) {
    message = {};
    message.header.stamp_ns = stamp_ns;
    message.header.frame_id = bus::borrow(frame);
    message.header.seq = world_seq;
    message.world_seq = world_seq;
    message.table_height_mm = table_height_mm;
    bus::borrow(message.parts, parts);
    bus::borrow(message.belts, belts);
    return message;
  }
};

}  // namespace cell::camera::testing
