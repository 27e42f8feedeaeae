#pragma once

#include <Eigen/Geometry>
#include <memory>
#include <optional>
#include <span>
#include <string>

#include "cell/calibration/camera_calibration.hpp"
#include "cell/common/result.hpp"
#include "cell/kinematics/robot_model.hpp"
#include "cell/render/camera_model.hpp"

/// From image pixels to the plane the parts lie on, and on to the robot.
///
/// Vision fits outlines in a **plane frame**: a 2-D metric frame (mm) on the working plane. A
/// pixel seen on a surface `h` mm above the working plane (a part's top face, the bottom edge
/// of its wall) maps to the point (x, y) of that surface; all points of a vertical wall then
/// share (x, y), which is how the parallax of part heights is removed. The plane frame is:
///
/// - pinhole calibration: the robot base frame itself (x, y of the base frame, z up; the plane
///   z = working_plane_z_mm + h). A pixel is undistorted with the lens model (a precomputed
///   grid, bilinear, < 0.002 px from Newton's answer), its ray cut with the plane. Eye-in-hand
///   cameras need the robot's joints at the exposure (base_T_camera = base_T_mount(joints) *
///   mount_T_camera); without them a link-2 camera is mapped with J1 = J2 = 0 (its view of the
///   table does not depend on them), so sizes and parallax stay right but the frame is not the
///   base frame (world() is false), and a tool-mounted camera falls back to the ideal image.
/// - planar_7545 calibration: the thesis's model. The plane frame is the camera's table-level
///   image scaled to mm, ((i_N - I_cp) / c_x, (j_N - J_cp) / c_y), with the parallax of eq. 2.21
///   (homothety about the image centre, d_ct = camera_height_mm); to_base() applies the
///   thesis's camera->robot formulas (planar_7545.hpp) and needs J1, J2.
/// - no calibration: the image itself (units px, no parallax, no undistortion): metric() false.
/// - a pinhole camera that cannot be placed over the plane (a tool-mounted camera without
///   joints): the ideal (undistorted) image in px about the principal point: metric() false.
///
/// Immutable after create(); copy and share across threads freely (copies share the
/// undistortion grid). Every method is allocation-free.
namespace cell::vision {

/// A point and a direction mapped to the robot base frame: x, y [mm], rz [rad] about +z.
struct BasePose2 {
  double x_mm = 0.0;
  double y_mm = 0.0;
  double rz_rad = 0.0;
};

class PixelMapper {
 public:
  /// The identity mapping (no calibration): plane = pixels.
  PixelMapper();

  /// A mapper for one frame. `robot` (the carrying robot's model; may be null for fixed
  /// cameras and planar models) and `joints` (the joints at exposure, the robot's joint-vector
  /// order and units; empty when unknown) are needed for eye-in-hand pinhole cameras and for
  /// planar_7545 (J1, J2). Missing joints make the mapper image-only (world() false) and
  /// `describe()` says why. Errors: kInvalidArgument for an invalid calibration, a robot whose
  /// id differs from the calibration's, joints of the wrong size or not finite, a link-2 mount
  /// on a robot that is not a SCARA; kOutOfRange when the camera does not look at the working
  /// plane (its axis parallel to it or the plane behind it).
  static Result<PixelMapper> create(const calibration::CameraCalibration& calibration,
                                    const kinematics::RobotModel* robot,
                                    std::span<const double> joints);

  /// The same calibration (sharing its undistortion grid, which create() builds once) for
  /// another frame's robot and joints. Errors: as create(); kNotReady on the identity mapping.
  Result<PixelMapper> rebind(const kinematics::RobotModel* robot,
                             std::span<const double> joints) const;

  /// True when plane coordinates are millimetres (a calibration that reaches the working plane).
  bool metric() const noexcept { return kind_ == Kind::kPinhole || kind_ == Kind::kPlanar; }
  /// True when to_base() gives robot base coordinates.
  bool world() const noexcept { return world_; }
  /// One line: "pinhole eye-in-hand (ibm7545, link2), calibration <version or source>" or why
  /// it is image-only.
  const std::string& describe() const noexcept { return description_; }
  /// The robot whose base frame to_base() maps to ("" when none).
  const std::string& robot_id() const noexcept { return robot_id_; }

  /// Image size the calibration is for (0 x 0: any).
  int width_px() const noexcept { return width_px_; }
  int height_px() const noexcept { return height_px_; }

  /// The plane point of a pixel seen on a surface `height_mm` above the working plane.
  /// Errors: kOutOfRange when the pixel's ray does not meet that surface in front of the
  /// camera or lies outside the lens's field.
  Result<Eigen::Vector2d> to_plane(const Eigen::Vector2d& px, double height_mm) const;

  /// The same mapping for every height at once: to_plane(px, h) == a + h * b, exactly (a ray
  /// cut with horizontal planes, or the planar model's homothety, is linear in h). For callers
  /// that map one pixel at several heights. Errors: as to_plane.
  struct PlaneLine {
    Eigen::Vector2d a = Eigen::Vector2d::Zero();
    Eigen::Vector2d b = Eigen::Vector2d::Zero();
    Eigen::Vector2d at(double height_mm) const { return a + height_mm * b; }
  };
  Result<PlaneLine> plane_line(const Eigen::Vector2d& px) const;

  /// The pixel where the plane point `xy` on the surface `height_mm` up appears.
  /// Errors: kOutOfRange when it is behind the camera or outside the lens's field.
  Result<Eigen::Vector2d> to_pixel(const Eigen::Vector2d& xy, double height_mm) const;

  /// The plane point straight below the camera's centre (walls facing it are visible).
  const Eigen::Vector2d& nadir() const noexcept { return nadir_; }

  /// Height of the camera's centre above the working plane [mm] (0 when not metric).
  double camera_height_mm() const noexcept { return camera_height_mm_; }

  /// True when the plane frame is right-handed seen from above (x, y of a z-up frame: pinhole);
  /// false when it is image-like, mirrored (v down: planar, none, ideal image). A polygon
  /// counter-clockwise seen from above has a positive signed area in a right-handed plane.
  bool plane_right_handed() const noexcept { return kind_ == Kind::kPinhole; }

  /// Plane units per pixel near `px` on the surface `height_mm` up (mean of both axes).
  double scale_at(const Eigen::Vector2d& px, double height_mm) const;

  /// A plane point and direction `rz` (plane frame) in the robot base frame. Errors:
  /// kNotReady when !world(); kOutOfRange from the planar model outside its quadrant.
  Result<BasePose2> to_base(const Eigen::Vector2d& xy, double rz_rad) const;

  /// The calibration (when any).
  const std::optional<calibration::CameraCalibration>& calibration() const noexcept {
    return calibration_;
  }

 private:
  enum class Kind : std::uint8_t { kNone, kPinhole, kPinholeIdeal, kPlanar };
  struct Grid;  // the undistortion grid

  Result<Eigen::Vector2d> undistort_normalised(const Eigen::Vector2d& px) const;
  Status bind(const kinematics::RobotModel* robot, std::span<const double> joints);

  Kind kind_ = Kind::kNone;
  bool world_ = false;
  std::string description_;
  std::string robot_id_;
  int width_px_ = 0;
  int height_px_ = 0;
  std::optional<calibration::CameraCalibration> calibration_;
  render::CameraModel camera_;
  std::shared_ptr<const Grid> grid_;
  Eigen::Isometry3d plane_T_camera_ = Eigen::Isometry3d::Identity();  // plane frame at z = 0
  Eigen::Isometry3d camera_T_plane_ = Eigen::Isometry3d::Identity();
  Eigen::Vector2d nadir_ = Eigen::Vector2d::Zero();
  double camera_height_mm_ = 0.0;
  double j1_rad_ = 0.0;
  double j2_rad_ = 0.0;
};

}  // namespace cell::vision
