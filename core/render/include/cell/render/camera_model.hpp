#pragma once

#include <array>

#include <Eigen/Core>

#include "cell/common/result.hpp"

/// The true (or nominal) camera: a pinhole with OpenCV's radial-tangential lens distortion.
///
/// Frames and units. The camera frame has its origin at the centre of projection, z forward
/// along the optical axis, x to the right (image u) and y down (image v). A point p_camera
/// [mm] with z > 0 projects to the normalised ideal coordinates (x/z, y/z), which the lens
/// distorts (OpenCV order k1 k2 p1 p2 k3):
///
///   r2 = x^2 + y^2,  radial = 1 + k1 r2 + k2 r2^2 + k3 r2^3
///   xd = x radial + 2 p1 x y + p2 (r2 + 2 x^2)
///   yd = y radial + p1 (r2 + 2 y^2) + 2 p2 x y
///   u = fx xd + cx,  v = fy yd + cy                                    [px]
///
/// exactly as cv::projectPoints computes it. Pixel (u, v): u = column to the right, v = row
/// down, the top-left pixel's centre at (0, 0), so pixel (i, j) covers [i - 0.5, i + 0.5] x
/// [j - 0.5, j + 0.5] (OpenCV's convention too; idl/vision.idl).
namespace cell::render {

/// Lens distortion coefficients in OpenCV's order and meaning (dimensionless).
struct Distortion {
  double k1 = 0.0;  ///< radial, r^2
  double k2 = 0.0;  ///< radial, r^4
  double p1 = 0.0;  ///< tangential
  double p2 = 0.0;  ///< tangential
  double k3 = 0.0;  ///< radial, r^6

  /// True when every coefficient is exactly 0 (an ideal pinhole).
  bool is_zero() const noexcept;
  /// {k1, k2, p1, p2, k3}: the layout cv::projectPoints and the IDL's `distortion` use.
  std::array<double, 5> as_array() const noexcept { return {k1, k2, p1, p2, k3}; }
};

/// Axis-aligned rectangle in normalised ideal coordinates (x/z, y/z).
struct NormalisedBounds {
  double x_min = 0.0;
  double x_max = 0.0;
  double y_min = 0.0;
  double y_max = 0.0;
};

/// An immutable pinhole camera with distortion: image size, intrinsics and lens. Create it with
/// create(), which validates; copy and share it freely across threads (every method is const,
/// pure and allocation-free unless it returns an error).
class CameraModel {
 public:
  /// Validates and builds a model. Errors (kInvalidArgument, naming the value and the rule):
  /// width/height not in 1..16384, fx/fy not finite and > 0, cx/cy not finite, a non-finite
  /// distortion coefficient, or a lens whose distortion folds back (stops being monotonic)
  /// inside the image, which no real lens does and which would make projection ambiguous.
  static Result<CameraModel> create(int width_px, int height_px, double fx_px, double fy_px,
                                    double cx_px, double cy_px, const Distortion& distortion);

  /// An ideal camera of 1 x 1 px (fx = fy = 1): only for default construction of holders.
  CameraModel() = default;

  int width_px() const noexcept { return width_px_; }
  int height_px() const noexcept { return height_px_; }
  double fx_px() const noexcept { return fx_; }
  double fy_px() const noexcept { return fy_; }
  double cx_px() const noexcept { return cx_; }
  double cy_px() const noexcept { return cy_; }
  const Distortion& distortion() const noexcept { return distortion_; }
  /// The camera matrix K = [fx 0 cx; 0 fy cy; 0 0 1].
  Eigen::Matrix3d camera_matrix() const noexcept;

  /// Normalised ideal -> normalised distorted coordinates (the formula in the file comment).
  Eigen::Vector2d distort(const Eigen::Vector2d& ideal) const noexcept;

  /// Normalised distorted -> normalised ideal coordinates (Newton's method, to 1e-12).
  /// Errors: kOutOfRange when `distorted` lies outside what the lens can produce (beyond the
  /// fold of the distortion polynomial) or the iteration does not converge.
  Result<Eigen::Vector2d> undistort(const Eigen::Vector2d& distorted) const;

  /// Pixel of a point in the camera frame [mm]. Errors: kOutOfRange when the point is not in
  /// front of the camera (z <= 0) or lies outside the lens's valid field (ideal radius beyond
  /// max_ideal_radius(), where the polynomial no longer describes the lens).
  Result<Eigen::Vector2d> project(const Eigen::Vector3d& p_camera) const;

  /// As project() for a point already in normalised ideal coordinates; no error checks
  /// (precondition: the radius is below max_ideal_radius()).
  Eigen::Vector2d project_normalised(const Eigen::Vector2d& ideal) const noexcept;

  /// The viewing ray of a pixel in the camera frame, as (x, y, 1) (not unit length): every
  /// point t * ray, t > 0, projects to `pixel`. Errors: as undistort().
  Result<Eigen::Vector3d> unproject(const Eigen::Vector2d& pixel) const;

  /// Largest normalised ideal radius for which the distortion is monotonic (capped at 4, i.e.
  /// about 76 degrees off axis): beyond it projection is not defined.
  double max_ideal_radius() const noexcept { return max_ideal_radius_; }

  /// The normalised ideal rectangle that contains every pixel of the image (its whole area,
  /// [-0.5, width - 0.5] x [-0.5, height - 0.5]), computed once at creation.
  const NormalisedBounds& image_bounds() const noexcept { return image_bounds_; }

 private:
  int width_px_ = 1;
  int height_px_ = 1;
  double fx_ = 1.0;
  double fy_ = 1.0;
  double cx_ = 0.0;
  double cy_ = 0.0;
  Distortion distortion_;
  double max_ideal_radius_ = 4.0;
  NormalisedBounds image_bounds_;
};

}  // namespace cell::render
