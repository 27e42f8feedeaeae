#pragma once

#include <cstdint>
#include <vector>

#include <Eigen/Geometry>

#include "cell/render/lighting.hpp"
#include "cell/render/scene.hpp"

/// Turns a Scene into lit, front-facing planar faces grouped into bodies (renderer internals).
namespace cell::render::detail {

/// One planar face: a ring of world vertices and its grey value.
struct FaceRecord {
  std::uint32_t first = 0;  ///< into SceneGeometry::vertices
  std::uint32_t count = 0;
  float shade = 0.0F;       ///< grey level (over) or reflectance / table reflectance (modulate)
  std::uint16_t layer = 0;  ///< layers of one body are composited in increasing order
};

/// One body: faces that do not overlap each other within a layer, painted as a unit.
struct BodyRecord {
  std::uint32_t first_face = 0;
  std::uint32_t face_count = 0;
  double depth_mm = 0.0;         ///< distance from the camera: painted far to near
  Eigen::Vector3d velocity_mm_s = Eigen::Vector3d::Zero();
  bool modulate = false;         ///< lit like the table under it (belts)
};

/// The footprint of a flat part in its own frame (x, y) [mm], counter-clockwise seen from +z:
/// rectangle/box/DIP body/square corners starting at (-L/2, -W/2); the triangle's three
/// corners starting at (-L/2, -h/3); a disc as `disc_segments` points. Empty for polyhedra.
std::vector<Eigen::Vector2d> footprint(const Part& part, int disc_segments);

/// Scratch geometry of one frame, reused across frames (clear() keeps capacity).
class SceneGeometry {
 public:
  /// `grey_per_radiance`: 255 * gain. `focal_px`: the larger focal length (sizes discs).
  void begin(const LightField& light, double grey_per_radiance, double focal_px,
             double table_reflectance);

  void add_belt(const Belt& belt);
  void add_part(const Part& part);
  void add_chessboard(const Chessboard& board);

  std::vector<Eigen::Vector3d> vertices;
  std::vector<FaceRecord> faces;
  std::vector<BodyRecord> bodies;

 private:
  void open_body(double depth_mm, const Eigen::Vector3d& velocity, bool modulate);
  void close_body();
  /// Appends the face if it faces the camera; `shade_of(centroid, normal)` gives its grey.
  template <typename ShadeFn>
  void add_face(const Eigen::Vector3d* ring, int n, std::uint16_t layer, ShadeFn&& shade_of);
  void add_prism(const Eigen::Isometry3d& world_T_part, const std::vector<Eigen::Vector2d>& fp,
                 double z0, double z1, double reflectance, std::uint16_t layer);
  void add_dip_leads(const Part& part);
  void add_polyhedron(const Part& part);
  double lambert(double reflectance, const Eigen::Vector3d& c, const Eigen::Vector3d& n) const;

  const LightField* light_ = nullptr;
  double grey_ = 255.0;
  double focal_px_ = 1.0;
  double table_reflectance_ = 0.9;
  std::vector<Eigen::Vector3d> ring_;  // scratch for one face
};

}  // namespace cell::render::detail
