#pragma once

#include <Eigen/Geometry>
#include <cstdint>
#include <opencv2/core.hpp>
#include <string>
#include <vector>

#include "cell/calibration/camera_calibration.hpp"
#include "cell/kinematics/robot_model.hpp"
#include "cell/render/camera_file.hpp"
#include "cell/render/scene.hpp"
#include "cell/render/truth.hpp"
#include "cell/vision/grip.hpp"
#include "cell/vision/locate.hpp"
#include "cell/vision/pixel_mapper.hpp"
#include "cell/world/part_class.hpp"

/// Rendered scenes of the world simulator with their ground truth, for vision's accuracy tests
/// and its benchmark: core/world places the parts (its catalogue's real sizes, its seeded
/// scatter with a minimum separation), core/render draws them through the 7545 eye-in-hand
/// camera's TRUE model (lens distortion, lighting gradient, IC leads, noise 2 grey levels).
namespace cell::vision::testing {

/// Lighting set-ups of the thesis's cell (digest 000 §1.1, §3).
enum class Lights : std::uint8_t {
  kTubes,         ///< the fluorescent tubes only: the table's gradient, dull leads
  kTubesAndLamp,  ///< plus the halogen lamp beside the camera: brighter, glinting leads
};

const char* to_string(Lights lights);

struct ScatterRequest {
  int count = 15;
  bool pins = true;  ///< false: the same DIP bodies without their leads
  Lights lights = Lights::kTubes;
  std::uint64_t seed = 1;
  double min_separation_mm = 5.7;  ///< the thesis's 20 px grouping distance
  std::vector<std::string> classes{"ic_7x30", "ic_6x19", "dip14", "dip8", "dip16", "dip20"};
  /// Render through the true camera without its lens distortion (the thesis had no lens model).
  bool ideal_lens = false;
};

struct RenderedScene {
  std::string name;
  cv::Mat image;
  std::vector<render::PartTruth> truth;  ///< parts wholly in view
  render::Scene scene;
  std::vector<double> joints;  ///< the 7545's at the exposure
  Eigen::Isometry3d world_T_camera = Eigen::Isometry3d::Identity();
};

/// The cell's 7545 camera, robot and calibrations, loaded once from the checkout.
class Cell {
 public:
  static const Cell& get();

  const render::CameraDescription& camera() const { return camera_; }
  const kinematics::RobotModel& robot() const { return robot_; }
  /// What a perfect calibration would give: the TRUE camera as a pinhole calibration.
  const calibration::CameraCalibration& true_calibration() const { return true_; }
  /// The cell's starting point: the camera file's nominal parameters.
  const calibration::CameraCalibration& nominal_calibration() const { return nominal_; }
  /// world z of the table top, and the 7545's base in the world.
  double table_z_mm() const { return 750.0; }
  const Eigen::Isometry3d& world_T_base() const { return world_T_base_; }

  /// Joints where the image axes line up with the world's (J1 45 deg, J2 135 deg), so a
  /// seeded scatter in an axis-aligned box fills the window; and the thesis's grab pose.
  std::vector<double> aligned_joints() const;
  std::vector<double> grab_joints() const;

  /// The table region (world x, y) that the aligned camera sees, shrunk by `margin_mm`.
  Eigen::AlignedBox2d window(double margin_mm) const;

  /// A render::Part for a catalogue class at a pose (pins: keep the class's leads).
  render::Part part(const std::string& id,
                    const world::PartClass& cls,
                    const Eigen::Isometry3d& world_T_part,
                    bool pins) const;
  render::Part part(const std::string& id,
                    const std::string& class_name,
                    double x_mm,
                    double y_mm,
                    double yaw_rad,
                    bool pins) const;

  /// Renders `parts` with the camera at `joints`; truth keeps the parts wholly in view.
  RenderedScene render(std::string name,
                       std::vector<render::Part> parts,
                       const std::vector<double>& joints,
                       Lights lights,
                       std::uint64_t noise_seed,
                       bool ideal_lens = false) const;

  /// The true calibration without its lens distortion (for ideal_lens renders).
  calibration::CameraCalibration ideal_calibration() const;

  /// A seeded scatter of core/world over the aligned window, rendered.
  RenderedScene scatter(const ScatterRequest& request) const;

  /// config/scenes/table_ics.yaml (the thesis's 15 ICs) at the grab pose.
  RenderedScene table_ics(bool pins, Lights lights) const;

  /// A rendered clear-grip case and the styles that stay clear in it, best first.
  struct ClearGraspScene {
    std::vector<render::Part> parts;
    std::vector<std::string> clear;
  };
  /// A dip14 at 25 deg in the window's centre, alone (both dip14_grasp_model() styles clear),
  /// then with a dip8 9.5 mm off its long side, inside the "across" fingerprint ("ends" only).
  std::vector<ClearGraspScene> clear_grasp_scenes() const;

  /// A mapper for a frame with the given calibration.
  PixelMapper mapper(const calibration::CameraCalibration& calibration,
                     const std::vector<double>& joints) const;

  const world::Catalogue& catalogue() const { return catalogue_; }

 private:
  Cell();
  std::string home_;
  render::CameraDescription camera_;
  kinematics::RobotModel robot_;
  calibration::CameraCalibration true_;
  calibration::CameraCalibration nominal_;
  Eigen::Isometry3d world_T_base_ = Eigen::Isometry3d::Identity();
  world::Catalogue catalogue_;
};

/// How detections compare with the truth of a frame.
struct Score {
  int parts = 0;  ///< truth parts in view
  int found = 0;  ///< matched (a detection within 4 px of the truth's centre)
  int missed = 0;
  int false_parts = 0;
  int wrong_class = 0;
  double sum_centre2_px = 0.0;  ///< over matched parts
  double sum_angle2_rad = 0.0;
  double max_centre_px = 0.0;
  double max_angle_rad = 0.0;
  double sum_world2_mm = 0.0;  ///< base-pose position error (when compared)
  double max_world_mm = 0.0;
  int world_compared = 0;
  std::vector<std::string> notes;  ///< misses and false parts, for test messages

  void add(const Score& other);
  double centre_rms_px() const;
  double angle_rms_deg() const;
  double world_rms_mm() const;
};

/// Matches `detections` to the frame's truth (nearest centre within 4 px, one to one) and
/// accumulates the errors (angles modulo the part's symmetry). With `world_T_base`, base poses
/// are compared with the truth's part origin too.
Score score(const std::vector<Detection>& detections,
            const RenderedScene& frame,
            bool compare_class,
            const Eigen::Isometry3d* world_T_base = nullptr);

/// A dip14 and its two styles: "across" (fingers on the long sides, over the leads; the tool
/// along the part) and "ends" (the tool across it).
GraspModel dip14_grasp_model();

}  // namespace cell::vision::testing
