// Hand-eye on renders through true cameras, with noise on the robot poses (0.05 deg and 0.1 mm
// per axis, the figures) and on the corners (0.2 px), against the truth and beside
// OpenCV's Tsai, Park and Daniilidis on the same samples.
#include "cell/calibration/hand_eye.hpp"

#include <cmath>
#include <iostream>
#include <numbers>

#include <fmt/format.h>
#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include "cell/calibration/pixel_mapping.hpp"
#include "cell/geometry/angles.hpp"
#include "cell/render/mount.hpp"
#include "cell/testing/matchers.hpp"
#include "sim_views.hpp"

namespace cell::calibration {
namespace {

using ::cell::testing::IsErrWith;
using ::cell::testing::IsOk;
using ::testing::HasSubstr;
using testing::HandEyeScenario;

using geometry::kDeg;
constexpr double kRotationTolDeg = 0.05;   // the issue: rotation error under 0.05 deg
constexpr double kTranslationTolMm = 0.2;  // and translation under 0.2 mm
constexpr double kPoseRotSigmaDeg = 0.05;
constexpr double kPoseTransSigmaMm = 0.1;
constexpr double kPixelSigma = 0.2;

struct PoseError {
  double rotation_deg;
  double translation_mm;
};

PoseError error_of(const Eigen::Isometry3d& estimate, const Eigen::Isometry3d& truth) {
  return {testing::rotation_error_rad(estimate.linear(), truth.linear()) / kDeg,
          (estimate.translation() - truth.translation()).norm()};
}

/// Runs the scenario, checks the bounds (`full_pose`: the rotation and translation
/// bounds on the whole transform; planar scenarios are checked on what they determine by the
/// caller), prints the closed forms beside the result.
HandEyeReport check(const HandEyeScenario& s, bool full_pose = true) {
  auto report = calibrate_hand_eye(s.samples, s.camera, s.options);
  EXPECT_THAT(report, IsOk()) << s.name;
  if (!report) {
    return {};
  }
  const PoseError mine = error_of(report->camera_extrinsics, s.truth_extrinsics);
  if (full_pose) {
    EXPECT_LT(mine.rotation_deg, kRotationTolDeg) << s.name << ": " << report->brief();
    EXPECT_LT(mine.translation_mm, kTranslationTolMm) << s.name << ": " << report->brief();
  }
  EXPECT_EQ(report->samples_rejected, 0) << report->brief();
  EXPECT_GE(report->samples_held_out, 2);
  EXPECT_LT(report->rms_px, 1.3 * kPixelSigma * std::sqrt(2.0)) << report->brief();
  EXPECT_GT(report->holdout_mm, 0.0);
  EXPECT_LT(report->holdout_mm, 1.0) << report->brief();
  std::cout << s.name << ": ceres rotation " << fmt::format("{:.4f}", mine.rotation_deg)
            << " deg, translation " << fmt::format("{:.3f}", mine.translation_mm) << " mm; "
            << report->brief() << "\n";
  for (const MethodEstimate& e : report->closed_forms) {
    if (e.ok) {
      const PoseError theirs = error_of(e.camera_extrinsics, s.truth_extrinsics);
      std::cout << fmt::format("  opencv {:<10} rotation {:8.4f} deg, translation {:8.3f} mm\n",
                               to_string(e.method), theirs.rotation_deg, theirs.translation_mm);
    } else {
      std::cout << "  opencv " << to_string(e.method) << ": " << e.error << "\n";
    }
  }
  return *report;
}

/// Rotation about the vertical between two camera poses in the same (level) mount frame: the
/// angle between their optical x axes projected on the horizontal [deg].
double yaw_error_deg(const Eigen::Isometry3d& a, const Eigen::Isometry3d& b) {
  const Eigen::Vector3d xa = a.linear().col(0);
  const Eigen::Vector3d xb = b.linear().col(0);
  return std::abs(std::remainder(std::atan2(xa.y(), xa.x()) - std::atan2(xb.y(), xb.x()),
                                 2.0 * std::numbers::pi)) / kDeg;
}

/// What the planar reduction promises: pixels mapped onto the working plane. For every mount
/// pose given and a 9 x 9 grid of pixels, the plane point through the calibration against the
/// plane point through the truth (same intrinsics): the worst distance [mm].
double plane_mapping_error_mm(const HandEyeScenario& s, const HandEyeReport& r,
                              const std::vector<Eigen::Isometry3d>& mounts, double plane_z) {
  double worst = 0.0;
  for (const Eigen::Isometry3d& m : mounts) {
    const bool in_hand = s.options.setup == HandEyeSetup::kEyeInHand;
    const Eigen::Isometry3d truth = in_hand ? m * s.truth_extrinsics : s.truth_extrinsics;
    const Eigen::Isometry3d fit = in_hand ? m * r.camera_extrinsics : r.camera_extrinsics;
    for (int i = 0; i <= 8; ++i) {
      for (int j = 0; j <= 8; ++j) {
        const Eigen::Vector2d px((s.camera.width_px() - 1) * i / 8.0,
                                 (s.camera.height_px() - 1) * j / 8.0);
        auto a = pixel_to_plane(s.camera, truth, px, plane_z);
        auto b = pixel_to_plane(r.camera, fit, px, plane_z);
        if (a && b) {
          worst = std::max(worst, (*a - *b).norm());
        }
      }
    }
  }
  return worst;
}

const MethodEstimate& method(const HandEyeReport& r, HandEyeMethod m) {
  return r.closed_forms[static_cast<std::size_t>(m)];
}

// The must-hold: rotation under 0.05 deg and translation under 0.2 mm with 0.05 deg
// and 0.1 mm of robot pose noise (per axis), beside Tsai, Park and Daniilidis on the same
// samples. 30 poses seen from 25 to 65 degrees above the table, from every side: over 30 seeded
// trials the joint fit meets both bounds in 28 (bench/calibration). Tsai's and Daniilidis's
// closed forms break down on these large, varied turns (degrees off); Park's holds.
TEST(HandEye, ExcaliburEyeInHandMeetsTheBoundsBesideTheClosedForms) {
  const HandEyeScenario s =
      testing::excalibur_eye_in_hand(30, kPoseRotSigmaDeg, kPoseTransSigmaMm, kPixelSigma, 11);
  ASSERT_EQ(s.samples.size(), 30U);
  const HandEyeReport r = check(s);
  ASSERT_EQ(r.closed_forms.size(), 7U);
  const PoseError mine = error_of(r.camera_extrinsics, s.truth_extrinsics);
  // Park's holds here (one trial: it can land closer in one of the two; over 30 trials its
  // median is 0.033 deg and 0.14 mm against 0.026 deg and 0.105 mm, bench/calibration).
  ASSERT_TRUE(method(r, HandEyeMethod::kPark).ok);
  const PoseError park = error_of(method(r, HandEyeMethod::kPark).camera_extrinsics,
                                  s.truth_extrinsics);
  EXPECT_LT(park.rotation_deg, 0.2);
  EXPECT_LT(mine.rotation_deg + mine.translation_mm / 100.0,
            park.rotation_deg + park.translation_mm / 100.0 + 0.01);
  ::testing::Test::RecordProperty(
      "excalibur_eye_in_hand",
      fmt::format("ceres {:.4f} deg {:.3f} mm; park {:.4f} deg {:.3f} mm", mine.rotation_deg,
                  mine.translation_mm, park.rotation_deg, park.translation_mm));
  // The fit sees the robot's error about as it was made (0.05 deg, 0.1 mm per axis).
  EXPECT_GT(r.robot_translation_rms_mm, 0.05);
  EXPECT_LT(r.robot_translation_rms_mm, 0.3);
  // The board where it is.
  EXPECT_LT(error_of(r.target_pose, s.truth_target).translation_mm, 0.5);
}

// Views from a cap straight above the board (50 to 88 degrees), 20 poses: every closed form
// works there, and the joint fit is better than each of Tsai, Park and Daniilidis. (The cap
// determines the camera's turn about its optical axis poorly: the bounds are met in 6 of 30
// trials only, which is why the pose set above is tilted.)
TEST(HandEye, ExcaliburEyeInHandFromAboveBeatsTsaiParkAndDaniilidis) {
  const HandEyeScenario s = testing::excalibur_eye_in_hand(20, kPoseRotSigmaDeg, kPoseTransSigmaMm,
                                                           kPixelSigma, 11, 50.0, 88.0);
  ASSERT_EQ(s.samples.size(), 20U);
  const HandEyeReport r = check(s, false);
  const PoseError mine = error_of(r.camera_extrinsics, s.truth_extrinsics);
  for (const HandEyeMethod m : {HandEyeMethod::kTsai, HandEyeMethod::kPark,
                                HandEyeMethod::kDaniilidis}) {
    ASSERT_TRUE(method(r, m).ok) << to_string(m) << ": " << method(r, m).error;
    const PoseError theirs = error_of(method(r, m).camera_extrinsics, s.truth_extrinsics);
    EXPECT_LT(mine.translation_mm, theirs.translation_mm) << to_string(m);
    EXPECT_LT(mine.rotation_deg, theirs.rotation_deg) << to_string(m);
  }
}

TEST(HandEye, ExcaliburEyeToHandMeetsTheBounds) {
  const HandEyeScenario s =
      testing::excalibur_eye_to_hand(40, kPoseRotSigmaDeg, kPoseTransSigmaMm, kPixelSigma, 12);
  ASSERT_EQ(s.samples.size(), 40U);
  const HandEyeReport r = check(s);
  EXPECT_EQ(r.setup, HandEyeSetup::kEyeToHand);
  EXPECT_LT(error_of(r.target_pose, s.truth_target).translation_mm, 0.5);
}

// A SCARA cannot tilt its camera, and the 7545's camera does not even move with Z: every
// closed form is degenerate on its data, and even the planar reduction only sees the camera's
// tilt through the board's perspective (a tilt about a horizontal axis and a sideways shift of
// the camera by the tilt times its height look alike). What a SCARA camera is for, mapping
// pixels onto the working plane, is what the reduction determines well: held to 0.2 mm over
// the whole image, at the held-out poses and at the thesis's image-grab pose (J1 45, J2 105
// deg), which the calibration poses (near the end of the reach) never visited.
TEST(HandEye, Ibm7545LinkTwoCameraMapsTheTableWithThePlanarReduction) {
  const HandEyeScenario s =
      testing::ibm7545_eye_in_hand(30, kPoseRotSigmaDeg, kPoseTransSigmaMm, kPixelSigma, 13);
  ASSERT_EQ(s.samples.size(), 30U);
  const HandEyeReport r = check(s, false);
  EXPECT_TRUE(r.planar);
  EXPECT_EQ(r.init, "planar");
  EXPECT_LT(yaw_error_deg(r.camera_extrinsics, s.truth_extrinsics), kRotationTolDeg);
  const kinematics::RobotModel robot = testing::robot_file("ibm7545.yaml");
  std::vector<Eigen::Isometry3d> mounts;
  for (std::size_t i = 0; i < s.samples.size(); ++i) {
    if (r.samples[i].held_out) {
      mounts.push_back(s.true_mount[i]);
    }
  }
  kinematics::JointVector grab(4);
  grab << 45.0 * kDeg, 105.0 * kDeg, 0.0, 0.0;
  mounts.push_back(render::base_T_mount(robot, render::MountFrame::kLink2, grab).value());
  const double table_z = 750.0 - 981.51;
  const double mapping = plane_mapping_error_mm(s, r, mounts, table_z);
  EXPECT_LT(mapping, kTranslationTolMm) << r.brief();
  // A part's top 3.8 mm above the table (a DIP) maps as well.
  EXPECT_LT(plane_mapping_error_mm(s, r, mounts, table_z + 3.8), kTranslationTolMm);
  const PoseError mine = error_of(r.camera_extrinsics, s.truth_extrinsics);
  const PoseError tsai = error_of(method(r, HandEyeMethod::kTsai).camera_extrinsics,
                                  s.truth_extrinsics);
  EXPECT_GT(tsai.translation_mm, 10.0 * mine.translation_mm)
      << "Tsai on parallel axes should be far off";
  std::cout << fmt::format("  table mapping {:.3f} mm worst, camera yaw {:.4f} deg\n", mapping,
                           yaw_error_deg(r.camera_extrinsics, s.truth_extrinsics));
}

TEST(HandEye, PickerHoldingABoardUnderTheBeltCamera) {
  const HandEyeScenario s =
      testing::picker_eye_to_hand(20, kPoseRotSigmaDeg, kPoseTransSigmaMm, kPixelSigma, 14);
  ASSERT_EQ(s.samples.size(), 20U);
  const HandEyeReport r = check(s, false);
  EXPECT_TRUE(r.planar);
  // The belt's surface 200 mm under the picker's flange: where the camera locates parts.
  const double mapping = plane_mapping_error_mm(s, r, {Eigen::Isometry3d::Identity()}, -200.0);
  EXPECT_LT(mapping, kTranslationTolMm) << r.brief();
  std::cout << fmt::format("  belt-plane mapping {:.3f} mm worst\n", mapping);
}

TEST(HandEye, WithoutThePlanarReductionAScaraIsRefusedAndToldWhy) {
  HandEyeScenario s = testing::ibm7545_eye_in_hand(10, 0.0, 0.0, 0.0, 13);
  s.options.planar = false;
  EXPECT_THAT(calibrate_hand_eye(s.samples, s.camera, s.options),
              IsErrWith(Errc::kOutOfRange, "near-parallel rotation axes"));
  EXPECT_THAT(calibrate_hand_eye(s.samples, s.camera, s.options),
              IsErrWith(Errc::kOutOfRange, "use the planar reduction"));
}

TEST(HandEye, TooLittleRotationIsRefused) {
  HandEyeScenario s = testing::excalibur_eye_in_hand(12, 0.0, 0.0, 0.0, 15);
  // Keep the first pose's orientation for all, shifted about: pure translations, a few degrees.
  for (std::size_t i = 0; i < s.samples.size(); ++i) {
    Eigen::Isometry3d m = s.samples[0].base_T_mount;
    m.rotate(Eigen::AngleAxisd(0.5 * kDeg * static_cast<double>(i % 4),
                               Eigen::Vector3d(1, 1, 0).normalized()));
    m.translation() += Eigen::Vector3d(3.0 * static_cast<double>(i), 0.0, 0.0);
    s.samples[i].base_T_mount = m;
  }
  EXPECT_THAT(calibrate_hand_eye(s.samples, s.camera, s.options),
              IsErrWith(Errc::kOutOfRange, "too little rotation: the poses differ by at most"));
}

TEST(HandEye, RotationsAboutOneAxisAreRefused) {
  HandEyeScenario s = testing::excalibur_eye_in_hand(12, 0.0, 0.0, 0.0, 16);
  for (std::size_t i = 0; i < s.samples.size(); ++i) {
    Eigen::Isometry3d m = s.samples[0].base_T_mount;
    m.rotate(Eigen::AngleAxisd(4.0 * kDeg * static_cast<double>(i), Eigen::Vector3d::UnitZ()));
    s.samples[i].base_T_mount = m;
  }
  EXPECT_THAT(calibrate_hand_eye(s.samples, s.camera, s.options),
              IsErrWith(Errc::kOutOfRange, "near-parallel rotation axes"));
}

TEST(HandEye, ARobotThatNeverMovedIsRefused) {
  HandEyeScenario s = testing::excalibur_eye_in_hand(8, 0.0, 0.0, 0.0, 17);
  for (auto& sample : s.samples) {
    sample.base_T_mount = s.samples[0].base_T_mount;
  }
  EXPECT_THAT(calibrate_hand_eye(s.samples, s.camera, s.options),
              IsErrWith(Errc::kOutOfRange, "the robot never moved"));
  s.options.planar = true;
  EXPECT_THAT(calibrate_hand_eye(s.samples, s.camera, s.options),
              IsErrWith(Errc::kOutOfRange, "the robot never moved"));
}

TEST(HandEye, ThePlanarReductionRefusesATiltingMount) {
  HandEyeScenario s = testing::excalibur_eye_in_hand(10, 0.0, 0.0, 0.0, 18);
  s.options.planar = true;
  EXPECT_THAT(calibrate_hand_eye(s.samples, s.camera, s.options),
              IsErrWith(Errc::kOutOfRange, "planar reduction needs rotations about the base z"));
}

// Every sample keeps its own pose: a failed detection, a stale pose or a duplicate id is
// rejected by name, and the rest still calibrate to the truth.
TEST(HandEye, SamplesArePairedByIdAndStamp) {
  HandEyeScenario s =
      testing::excalibur_eye_in_hand(30, kPoseRotSigmaDeg, kPoseTransSigmaMm, kPixelSigma, 11);
  ASSERT_EQ(s.samples.size(), 30U);
  s.samples[3].detection_error = "no chessboard 9x6 inner corners, 20 mm squares found";
  s.samples[3].observation = {};
  s.samples[7].robot_stamp_ns = s.samples[7].stamp_ns - 300'000'000;  // a state 0.3 s old
  s.samples[11].id = s.samples[10].id;
  // A pose swapped with its neighbour's would pair images with the wrong poses: an outlier.
  std::swap(s.samples[15].base_T_mount, s.samples[16].base_T_mount);
  auto r = calibrate_hand_eye(s.samples, s.camera, s.options);
  ASSERT_THAT(r, IsOk());
  EXPECT_THAT(r->samples[3].reason, HasSubstr("target not found: no chessboard"));
  EXPECT_THAT(r->samples[7].reason, HasSubstr("0.300 s away from the exposure"));
  EXPECT_THAT(r->samples[11].reason, HasSubstr("'pose 10' used twice"));
  const bool swapped_caught = !r->samples[15].used && !r->samples[16].used &&
                              !r->samples[15].held_out && !r->samples[16].held_out;
  EXPECT_TRUE(swapped_caught) << r->samples[15].reason << " / " << r->samples[16].reason;
  EXPECT_THAT(r->samples[15].reason + r->samples[16].reason, HasSubstr("outlier"));
  EXPECT_THAT(r->samples[15].reason + r->samples[16].reason, HasSubstr("robot pose disagrees"));
  const PoseError e = error_of(r->camera_extrinsics, s.truth_extrinsics);
  EXPECT_LT(e.rotation_deg, kRotationTolDeg);
  EXPECT_LT(e.translation_mm, kTranslationTolMm);
}

TEST(HandEye, TooFewSamplesCountsThem) {
  HandEyeScenario s = testing::excalibur_eye_in_hand(5, 0.0, 0.0, 0.0, 19);
  EXPECT_THAT(calibrate_hand_eye(s.samples, s.camera, s.options),
              IsErrWith(Errc::kInvalidArgument, "too few samples: 5 given, 5 usable"));
}

TEST(HandEyeOptions, ValidateNamesTheOption) {
  HandEyeOptions o;
  o.pixel_sigma_px = 0.0;
  EXPECT_THAT(o.validate(), IsErrWith(Errc::kInvalidArgument, "pixel_sigma_px must be > 0"));
  o = {};
  o.robot_rotation_sigma_deg = -1.0;
  EXPECT_THAT(o.validate(), IsErrWith(Errc::kInvalidArgument, "robot sigmas must be >= 0"));
}

}  // namespace
}  // namespace cell::calibration
