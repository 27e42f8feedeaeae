#pragma once

#include <cstdint>
#include <memory>
#include <vector>

#include <Eigen/Geometry>
#include <opencv2/core.hpp>

#include "cell/common/result.hpp"
#include "cell/render/camera_model.hpp"
#include "cell/render/lighting.hpp"
#include "cell/render/scene.hpp"

/// The renderer: draws a Scene as the true camera sees it, into an 8-bit mono image.
///
/// How. Every surface is a planar polygon (part faces, DIP leads, belts, chessboard squares).
/// Each is clipped to the camera's field in 3-D, projected through the full camera model
/// (edges subdivided so that the lens's curvature of straight lines is followed to better than
/// 0.005 px) and rasterised with exact area coverage (signed-area accumulation, as font
/// rasterisers do): a pixel's value is the area-weighted mean of what covers it, so edges,
/// centres and angles are honest to a small fraction of a pixel without supersampling.
/// The faces of one convex body are accumulated together (no seams between them); bodies are
/// painted far to near. The table is a plane lit per pixel (a grid of exact lighting
/// values every 16 px, interpolated); part faces are Lambert-shaded once per face (edges of
/// polyhedra are visible because their faces face the lights differently); DIP leads get a
/// specular highlight. Moving parts are drawn at up to 64 instants across the exposure and
/// averaged (the coverage accumulation is linear, so this costs edges, not pixels): an edge
/// moving d px during the exposure becomes a d px ramp. Finally seeded Gaussian sensor noise
/// (a 4096-level quantile table indexed by xoshiro256**) and rounding to 0..255.
namespace cell::render {

/// Per-frame settings.
struct RenderOptions {
  double exposure_s = 0.0;    ///< integration time for motion blur (0: instantaneous)
  double noise_sigma = 0.0;   ///< sensor noise, standard deviation in grey levels (>= 0)
  std::uint64_t seed = 0;     ///< noise seed: same seed, scene and camera -> same bytes
  double gain = 1.0;          ///< grey = 255 * gain * radiance (> 0)
  double max_segment_px = 8.0;  ///< edge subdivision length under distortion (> 0)

  /// Ok, or kInvalidArgument naming the option and its value.
  Status validate() const;
};

/// What one render did.
struct RenderStats {
  int bodies_drawn = 0;   ///< parts, targets and belts that reached the image
  int faces_drawn = 0;    ///< polygons rasterised (each motion-blur instant counted once)
  int parts_skipped = 0;  ///< parts refused by validate() (see the skipped list)
  std::vector<Error> skipped;  ///< why each skipped part or target was refused
};

/// Renders scenes for one camera model. Holds the model, the lights and per-frame scratch
/// buffers (reused, so a render does not allocate once warmed up). One thread at a time; use
/// one Renderer per thread. Deterministic: the output depends only on the arguments.
class Renderer {
 public:
  /// Errors: kInvalidArgument from lighting.validate().
  static Result<Renderer> create(const CameraModel& camera, const Lighting& lighting);

  Renderer(Renderer&&) noexcept;
  Renderer& operator=(Renderer&&) noexcept;
  ~Renderer();

  const CameraModel& camera() const noexcept;
  const Lighting& lighting() const noexcept;

  /// Draws `scene` seen from the camera at `world_T_camera` (camera frame as in
  /// camera_model.hpp) into `image`, which becomes a continuous CV_8UC1 Mat of the camera's
  /// size (reallocated only when its size or type differ). Parts or targets that fail their
  /// validate() are skipped and listed in the stats, never drawn half. Errors:
  /// kInvalidArgument for bad options or a non-rigid world_T_camera (the image is untouched).
  Result<RenderStats> render(const Scene& scene, const Eigen::Isometry3d& world_T_camera,
                             const RenderOptions& options, cv::Mat& image);

 private:
  struct Impl;
  explicit Renderer(std::unique_ptr<Impl> impl);
  std::unique_ptr<Impl> impl_;
};

}  // namespace cell::render
