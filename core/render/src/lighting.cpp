#include "cell/render/lighting.hpp"

#include <algorithm>
#include <cmath>

#include <fmt/format.h>

namespace cell::render {
namespace {

constexpr double kOneMetre2 = 1000.0 * 1000.0;

/// Irradiance from a point source of strength `at_1m` at `light`, on `normal` at `point`.
double point_source(const Eigen::Vector3d& light, double at_1m, const Eigen::Vector3d& point,
                    const Eigen::Vector3d& normal, Eigen::Vector3d* to_light_unit) {
  const Eigen::Vector3d to_light = light - point;
  const double d2 = std::max(to_light.squaredNorm(), 1.0);
  const Eigen::Vector3d l = to_light / std::sqrt(d2);
  if (to_light_unit != nullptr) {
    *to_light_unit = l;
  }
  return at_1m * kOneMetre2 / d2 * std::max(0.0, normal.dot(l));
}

/// Best Blinn-Phong term of a cylinder with unit axis `axis`: the normal in its fan closest to
/// the half vector h has n.h = sqrt(1 - (h.axis)^2).
double cylinder_lobe(const Eigen::Vector3d& to_light, const Eigen::Vector3d& to_camera,
                     const Eigen::Vector3d& axis, double shininess) {
  const Eigen::Vector3d h = (to_light + to_camera).normalized();
  const double ha = h.dot(axis);
  const double nh = std::sqrt(std::max(0.0, 1.0 - ha * ha));
  return std::pow(nh, shininess);
}

}  // namespace

Status Lighting::validate() const {
  auto bad = [](const char* what, double v) {
    return Error{Errc::kInvalidArgument,
                 fmt::format("lighting {} = {}: must be finite and >= 0", what, v)};
  };
  const std::pair<const char*, double> scalars[] = {
      {"ambient", ambient},
      {"fluorescent_irradiance_at_1m", fluorescent_irradiance_at_1m},
      {"fluorescent_specular", fluorescent_specular},
      {"lamp_irradiance_at_1m", lamp_irradiance_at_1m},
      {"lamp_spot_exponent", lamp_spot_exponent},
      {"lamp_specular", lamp_specular},
      {"shininess", shininess}};
  for (const auto& [name, v] : scalars) {
    if (!std::isfinite(v) || v < 0.0) {
      return bad(name, v);
    }
  }
  if (!fluorescent_position_world_mm.allFinite() || !lamp_position_camera_mm.allFinite()) {
    return Error{Errc::kInvalidArgument, "lighting: a light position is not finite"};
  }
  if (!lamp_axis_camera.allFinite() || lamp_axis_camera.norm() < 1e-9) {
    return Error{Errc::kInvalidArgument, "lighting: the lamp axis must be a non-zero vector"};
  }
  return ok_status();
}

LightField::LightField(const Lighting& lighting, const LightSwitches& switches,
                       const Eigen::Isometry3d& world_T_camera)
    : lighting_(lighting),
      switches_(switches),
      camera_position_(world_T_camera.translation()),
      lamp_position_(world_T_camera * lighting.lamp_position_camera_mm),
      lamp_axis_((world_T_camera.linear() * lighting.lamp_axis_camera).normalized()) {}

double LightField::irradiance(const Eigen::Vector3d& point_world,
                              const Eigen::Vector3d& normal_world) const noexcept {
  double e = lighting_.ambient;
  if (switches_.fluorescent_on) {
    e += point_source(lighting_.fluorescent_position_world_mm,
                      lighting_.fluorescent_irradiance_at_1m, point_world, normal_world, nullptr);
  }
  if (switches_.lamp_on) {
    Eigen::Vector3d l;
    const double lambert = point_source(lamp_position_, lighting_.lamp_irradiance_at_1m,
                                        point_world, normal_world, &l);
    const double off_axis = std::max(0.0, -l.dot(lamp_axis_));
    e += lambert * std::pow(off_axis, lighting_.lamp_spot_exponent);
  }
  return e;
}

double LightField::cylinder_highlight(const Eigen::Vector3d& point_world,
                                      const Eigen::Vector3d& axis_world) const noexcept {
  const Eigen::Vector3d to_camera = (camera_position_ - point_world).normalized();
  double s = 0.0;
  if (switches_.fluorescent_on) {
    Eigen::Vector3d l;
    // Strength: the source's irradiance facing it (normal = l), times the lobe.
    const Eigen::Vector3d to_light = lighting_.fluorescent_position_world_mm - point_world;
    l = to_light.normalized();
    const double e = point_source(lighting_.fluorescent_position_world_mm,
                                  lighting_.fluorescent_irradiance_at_1m, point_world, l, nullptr);
    s += lighting_.fluorescent_specular * e *
         cylinder_lobe(l, to_camera, axis_world, lighting_.shininess);
  }
  if (switches_.lamp_on) {
    const Eigen::Vector3d l = (lamp_position_ - point_world).normalized();
    const double e = point_source(lamp_position_, lighting_.lamp_irradiance_at_1m, point_world, l,
                                  nullptr) *
                     std::pow(std::max(0.0, -l.dot(lamp_axis_)), lighting_.lamp_spot_exponent);
    s += lighting_.lamp_specular * e * cylinder_lobe(l, to_camera, axis_world, lighting_.shininess);
  }
  return s;
}

}  // namespace cell::render
