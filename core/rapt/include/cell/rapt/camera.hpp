#pragma once

#include <Eigen/Geometry>
#include <array>

#include "cell/common/result.hpp"
#include "cell/rapt/frames.hpp"

/// The thesis's camera model, window suggester and face generator (digest 003 §2.2-§2.3,
/// thesis §5.6-§5.7).
///
/// Camera frame world_T_camera: X is the lens axis (looking along +X), the origin the lens
/// centre. A world point P with camera coordinates (a, b, c) = camera_T_world * P images at
///     y = F * b / a,   z = F * c / a                        (thesis (5.5)-(5.6), as corrected
/// by the digest: the OCR's "y = b.a/F" does not reproduce Appendix V; F*b/a does, to 5 decimals)
/// in image units (the unit of F; mm for the thesis programs). An image point (y, z) back-
/// projects to the ray (F, y, z) in camera axes.
namespace cell::rapt {

/// An image point (y, z), in the unit of the focal length.
using ImagePoint = Eigen::Vector2d;

/// A pinhole camera at a known pose. Immutable value; cheap to copy.
struct CameraModel {
  Pose world_T_camera = Pose::Identity();  ///< X = lens axis, origin = lens centre
  double focus = 1.0;                      ///< F, image units

  /// The image of a world point [mm]. Errors: kOutOfRange when the point is not in front of
  /// the lens (a <= 1e-9 mm): "behind the camera".
  Result<ImagePoint> project(const Eigen::Vector3d& p_world) const;

  /// d(y, z)/d(p_world) at a point in front of the lens (2x3).
  Eigen::Matrix<double, 2, 3> jacobian(const Eigen::Vector3d& p_world) const;

  /// The unit direction in world axes of the ray through an image point.
  Eigen::Vector3d ray(const ImagePoint& image) const;
};

/// An infinite plane (point, unit normal), world coordinates.
struct Plane {
  Eigen::Vector3d point = Eigen::Vector3d::Zero();
  Eigen::Vector3d normal = Eigen::Vector3d::UnitX();
};

/// The face generator (thesis §5.7.3): the plane through the lens centre containing the rays
/// of two image points of an edge; normal = (F,y1,z1) x (F,y2,z2) in camera axes, turned to
/// world axes. Errors: kInvalidArgument when the two points coincide or are not finite.
Result<Plane> face_from_image(const CameraModel& camera,
                              const ImagePoint& p1,
                              const ImagePoint& p2);

/// A search window (thesis §5.7.1): a rectangle given by three vertices, p1->p2 the short side
/// across the edge, p1->p3 the long side along it (image units).
struct Window {
  ImagePoint p1 = ImagePoint::Zero();
  ImagePoint p2 = ImagePoint::Zero();
  ImagePoint p3 = ImagePoint::Zero();
  double half_width = 0.0;  ///< half of the short side: the tolerance projected across the edge
  /// Margins cut from each end of the predicted edge so that part of the edge is inside the
  /// window whatever the error within the tolerance; when the tolerance exceeds the edge the
  /// window collapses to the middle of the edge and `guaranteed` is false.
  double margin1 = 0.0;
  double margin2 = 0.0;
  bool guaranteed = true;  ///< false when the window collapsed to the edge's middle
};

/// The window suggester: the tolerance box `tolerance_mm` (per world axis, the combined
/// tolerance of (5.1)/(5.2)) is projected, linearised, at each world end point `q1`, `q2` of
/// the edge; the short side is +- the largest projected extent across the edge, the long side
/// the predicted edge shortened at each end by the projected extent along it. This reproduces
/// the printed window of Appendix V situation 11 (e2 of b2, cam6: short side -5.76..13.98,
/// long side 5.76..10.69, printed rounded as (6;-6) (6;14) (11;-6)); the thesis's other
/// windows are not reproduced exactly (digest §2.3: the margins could not be recovered).
/// Errors: kOutOfRange if an end point is behind the camera.
Result<Window> suggest_window(const CameraModel& camera,
                              const Eigen::Vector3d& q1,
                              const Eigen::Vector3d& q2,
                              const Eigen::Vector3d& tolerance_mm);

}  // namespace cell::rapt
