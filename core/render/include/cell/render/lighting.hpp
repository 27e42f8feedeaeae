#pragma once

#include <Eigen/Geometry>

#include "cell/common/result.hpp"

/// The lights of a scene and how a surface point is lit (digest 000 §1.1: "three fluorescent
/// lights, and a halogen lamp next to the camera", switched by the master through relays;
/// digest 002 §1.1: a strobe fired at every acquisition of the belt camera).
///
/// Units. Irradiance is dimensionless and normalised so that a surface of reflectance rho
/// under irradiance E reads 255 * gain * rho * E grey levels (before noise and clipping): E = 1
/// on a white (rho = 1) surface is full scale. Positions in mm; the fluorescent fixture in the
/// world frame, the camera lamp in the camera frame (it moves with the camera).
namespace cell::render {

/// Which lights are on (RobotState halogen_on / fluorescent_on of the 7545's gateway, or the
/// camera's configuration when no robot switches them).
struct LightSwitches {
  bool lamp_on = true;         ///< the lamp beside the camera: the 7545's halogen, a strobe
  bool fluorescent_on = true;  ///< the room's fluorescent tubes above the table
};

/// An immutable light rig. Point sources with inverse-square fall-off and Lambert's cosine;
/// the camera lamp is a spot with cos^spot_exponent fall-off about its axis. Specular
/// highlights (pins) use Blinn-Phong with `shininess`.
struct Lighting {
  double ambient = 0.08;  ///< irradiance from everywhere (walls, ceiling)

  /// Fluorescent fixture (centre of the tubes), world frame [mm]. High above and to one side
  /// of the working area, so the table shows a gradient of a few percent across the field.
  Eigen::Vector3d fluorescent_position_world_mm{400.0, 0.0, 1200.0};
  double fluorescent_irradiance_at_1m = 1.25;  ///< normal incidence, 1000 mm away
  double fluorescent_specular = 0.3;           ///< highlight strength (tubes: weak, broad)

  /// Lamp beside the camera (halogen, strobe), camera frame [mm], and its beam axis.
  Eigen::Vector3d lamp_position_camera_mm{70.0, 0.0, 0.0};
  Eigen::Vector3d lamp_axis_camera{0.0, 0.0, 1.0};
  double lamp_irradiance_at_1m = 0.045;  ///< on the beam axis, normal incidence, 1000 mm away
  double lamp_spot_exponent = 6.0;       ///< beam fall-off cos^n of the angle off its axis
  double lamp_specular = 1.6;            ///< highlight strength (a point-like lamp: strong)

  double shininess = 40.0;  ///< Blinn-Phong exponent of specular surfaces

  /// Ok, or kInvalidArgument naming the first non-finite or negative value.
  Status validate() const;
};

/// Everything needed to light points for one frame: the rig, its switches and where the
/// camera is. Cheap to build per frame; pure and thread-safe.
class LightField {
 public:
  LightField(const Lighting& lighting, const LightSwitches& switches,
             const Eigen::Isometry3d& world_T_camera);

  /// Diffuse irradiance at `point_world` on a surface with unit normal `normal_world`.
  double irradiance(const Eigen::Vector3d& point_world,
                    const Eigen::Vector3d& normal_world) const noexcept;

  /// Specular radiance reflected toward the camera by a glossy cylinder (a DIP pin) through
  /// `point_world` with unit axis `axis_world`: its normals fan around the axis, so the best
  /// one for each light gives the highlight (Blinn-Phong). Add it to rho * irradiance.
  double cylinder_highlight(const Eigen::Vector3d& point_world,
                            const Eigen::Vector3d& axis_world) const noexcept;

  /// The camera's centre in the world [mm].
  const Eigen::Vector3d& camera_position() const noexcept { return camera_position_; }

 private:
  Lighting lighting_;
  LightSwitches switches_;
  Eigen::Vector3d camera_position_;
  Eigen::Vector3d lamp_position_;
  Eigen::Vector3d lamp_axis_;
};

}  // namespace cell::render
