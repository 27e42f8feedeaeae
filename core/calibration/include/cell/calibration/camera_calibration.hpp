#pragma once

#include <array>
#include <cstdint>
#include <string>
#include <string_view>

#include <Eigen/Geometry>

#include "calibration.h"
#include "cell/common/result.hpp"
#include "cell/render/camera_file.hpp"
#include "cell/render/camera_model.hpp"

/// What the cell believes about a camera: the one data type that the calibration service
/// produces, the store keeps as YAML files, the bus carries as `CameraCalibration`
/// (idl/calibration.idl) and vision uses to map pixels to the robot. Two model types:
///
/// - **pinhole**: intrinsics (fx, fy, cx, cy [px]) and OpenCV's lens distortion (k1 k2 p1 p2
///   k3) as render::CameraModel has them, plus extrinsics. Fixed camera: `extrinsics` =
///   base_T_camera in the base frame of `robot_id` (the robot that picks what it sees: V+'s
///   `to.cam` of the conveyor chapter). Eye-in-hand: `extrinsics` = mount_T_camera, the mount
///   being the robot frame named by `mount_frame` (render/camera_file.hpp: `tool` is the
///   flange, `link2` a SCARA's link 2). Camera frame: z along the optical axis, x = image u,
///   y = image v (render/camera_model.hpp).
/// - **planar_7545**: the AVRS thesis's planar eye-in-hand model (digest 000 §4): pixel
///   scales c_x, c_y [px/mm], Ref_Point (b_x, b_y) and centre (I_cp, J_cp) [px], d_t_c [mm],
///   b_angl and angl_err [rad], link lengths and the camera height [mm]. Its fields are kept
///   in `planar`; `pinhole` and `extrinsics` are unused.
///
/// `working_plane_z_mm` is the height of the plane the parts lie on (table or belt top) in the
/// base frame of `robot_id`: a pixel's ray is cut with it to give the part's base x, y.
/// Units: mm and rad inside; the file writes angles in degrees (keys ending in _deg).
namespace cell::calibration {

enum class ModelType : std::uint8_t { kPinhole, kPlanar7545 };
enum class Mounting : std::uint8_t { kFixed, kEyeInHand };

/// Pinhole intrinsics and lens (OpenCV's order and meaning).
struct PinholeParameters {
  double fx_px = 0.0;
  double fy_px = 0.0;
  double cx_px = 0.0;
  double cy_px = 0.0;
  render::Distortion distortion;
};

/// The thesis's planar model (digest 000 §4, its symbols in the comments).
struct PlanarParameters {
  double c_x_px_per_mm = 0.0;  ///< c_x: pixels per mm along image i (u)
  double c_y_px_per_mm = 0.0;  ///< c_y: pixels per mm along image j (v)
  double ref_u_px = 0.0;       ///< Ref_Point b_x
  double ref_v_px = 0.0;       ///< Ref_Point b_y
  double center_u_px = 0.0;    ///< I_cp
  double center_v_px = 0.0;    ///< J_cp
  double d_t_c_mm = 0.0;       ///< d_t_c: tool axis to the Ref_Point's ray
  double b_angl_rad = 0.0;     ///< b_angl
  double angl_err_rad = 0.0;   ///< angl_err: camera i axis against link 2
  double link1_mm = 0.0;       ///< as calibrated (the thesis calibrates them too)
  double link2_mm = 0.0;
  double camera_height_mm = 0.0;  ///< d_ct: camera above the working plane
};

/// How good the calibration is (all optional; 0 when unknown).
struct Quality {
  double rms_px = 0.0;          ///< reprojection RMS on the fitting data
  double holdout_rms_px = 0.0;  ///< reprojection RMS on views not used in the fit
  double holdout_mm = 0.0;      ///< predicted vs measured position of held-out points [mm]
  std::uint32_t sample_count = 0;
};

struct CameraCalibration {
  std::string camera_id;
  std::string version;      ///< store version, e.g. "2026-12-01T16:00:00Z#3"; "" if none
  std::string created_utc;  ///< ISO 8601, when it was made
  std::string source;       ///< what data it came from (procedure, files, sample ids)
  ModelType model = ModelType::kPinhole;
  Mounting mounting = Mounting::kFixed;
  render::MountFrame mount_frame = render::MountFrame::kTool;  ///< eye-in-hand only
  std::string robot_id;
  int width_px = 0;
  int height_px = 0;
  PinholeParameters pinhole;
  /// base_T_camera (fixed) or mount_T_camera (eye-in-hand) [mm]; pinhole only.
  Eigen::Isometry3d extrinsics = Eigen::Isometry3d::Identity();
  double working_plane_z_mm = 0.0;
  PlanarParameters planar;
  Quality quality;

  /// Ok, or kInvalidArgument naming the first offending field and the rule (ids non-empty,
  /// image size in 1..16384, intrinsics finite with fx, fy > 0 and a lens that does not fold
  /// inside the image, extrinsics a finite rigid transform; planar: scales > 0, finite).
  Status validate() const;

  /// The pinhole model (validated). Errors: as validate(); kInvalidArgument for planar_7545.
  Result<render::CameraModel> camera_model() const;
};

std::string_view to_string(ModelType model) noexcept;  ///< "pinhole" / "planar_7545"
std::string_view to_string(Mounting mounting) noexcept;  ///< "fixed" / "eye_in_hand"

/// Reads a calibration file (format: core/calibration/README.md). Errors (kConfig): every
/// problem at once, "file:line:col: key 'a.b': what", then validate()'s verdict.
Result<CameraCalibration> load_camera_calibration(const std::string& path);

/// As load_camera_calibration, from YAML text; `origin` names it in errors.
Result<CameraCalibration> parse_camera_calibration(const std::string& text,
                                                   const std::string& origin);

/// The YAML text of a calibration (round-trips through parse_camera_calibration to the last
/// bit: numbers are written with 17 significant digits).
std::string format_camera_calibration(const CameraCalibration& calibration);

/// Writes the file atomically (temporary file, then rename). Errors: kInvalidArgument from
/// validate(), kIo when the file cannot be written (naming the path and errno's text).
Status save_camera_calibration(const CameraCalibration& calibration, const std::string& path);

/// The calibration the cell starts from before anything was calibrated: the camera file's
/// NOMINAL parameters (config/cameras/<id>.yaml), no distortion beyond what it states.
/// Eye-in-hand: robot and mount frame from the file. Fixed: `robot_id` and `world_T_base`
/// (that robot's base in the world, config/sim-world.yaml) give base_T_camera =
/// world_T_base^-1 * world_T_camera. `working_plane_z_mm` is in that robot's base frame.
/// Errors: kInvalidArgument when a fixed camera gets no robot_id.
Result<CameraCalibration> nominal_calibration(const render::CameraDescription& camera,
                                              const std::string& robot_id,
                                              const Eigen::Isometry3d& world_T_base,
                                              double working_plane_z_mm);

/// Strings and sequences of the IDL sample that to_idl fills point into this holder.
struct IdlHolder {
  std::string mount_frame;
  std::string frame_id;
  std::vector<double> distortion;
};

/// The bus sample of a calibration. Its strings borrow from `calibration` and `holder`, which
/// must outlive the sample (write it, then let both go). `stamp_ns` goes into the header.
cell_calibration_CameraCalibration to_idl(const CameraCalibration& calibration, IdlHolder& holder,
                                          std::int64_t stamp_ns);

/// A calibration from a bus sample, validated. Errors: kInvalidArgument naming the field (an
/// unknown enum value, a distortion sequence that is not 0 or 5 long, a mount frame that is
/// neither "tool" nor "link2", or what validate() finds).
Result<CameraCalibration> from_idl(const cell_calibration_CameraCalibration& sample);

}  // namespace cell::calibration
