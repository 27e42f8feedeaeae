#include "cell/render/truth.hpp"

#include <algorithm>
#include <cmath>

#include "scene_builder.hpp"

namespace cell::render {
namespace {

constexpr int kVisibilityGrid = 24;
constexpr int kDiscTruthSegments = 64;

bool inside_image(const CameraModel& camera, const Eigen::Vector2d& px) {
  return px.x() >= -0.5 && px.y() >= -0.5 && px.x() <= camera.width_px() - 0.5 &&
         px.y() <= camera.height_px() - 0.5;
}

/// Point-in-convex-polygon (counter-clockwise) test.
bool inside_convex(const std::vector<Eigen::Vector2d>& poly, const Eigen::Vector2d& p) {
  const std::size_t n = poly.size();
  for (std::size_t i = 0; i < n; ++i) {
    const Eigen::Vector2d e = poly[(i + 1) % n] - poly[i];
    const Eigen::Vector2d q = p - poly[i];
    if (e.x() * q.y() - e.y() * q.x() < 0.0) {
      return false;
    }
  }
  return true;
}

}  // namespace

Result<Eigen::Vector2d> project_world(const CameraModel& camera,
                                      const Eigen::Isometry3d& world_T_camera,
                                      const Eigen::Vector3d& p_world) {
  return camera.project(world_T_camera.inverse() * p_world);
}

std::vector<PartTruth> ground_truth(const Scene& scene, const CameraModel& camera,
                                    const Eigen::Isometry3d& world_T_camera) {
  std::vector<PartTruth> out;
  const Eigen::Isometry3d camera_T_world = world_T_camera.inverse();
  auto pixel = [&](const Eigen::Vector3d& p_world) {
    return camera.project(camera_T_world * p_world);
  };
  for (const Part& part : scene.parts) {
    if (!part.validate()) {
      continue;
    }
    const double h = part.height_mm;
    // The face whose visibility counts: the footprint at the top, or for a polyhedron the
    // bounding rectangle of its vertices at its highest z.
    std::vector<Eigen::Vector2d> face = detail::footprint(part, kDiscTruthSegments);
    double z_top = h;
    if (part.shape == Shape::kPolyhedron) {
      Eigen::Vector3d lo = part.mesh.vertices_mm.front();
      Eigen::Vector3d hi = lo;
      for (const auto& v : part.mesh.vertices_mm) {
        lo = lo.cwiseMin(v);
        hi = hi.cwiseMax(v);
      }
      face = {{lo.x(), lo.y()}, {hi.x(), lo.y()}, {hi.x(), hi.y()}, {lo.x(), hi.y()}};
      z_top = hi.z();
    }
    Eigen::Vector2d lo2 = face.front();
    Eigen::Vector2d hi2 = lo2;
    for (const auto& p : face) {
      lo2 = lo2.cwiseMin(p);
      hi2 = hi2.cwiseMax(p);
    }
    int total = 0;
    int visible = 0;
    for (int j = 0; j < kVisibilityGrid; ++j) {
      for (int i = 0; i < kVisibilityGrid; ++i) {
        const Eigen::Vector2d q(lo2.x() + (hi2.x() - lo2.x()) * (i + 0.5) / kVisibilityGrid,
                                lo2.y() + (hi2.y() - lo2.y()) * (j + 0.5) / kVisibilityGrid);
        if (!inside_convex(face, q)) {
          continue;
        }
        ++total;
        auto px = pixel(part.world_T_part * Eigen::Vector3d(q.x(), q.y(), z_top));
        if (px && inside_image(camera, *px)) {
          ++visible;
        }
      }
    }
    if (total == 0 || visible == 0) {
      continue;
    }
    PartTruth t;
    t.part_id = part.id;
    t.class_name = part.class_name;
    t.world_T_part = part.world_T_part;
    t.visible_fraction = static_cast<double>(visible) / total;
    const double axis_mm = std::max(0.5 * part.length_mm, 1.0);
    auto c = pixel(part.world_T_part * Eigen::Vector3d(0.0, 0.0, h));
    auto a = pixel(part.world_T_part * Eigen::Vector3d(axis_mm, 0.0, h));
    if (c && a) {
      t.center_px = *c;
      t.angle_rad = std::atan2(a->y() - c->y(), a->x() - c->x());
    }
    if (part.shape != Shape::kDisc && part.shape != Shape::kPolyhedron) {
      for (const auto& p : detail::footprint(part, 0)) {
        auto px = pixel(part.world_T_part * Eigen::Vector3d(p.x(), p.y(), h));
        if (px) {
          t.corners_px.push_back(*px);
        }
      }
    }
    out.push_back(std::move(t));
  }
  return out;
}

}  // namespace cell::render
