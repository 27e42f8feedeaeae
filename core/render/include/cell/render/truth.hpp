#pragma once

#include <string>
#include <vector>

#include <Eigen/Geometry>

#include "cell/render/camera_model.hpp"
#include "cell/render/scene.hpp"

/// Ground truth of a rendered frame: where each part really is, in pixels and in the world
/// (ImageTruth / TruthPart of idl/vision.idl). Pure; thread-safe.
namespace cell::render {

/// One visible part.
struct PartTruth {
  std::string part_id;
  std::string class_name;
  /// Projection of the centre of the part's top face (part frame (0, 0, height)) [px].
  Eigen::Vector2d center_px = Eigen::Vector2d::Zero();
  /// Angle of the part's +x axis in the image, atan2(dv, du) of the projected axis at the top
  /// centre [rad], in (-pi, pi]: 0 along +u, positive turning toward +v (clockwise on screen).
  double angle_rad = 0.0;
  /// The top face's corners [px], in the footprint's order (counter-clockwise seen from above
  /// the part): rectangles, squares, boxes and DIP bodies 4 (from (-L/2, -W/2)), triangles 3;
  /// none for discs and polyhedra.
  std::vector<Eigen::Vector2d> corners_px;
  Eigen::Isometry3d world_T_part = Eigen::Isometry3d::Identity();
  /// Fraction of the top face (of the mesh's bounding footprint for polyhedra) whose points
  /// project inside the image, estimated on a 24 x 24 grid over the face: 0..1. Occlusion by
  /// other parts is not counted.
  double visible_fraction = 0.0;
};

/// Truth for every valid part of `scene` with a visible fraction > 0, in scene order, for the
/// camera `camera` at `world_T_camera`. Invalid parts (Part::validate) are left out, as the
/// renderer leaves them out. When a visible part's top centre cannot be projected (it lies
/// behind the camera or outside the lens's field) its centre and angle stay 0, and corners
/// that cannot be projected are left out: neither happens with the cell's downward cameras.
std::vector<PartTruth> ground_truth(const Scene& scene, const CameraModel& camera,
                                    const Eigen::Isometry3d& world_T_camera);

/// The pixel of the world point `p_world` [mm], or an error (kOutOfRange) when it is behind the
/// camera or outside the lens's field: world_T_camera composed with CameraModel::project.
Result<Eigen::Vector2d> project_world(const CameraModel& camera,
                                      const Eigen::Isometry3d& world_T_camera,
                                      const Eigen::Vector3d& p_world);

}  // namespace cell::render
