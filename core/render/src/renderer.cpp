#include "cell/render/renderer.hpp"

#include <algorithm>
#include <cmath>
#include <numeric>

#include <fmt/format.h>

#include "cell/geometry/pose.hpp"
#include "coverage.hpp"
#include "scene_builder.hpp"

namespace cell::render {
namespace {

constexpr int kGridStep = 16;         // background lighting grid spacing [px]
constexpr double kNearMm = 1.0;       // near clipping plane
constexpr double kFieldMargin = 0.02; // frustum margin around the image, fraction of its span
constexpr int kMaxInstants = 64;      // motion-blur instants per exposure

}  // namespace

Status RenderOptions::validate() const {
  if (!(std::isfinite(exposure_s) && exposure_s >= 0.0 && exposure_s <= 10.0)) {
    return Error{Errc::kInvalidArgument,
                 fmt::format("exposure_s = {}: must be in [0, 10] s", exposure_s)};
  }
  if (!(std::isfinite(noise_sigma) && noise_sigma >= 0.0 && noise_sigma <= 255.0)) {
    return Error{Errc::kInvalidArgument,
                 fmt::format("noise_sigma = {}: must be in [0, 255] grey levels", noise_sigma)};
  }
  if (!(std::isfinite(gain) && gain > 0.0)) {
    return Error{Errc::kInvalidArgument, fmt::format("gain = {}: must be finite and > 0", gain)};
  }
  if (!(std::isfinite(max_segment_px) && max_segment_px > 0.0)) {
    return Error{Errc::kInvalidArgument,
                 fmt::format("max_segment_px = {}: must be finite and > 0", max_segment_px)};
  }
  return ok_status();
}

struct Renderer::Impl {
  CameraModel camera;
  Lighting lighting;
  // Clipping frustum in normalised ideal coordinates: the image plus a margin.
  NormalisedBounds field;
  // Background grid: node (k, l) sits at pixel (k * step, l * step), clamped into the image.
  int grid_cols = 0;
  int grid_rows = 0;
  std::vector<Eigen::Vector3d> grid_rays;  // camera frame, (x, y, 1)
  // Per-frame scratch.
  std::vector<float> grid_values;
  std::vector<float> column_values;
  std::vector<float> canvas;
  detail::SceneGeometry geometry;
  detail::CoverageAccumulator accumulator;
  std::vector<std::uint32_t> order;
  std::vector<Eigen::Vector3d> camera_ring;
  std::vector<Eigen::Vector3d> clip_a;
  std::vector<Eigen::Vector3d> clip_b;
  std::vector<detail::RasterPoint> points;
  struct Ring {
    std::uint32_t first;
    std::uint32_t count;
    float coverage_weight;
    float shade_weight;
  };
  std::vector<Ring> rings;

  void fill_background(const Scene& scene, const Eigen::Isometry3d& world_T_camera,
                       const LightField& light, double grey);
  /// Clips `in` (camera frame) to the field; result in clip_a. Returns its size.
  std::size_t clip(const Eigen::Vector3d* in, std::size_t n);
  /// Projects the clipped ring in clip_a into `points` (subdividing under distortion).
  void emit_ring(std::size_t n, double max_segment_px);
  void draw_layer(const detail::BodyRecord& body, std::uint32_t face_begin,
                  std::uint32_t face_end, const Eigen::Isometry3d& camera_T_world,
                  const RenderOptions& options, RenderStats& stats);
};

Result<Renderer> Renderer::create(const CameraModel& camera, const Lighting& lighting) {
  CELL_TRY(lighting.validate());
  auto impl = std::make_unique<Impl>();
  impl->camera = camera;
  impl->lighting = lighting;
  const NormalisedBounds& b = camera.image_bounds();
  const double mx = kFieldMargin * (b.x_max - b.x_min);
  const double my = kFieldMargin * (b.y_max - b.y_min);
  NormalisedBounds f{b.x_min - mx, b.x_max + mx, b.y_min - my, b.y_max + my};
  // Keep the frustum's corners inside the lens's valid field.
  const double r_max = camera.max_ideal_radius();
  for (int i = 0; i < 40; ++i) {
    const double rx = std::max(std::abs(f.x_min), std::abs(f.x_max));
    const double ry = std::max(std::abs(f.y_min), std::abs(f.y_max));
    if (std::hypot(rx, ry) <= r_max) {
      break;
    }
    f = {0.5 * (f.x_min + b.x_min), 0.5 * (f.x_max + b.x_max), 0.5 * (f.y_min + b.y_min),
         0.5 * (f.y_max + b.y_max)};
  }
  impl->field = f;
  const int w = camera.width_px();
  const int h = camera.height_px();
  impl->grid_cols = (w - 1) / kGridStep + 2;
  impl->grid_rows = (h - 1) / kGridStep + 2;
  impl->grid_rays.reserve(static_cast<std::size_t>(impl->grid_cols) *
                          static_cast<std::size_t>(impl->grid_rows));
  for (int l = 0; l < impl->grid_rows; ++l) {
    for (int k = 0; k < impl->grid_cols; ++k) {
      const Eigen::Vector2d px(std::min(k * kGridStep, w - 1), std::min(l * kGridStep, h - 1));
      auto ray = camera.unproject(px);
      // Every pixel of the image has a ray (create() checked the border); guard anyway.
      impl->grid_rays.push_back(ray ? *ray : Eigen::Vector3d(0.0, 0.0, 1.0));
    }
  }
  impl->grid_values.resize(impl->grid_rays.size());
  impl->column_values.resize(static_cast<std::size_t>(impl->grid_cols));
  impl->canvas.resize(static_cast<std::size_t>(w) * static_cast<std::size_t>(h));
  return Renderer(std::move(impl));
}

Renderer::Renderer(std::unique_ptr<Impl> impl) : impl_(std::move(impl)) {}
Renderer::Renderer(Renderer&&) noexcept = default;
Renderer& Renderer::operator=(Renderer&&) noexcept = default;
Renderer::~Renderer() = default;

const CameraModel& Renderer::camera() const noexcept { return impl_->camera; }
const Lighting& Renderer::lighting() const noexcept { return impl_->lighting; }

void Renderer::Impl::fill_background(const Scene& scene, const Eigen::Isometry3d& world_T_camera,
                                     const LightField& light, double grey) {
  const Eigen::Matrix3d& r = world_T_camera.linear();
  const Eigen::Vector3d o = world_T_camera.translation();
  const Eigen::Vector3d up = Eigen::Vector3d::UnitZ();
  const double table_grey = grey * scene.table_reflectance;
  const float beyond = static_cast<float>(table_grey * lighting.ambient * 0.5);
  for (std::size_t i = 0; i < grid_rays.size(); ++i) {
    const Eigen::Vector3d d = r * grid_rays[i];
    const double t = d.z() != 0.0 ? (scene.table_height_mm - o.z()) / d.z() : -1.0;
    if (t > 0.0 && std::isfinite(t)) {
      grid_values[i] = static_cast<float>(table_grey * light.irradiance(o + t * d, up));
    } else {
      grid_values[i] = beyond;  // the ray misses the table: the dim room beyond it
    }
  }
  const int w = camera.width_px();
  const int h = camera.height_px();
  constexpr float kInvStep = 1.0F / kGridStep;
  for (int v = 0; v < h; ++v) {
    const int l = v / kGridStep;
    const float fy = static_cast<float>(v - l * kGridStep) * kInvStep;
    const float* g0 = grid_values.data() + static_cast<std::ptrdiff_t>(l) * grid_cols;
    const float* g1 = g0 + grid_cols;
    for (int k = 0; k < grid_cols; ++k) {
      column_values[static_cast<std::size_t>(k)] = g0[k] + (g1[k] - g0[k]) * fy;
    }
    float* row = canvas.data() + static_cast<std::ptrdiff_t>(v) * w;
    for (int k = 0; k + 1 < grid_cols; ++k) {
      const int u0 = k * kGridStep;
      if (u0 >= w) {
        break;
      }
      const int u1 = std::min(u0 + kGridStep, w);
      const float a = column_values[static_cast<std::size_t>(k)];
      const float step = (column_values[static_cast<std::size_t>(k) + 1] - a) * kInvStep;
      for (int u = u0; u < u1; ++u) {
        row[u] = a + step * static_cast<float>(u - u0);
      }
    }
  }
}

std::size_t Renderer::Impl::clip(const Eigen::Vector3d* in, std::size_t n) {
  clip_a.assign(in, in + n);
  // Most faces lie wholly inside the field: nothing to cut.
  bool inside = true;
  for (std::size_t i = 0; i < n && inside; ++i) {
    const Eigen::Vector3d& p = in[i];
    inside = p.z() >= kNearMm && p.x() >= field.x_min * p.z() && p.x() <= field.x_max * p.z() &&
             p.y() >= field.y_min * p.z() && p.y() <= field.y_max * p.z();
  }
  if (inside) {
    return n >= 3 ? n : 0;
  }
  // Planes as f(p) >= 0: near, left, right, top, bottom of the field.
  const std::array<Eigen::Vector4d, 5> planes = {
      Eigen::Vector4d(0.0, 0.0, 1.0, -kNearMm),
      Eigen::Vector4d(1.0, 0.0, -field.x_min, 0.0),
      Eigen::Vector4d(-1.0, 0.0, field.x_max, 0.0),
      Eigen::Vector4d(0.0, 1.0, -field.y_min, 0.0),
      Eigen::Vector4d(0.0, -1.0, field.y_max, 0.0)};
  for (const Eigen::Vector4d& pl : planes) {
    if (clip_a.empty()) {
      break;
    }
    clip_b.clear();
    const std::size_t m = clip_a.size();
    for (std::size_t i = 0; i < m; ++i) {
      const Eigen::Vector3d& a = clip_a[i];
      const Eigen::Vector3d& b = clip_a[(i + 1) % m];
      const double fa = pl.head<3>().dot(a) + pl.w();
      const double fb = pl.head<3>().dot(b) + pl.w();
      if (fa >= 0.0) {
        clip_b.push_back(a);
      }
      if ((fa >= 0.0) != (fb >= 0.0)) {
        clip_b.push_back(a + (b - a) * (fa / (fa - fb)));
      }
    }
    clip_a.swap(clip_b);
  }
  return clip_a.size() >= 3 ? clip_a.size() : 0;
}

void Renderer::Impl::emit_ring(std::size_t n, double max_segment_px) {
  const bool distorted = !camera.distortion().is_zero();
  const double fx = camera.fx_px();
  const double fy = camera.fy_px();
  auto push = [&](const Eigen::Vector2d& ideal) {
    const Eigen::Vector2d px = camera.project_normalised(ideal);
    points.push_back({px.x() + 0.5, px.y() + 0.5});
  };
  for (std::size_t i = 0; i < n; ++i) {
    const Eigen::Vector3d& pa = clip_a[i];
    const Eigen::Vector2d a(pa.x() / pa.z(), pa.y() / pa.z());
    push(a);
    if (!distorted) {
      continue;
    }
    // A straight 3-D edge is straight in the ideal image; the lens bends it. Follow it with
    // chords of at most max_segment_px (sagitta well below 0.005 px for this cell's lenses).
    const Eigen::Vector3d& pb = clip_a[(i + 1) % n];
    const Eigen::Vector2d b(pb.x() / pb.z(), pb.y() / pb.z());
    const double len_px = std::hypot((b.x() - a.x()) * fx, (b.y() - a.y()) * fy);
    const int pieces = static_cast<int>(std::ceil(len_px / max_segment_px));
    for (int k = 1; k < pieces; ++k) {
      push(a + (b - a) * (static_cast<double>(k) / pieces));
    }
  }
}

void Renderer::Impl::draw_layer(const detail::BodyRecord& body, std::uint32_t face_begin,
                                std::uint32_t face_end, const Eigen::Isometry3d& camera_T_world,
                                const RenderOptions& options, RenderStats& stats) {
  points.clear();
  rings.clear();
  // Motion blur: instants across the exposure, two per pixel of image motion.
  const Eigen::Vector3d travel = body.velocity_mm_s * options.exposure_s;
  int instants = 1;
  if (travel.squaredNorm() > 0.0) {
    const double focal = std::max(camera.fx_px(), camera.fy_px());
    const double blur_px = focal * travel.norm() / std::max(body.depth_mm, 1.0);
    instants = static_cast<int>(std::clamp(std::ceil(2.0 * blur_px), 1.0,
                                           static_cast<double>(kMaxInstants)));
  }
  const float weight = 1.0F / static_cast<float>(instants);
  for (std::uint32_t f = face_begin; f < face_end; ++f) {
    const detail::FaceRecord& face = geometry.faces[f];
    const Eigen::Vector3d* world = geometry.vertices.data() + face.first;
    if (camera_ring.size() < face.count) {
      camera_ring.resize(face.count);
    }
    Eigen::Vector3d* ring = camera_ring.data();
    for (int k = 0; k < instants; ++k) {
      const double t = instants == 1 ? 0.0 : (k + 0.5) / instants - 0.5;
      const Eigen::Vector3d offset = travel * t;
      for (std::uint32_t i = 0; i < face.count; ++i) {
        ring[i] = camera_T_world * (world[i] + offset);
      }
      const std::size_t n = clip(ring, face.count);
      if (n == 0) {
        continue;
      }
      const auto first = static_cast<std::uint32_t>(points.size());
      emit_ring(n, options.max_segment_px);
      rings.push_back({first, static_cast<std::uint32_t>(points.size()) - first, weight,
                       weight * face.shade});
      ++stats.faces_drawn;
    }
  }
  if (rings.empty()) {
    return;
  }
  double x_min = 1e300;
  double x_max = -1e300;
  double y_min = 1e300;
  double y_max = -1e300;
  for (const auto& p : points) {
    x_min = std::min(x_min, p.x);
    x_max = std::max(x_max, p.x);
    y_min = std::min(y_min, p.y);
    y_max = std::max(y_max, p.y);
  }
  const int w = camera.width_px();
  const int h = camera.height_px();
  const int x0 = static_cast<int>(std::floor(x_min));
  const int x1 = static_cast<int>(std::ceil(x_max));
  const int y0 = std::max(0, static_cast<int>(std::floor(y_min)));
  const int y1 = std::min(h, static_cast<int>(std::ceil(y_max)));
  if (y1 <= y0 || x1 <= 0 || x0 >= w) {
    return;
  }
  accumulator.reset(x0, y0, x1 - x0, y1 - y0);
  for (const Ring& r : rings) {
    accumulator.add_ring(points.data() + r.first, static_cast<int>(r.count), r.coverage_weight,
                         r.shade_weight);
  }
  if (body.modulate) {
    accumulator.composite_modulate(canvas.data(), w, h);
  } else {
    accumulator.composite_over(canvas.data(), w, h);
  }
}

Result<RenderStats> Renderer::render(const Scene& scene, const Eigen::Isometry3d& world_T_camera,
                                     const RenderOptions& options, cv::Mat& image) {
  CELL_TRY(options.validate());
  CELL_TRY(geometry::check_rigid(world_T_camera, "world_T_camera", 1e-6));
  if (!(std::isfinite(scene.table_height_mm) && std::isfinite(scene.table_reflectance) &&
        scene.table_reflectance >= 0.0 && scene.table_reflectance <= 1.0)) {
    return Error{Errc::kInvalidArgument,
                 fmt::format("table height {} mm / reflectance {}: must be finite, reflectance "
                             "in [0, 1]",
                             scene.table_height_mm, scene.table_reflectance)};
  }
  Impl& s = *impl_;
  RenderStats stats;
  const double grey = 255.0 * options.gain;
  const LightField light(s.lighting, scene.lights, world_T_camera);
  const Eigen::Isometry3d camera_T_world = world_T_camera.inverse();

  s.fill_background(scene, world_T_camera, light, grey);

  s.geometry.begin(light, grey, std::max(s.camera.fx_px(), s.camera.fy_px()),
                   scene.table_reflectance);
  for (const Belt& belt : scene.belts) {
    if (auto v = belt.validate(); !v) {
      stats.skipped.push_back(v.error());
      continue;
    }
    s.geometry.add_belt(belt);
  }
  for (const Chessboard& board : scene.targets) {
    if (auto v = board.validate(); !v) {
      stats.skipped.push_back(v.error());
      continue;
    }
    s.geometry.add_chessboard(board);
  }
  for (const Part& part : scene.parts) {
    if (auto v = part.validate(); !v) {
      stats.skipped.push_back(v.error());
      ++stats.parts_skipped;
      continue;
    }
    s.geometry.add_part(part);
  }
  // Far to near (belts first: they lie under everything); ties keep scene order.
  s.order.resize(s.geometry.bodies.size());
  std::iota(s.order.begin(), s.order.end(), 0U);
  std::stable_sort(s.order.begin(), s.order.end(), [&](std::uint32_t a, std::uint32_t b) {
    return s.geometry.bodies[a].depth_mm > s.geometry.bodies[b].depth_mm;
  });
  for (const std::uint32_t index : s.order) {
    const detail::BodyRecord& body = s.geometry.bodies[index];
    const int faces_before = stats.faces_drawn;
    std::uint32_t begin = body.first_face;
    const std::uint32_t end = body.first_face + body.face_count;
    while (begin < end) {
      std::uint32_t stop = begin + 1;
      while (stop < end && s.geometry.faces[stop].layer == s.geometry.faces[begin].layer) {
        ++stop;
      }
      s.draw_layer(body, begin, stop, camera_T_world, options, stats);
      begin = stop;
    }
    if (stats.faces_drawn > faces_before) {
      ++stats.bodies_drawn;
    }
  }

  image.create(s.camera.height_px(), s.camera.width_px(), CV_8UC1);
  detail::add_noise_and_quantise(s.canvas.data(), s.canvas.size(), options.noise_sigma,
                                 options.seed, image.ptr<std::uint8_t>(0));
  return stats;
}

}  // namespace cell::render
