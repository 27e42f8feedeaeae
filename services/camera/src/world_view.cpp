#include "world_view.hpp"

#include <cmath>

#include <fmt/format.h>

#include "cell/bus/view.hpp"

namespace cell::camera {
namespace {

Result<render::Shape> shape_from_idl(const cell_world_PartShape& field) {
  const auto shape = bus::raw(field);  // any value may come off the wire
  switch (shape) {
    case cell_world_SHAPE_DIP:
      return render::Shape::kDip;
    case cell_world_SHAPE_RECTANGLE:
      return render::Shape::kRectangle;
    case cell_world_SHAPE_SQUARE:
      return render::Shape::kSquare;
    case cell_world_SHAPE_DISC:
      return render::Shape::kDisc;
    case cell_world_SHAPE_TRIANGLE:
      return render::Shape::kTriangle;
    case cell_world_SHAPE_BOX:
      return render::Shape::kBox;
    case cell_world_SHAPE_POLYHEDRON:
      return render::Shape::kPolyhedron;
  }
  return Error{Errc::kInvalidArgument, fmt::format("unknown shape {}", shape)};
}

Eigen::Vector3d vec(const cell_common_Vector3& v) { return {v.x, v.y, v.z}; }

Result<render::Part> part_from_idl(const cell_world_WorldPart& wp,
                                   const std::map<std::string, Eigen::Vector3d>& belt_velocity) {
  render::Part p;
  p.id = std::string(bus::str(wp.part_id));
  p.class_name = std::string(bus::str(wp.class_name));
  auto shape = shape_from_idl(wp.shape);
  if (!shape) {
    return std::move(shape).error();
  }
  p.shape = *shape;
  p.length_mm = wp.length_mm;
  p.width_mm = wp.width_mm;
  p.height_mm = wp.height_mm;
  if (wp.pins > 256) {
    return Error{Errc::kInvalidArgument, fmt::format("{} pins is not a DIP", wp.pins)};
  }
  p.pins = static_cast<int>(wp.pins);
  p.reflectance = wp.reflectance;
  if (p.shape == render::Shape::kDip) {
    p.leads = render::DipLeads::standard_for_width(p.width_mm);
  }
  auto pose = pose_from_idl(wp.world_T_part);
  if (!pose) {
    return with_context(std::move(pose).error(), "world_T_part");
  }
  p.world_T_part = *pose;
  if (p.shape == render::Shape::kPolyhedron) {
    for (const auto& v : bus::span(wp.mesh.vertices_mm)) {
      p.mesh.vertices_mm.push_back(vec(v));
    }
    const auto sizes = bus::span(wp.mesh.face_sizes);
    const auto indices = bus::span(wp.mesh.face_indices);
    std::size_t next = 0;
    for (const std::uint32_t n : sizes) {
      if (n > indices.size() - next) {
        return Error{Errc::kInvalidArgument,
                     fmt::format("mesh face sizes need more than the {} face indices given",
                                 indices.size())};
      }
      p.mesh.faces.emplace_back(indices.begin() + static_cast<std::ptrdiff_t>(next),
                                indices.begin() + static_cast<std::ptrdiff_t>(next + n));
      next += n;
    }
  }
  const std::string support(bus::str(wp.support));
  if (support.rfind("belt/", 0) == 0) {
    if (auto it = belt_velocity.find(support.substr(5)); it != belt_velocity.end()) {
      p.velocity_mm_s = it->second;
    }
  }
  CELL_TRY(p.validate());
  return p;
}

}  // namespace

Result<Eigen::Isometry3d> pose_from_idl(const cell_common_Pose& pose) {
  const Eigen::Vector3d t = vec(pose.position_mm);
  Eigen::Quaterniond q(pose.orientation.w, pose.orientation.x, pose.orientation.y,
                       pose.orientation.z);
  if (!t.allFinite() || !q.coeffs().allFinite()) {
    return Error{Errc::kInvalidArgument, "pose has non-finite values"};
  }
  const double n = q.norm();
  if (n < 0.9 || n > 1.1) {
    return Error{Errc::kInvalidArgument,
                 fmt::format("pose quaternion has length {:.3f}, expected 1", n)};
  }
  q.normalize();
  Eigen::Isometry3d out = Eigen::Isometry3d::Identity();
  out.linear() = q.toRotationMatrix();
  out.translation() = t;
  return out;
}

cell_common_Pose pose_to_idl(const Eigen::Isometry3d& pose) {
  const Eigen::Quaterniond q(pose.linear());
  cell_common_Pose out{};
  out.position_mm = {pose.translation().x(), pose.translation().y(), pose.translation().z()};
  out.orientation = {q.w(), q.x(), q.y(), q.z()};
  return out;
}

WorldSnapshot snapshot_from_idl(const cell_world_WorldState& state) {
  WorldSnapshot w;
  w.stamp_ns = state.header.stamp_ns;
  w.world_seq = state.world_seq;
  w.scene.table_height_mm = std::isfinite(state.table_height_mm) ? state.table_height_mm : 0.0;
  std::map<std::string, Eigen::Vector3d> belt_velocity;
  for (const auto& b : bus::span(state.belts)) {
    render::Belt belt;
    belt.id = std::string(bus::str(b.belt_id));
    belt.origin_mm = vec(b.origin_mm);
    belt.direction = vec(b.direction);
    belt.length_mm = b.length_mm;
    belt.width_mm = b.width_mm;
    if (auto s = belt.validate(); !s || !std::isfinite(b.speed_mm_per_s)) {
      w.skipped.push_back(s ? fmt::format("belt '{}': speed is not finite", belt.id)
                            : s.error().message);
      continue;
    }
    belt.direction.normalize();
    belt_velocity[belt.id] = belt.direction * b.speed_mm_per_s;
    w.scene.belts.push_back(std::move(belt));
  }
  for (const auto& wp : bus::span(state.parts)) {
    auto part = part_from_idl(wp, belt_velocity);
    if (!part) {
      w.skipped.push_back(
          fmt::format("part '{}': {}", bus::str(wp.part_id), part.error().message));
      continue;
    }
    w.scene.parts.push_back(std::move(*part));
  }
  return w;
}

render::Scene scene_at(const WorldSnapshot& world, std::int64_t exposure_ns) {
  render::Scene scene = world.scene;
  const double dt_s = static_cast<double>(exposure_ns - world.stamp_ns) * 1e-9;
  for (auto& part : scene.parts) {
    if (!part.velocity_mm_s.isZero()) {
      part.world_T_part.pretranslate(part.velocity_mm_s * dt_s);
    }
  }
  return scene;
}

Status RobotHistory::add(const cell_robot_RobotState& state) {
  const auto q = bus::span(state.position_rad_or_mm);
  if (q.size() > static_cast<std::size_t>(kinematics::kMaxDof)) {
    return Error{Errc::kInvalidArgument,
                 fmt::format("robot '{}' reports {} joints", bus::str(state.robot_id), q.size())};
  }
  Sample s;
  s.stamp_ns = state.header.stamp_ns;
  s.q.resize(static_cast<Eigen::Index>(q.size()));
  for (std::size_t i = 0; i < q.size(); ++i) {
    if (!std::isfinite(q[i])) {
      return Error{Errc::kInvalidArgument,
                   fmt::format("robot '{}': joint {} is not finite", bus::str(state.robot_id), i)};
    }
    s.q[static_cast<Eigen::Index>(i)] = q[i];
  }
  s.halogen_on = state.halogen_on;
  s.fluorescent_on = state.fluorescent_on;
  if (!samples_.empty() && s.stamp_ns < samples_.back().stamp_ns) {
    return ok_status();  // out of order (best-effort stream): the newer sample stands
  }
  samples_.push_back(std::move(s));
  while (samples_.size() > capacity_) {
    samples_.pop_front();
  }
  return ok_status();
}

Result<RobotHistory::Sample> RobotHistory::at(std::int64_t stamp_ns,
                                              std::int64_t max_age_ns) const {
  if (samples_.empty()) {
    return Error{Errc::kNotReady, "no state received"};
  }
  const Sample& last = samples_.back();
  if (stamp_ns >= last.stamp_ns) {
    if (stamp_ns - last.stamp_ns > max_age_ns) {
      return Error{Errc::kNotReady,
                   fmt::format("its latest state is {:.3f} s older than the exposure",
                               static_cast<double>(stamp_ns - last.stamp_ns) * 1e-9)};
    }
    return last;
  }
  if (stamp_ns <= samples_.front().stamp_ns) {
    return samples_.front();
  }
  // The first sample after the exposure and the one before it.
  std::size_t hi = samples_.size() - 1;
  while (hi > 0 && samples_[hi - 1].stamp_ns > stamp_ns) {
    --hi;
  }
  const Sample& a = samples_[hi - 1];
  const Sample& b = samples_[hi];
  Sample out = a;
  if (b.stamp_ns > a.stamp_ns && a.q.size() == b.q.size()) {
    const double t = static_cast<double>(stamp_ns - a.stamp_ns) /
                     static_cast<double>(b.stamp_ns - a.stamp_ns);
    out.q = a.q + t * (b.q - a.q);
    out.stamp_ns = stamp_ns;
  }
  return out;
}

void BeltHistory::add(const Sample& sample) {
  if (!samples_.empty() && sample.stamp_ns <= samples_.back().stamp_ns) {
    return;
  }
  samples_.push_back(sample);
  while (samples_.size() > capacity_) {
    samples_.pop_front();
  }
}

Result<std::int64_t> BeltHistory::count_at(std::int64_t stamp_ns, std::int64_t max_age_ns) const {
  if (samples_.empty()) {
    return Error{Errc::kNotReady, "no belt state received"};
  }
  if (stamp_ns - samples_.back().stamp_ns > max_age_ns) {
    return Error{Errc::kNotReady,
                 fmt::format("its latest state is {:.3f} s older than the exposure",
                             static_cast<double>(stamp_ns - samples_.back().stamp_ns) * 1e-9)};
  }
  if (samples_.size() == 1) {
    return samples_.back().encoder_count;
  }
  // The pair around the exposure, or the last two to extrapolate from.
  std::size_t hi = samples_.size() - 1;
  while (hi > 1 && samples_[hi - 1].stamp_ns >= stamp_ns) {
    --hi;
  }
  const Sample& a = samples_[hi - 1];
  const Sample& b = samples_[hi];
  const double t = static_cast<double>(stamp_ns - a.stamp_ns) /
                   static_cast<double>(b.stamp_ns - a.stamp_ns);
  const double count = static_cast<double>(a.encoder_count) +
                       t * static_cast<double>(b.encoder_count - a.encoder_count);
  return static_cast<std::int64_t>(std::llround(count));
}

std::optional<double> BeltHistory::speed() const {
  if (samples_.empty()) {
    return std::nullopt;
  }
  return samples_.back().speed_mm_per_s;
}

}  // namespace cell::camera
