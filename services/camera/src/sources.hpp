#pragma once

#include <cstdint>
#include <memory>
#include <optional>
#include <string>
#include <string_view>
#include <vector>

#include <Eigen/Geometry>
#include <opencv2/core.hpp>

#include "camera_config.hpp"
#include "cell/common/result.hpp"
#include "cell/kinematics/robot_model.hpp"
#include "cell/render/camera_file.hpp"
#include "cell/render/renderer.hpp"
#include "cell/render/truth.hpp"

/// Camera sources behind one interface: the simulated renderer, a directory of image files
/// (replay) and a real device through cv::VideoCapture. The service owns one; it decides
/// when to grab and what the frame is published with.
namespace cell::camera {

/// What the service knows at the exposure, for the source to use.
struct GrabContext {
  std::int64_t exposure_ns = 0;             ///< mid-exposure, wall clock
  std::uint64_t frame_index = 0;            ///< 1, 2, ... (seeds the simulated noise)
  const render::Scene* scene = nullptr;     ///< sim: the world at the exposure (nullptr: none)
  std::optional<kinematics::JointVector> joints;  ///< eye-in-hand: the robot at the exposure
  bool want_truth = false;
};

/// What the simulated frame really shows (ImageTruth).
struct FrameTruth {
  Eigen::Isometry3d world_T_camera = Eigen::Isometry3d::Identity();  ///< the TRUE pose
  render::CameraModel model;                                         ///< the TRUE intrinsics
  std::vector<render::PartTruth> parts;
};

/// One frame.
struct Frame {
  cv::Mat image;                    ///< CV_8UC1, continuous
  std::int64_t exposure_ns = 0;     ///< mid-exposure (the source's own stamp when it has one)
  std::optional<FrameTruth> truth;  ///< sim with want_truth only
  int parts_skipped = 0;            ///< sim: malformed parts the renderer refused
};

/// A source of frames. grab() never throws; what goes wrong comes back as an Error:
/// kNotReady (no world yet, no robot state), kIo (a file or device failed), kInvalidArgument.
/// One thread at a time.
class CameraSource {
 public:
  CameraSource() = default;
  CameraSource(const CameraSource&) = delete;
  CameraSource& operator=(const CameraSource&) = delete;
  virtual ~CameraSource() = default;

  virtual SourceKind kind() const noexcept = 0;
  /// True when grab() can produce ground truth (the simulator).
  virtual bool has_truth() const noexcept { return false; }
  /// The eye-in-hand robot whose joints the frame needs ("" when none).
  virtual const std::string& mount_robot_id() const noexcept;
  /// Takes one frame at ctx.exposure_ns (the simulator renders that instant; real sources take
  /// the next frame they have and stamp it).
  virtual Result<Frame> grab(const GrabContext& ctx) = 0;

 private:
  std::string none_;
};

/// Builds the source `config` asks for. Errors (setup; main turns them into exit code 2):
/// kConfig for a camera file that does not load or whose id is not camera_id, kIo for a
/// directory with no images or a device that does not open.
Result<std::unique_ptr<CameraSource>> make_source(const CameraConfig& config);

/// The simulator: renders the world through the camera file's TRUE model and pose.
class SimSource final : public CameraSource {
 public:
  /// Errors: kConfig (camera file, robot file, or a lighting the renderer refuses).
  static Result<std::unique_ptr<SimSource>> create(const CameraConfig& config);

  SourceKind kind() const noexcept override { return SourceKind::kSim; }
  bool has_truth() const noexcept override { return true; }
  const std::string& mount_robot_id() const noexcept override;
  Result<Frame> grab(const GrabContext& ctx) override;

  const render::CameraDescription& camera() const noexcept { return camera_; }
  /// The TRUE camera pose for `ctx` (eye-in-hand: at its joints). Errors: kNotReady without
  /// joints for an eye-in-hand camera; kInvalidArgument for bad joints.
  Result<Eigen::Isometry3d> true_pose(const GrabContext& ctx) const;

 private:
  SimSource(render::CameraDescription camera, std::optional<kinematics::RobotModel> robot,
            render::Renderer renderer, render::RenderOptions options);

  render::CameraDescription camera_;
  std::optional<kinematics::RobotModel> robot_;
  render::Renderer renderer_;
  render::RenderOptions options_;
};

/// Replays a directory of images (png, jpg, bmp, pgm, ppm, tif) in name order, as mono8.
class FileSource final : public CameraSource {
 public:
  /// Errors: kIo when the directory cannot be listed or holds no image.
  static Result<std::unique_ptr<FileSource>> create(const FileOptions& options);
  SourceKind kind() const noexcept override { return SourceKind::kFiles; }
  Result<Frame> grab(const GrabContext& ctx) override;
  std::size_t size() const noexcept { return files_.size(); }

 private:
  explicit FileSource(std::vector<std::string> files, bool loop)
      : files_(std::move(files)), loop_(loop) {}
  std::vector<std::string> files_;
  bool loop_;
  std::size_t next_ = 0;
};

/// A camera (or a video file, or an image-sequence pattern) through cv::VideoCapture.
class DeviceSource final : public CameraSource {
 public:
  /// Errors: kIo when the capture does not open.
  static Result<std::unique_ptr<DeviceSource>> create(const DeviceOptions& options);
  ~DeviceSource() override;
  SourceKind kind() const noexcept override { return SourceKind::kDevice; }
  Result<Frame> grab(const GrabContext& ctx) override;

 private:
  struct Capture;
  explicit DeviceSource(std::unique_ptr<Capture> capture, std::string name);
  std::unique_ptr<Capture> capture_;
  std::string name_;
};

}  // namespace cell::camera
