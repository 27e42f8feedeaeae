#include "sources.hpp"

#include <algorithm>
#include <filesystem>
#include <system_error>

#include <fmt/format.h>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>
#include <opencv2/videoio.hpp>

#include "cell/common/time.hpp"
#include "cell/kinematics/robot_config.hpp"
#include "cell/render/mount.hpp"
#include "cell/service/paths.hpp"

namespace cell::camera {
namespace {

/// A frame's noise seed: the configured seed and the frame index mixed (splitmix64 finaliser),
/// so frames differ from each other and a run repeats exactly.
std::uint64_t frame_seed(std::uint64_t seed, std::uint64_t index) {
  std::uint64_t z = seed ^ (index * 0x9E3779B97F4A7C15ULL);
  z = (z ^ (z >> 30U)) * 0xBF58476D1CE4E5B9ULL;
  z = (z ^ (z >> 27U)) * 0x94D049BB133111EBULL;
  return z ^ (z >> 31U);
}

/// Any image as continuous mono8. Errors: kIo for an empty or unsupported image.
Result<cv::Mat> to_mono8(const cv::Mat& in, const std::string& what) {
  if (in.empty()) {
    return Error{Errc::kIo, what + ": empty image"};
  }
  cv::Mat grey;
  try {
    if (in.channels() == 3) {
      cv::cvtColor(in, grey, cv::COLOR_BGR2GRAY);
    } else if (in.channels() == 4) {
      cv::cvtColor(in, grey, cv::COLOR_BGRA2GRAY);
    } else {
      grey = in;
    }
    if (grey.depth() != CV_8U) {
      cv::Mat eight;
      grey.convertTo(eight, CV_8U, grey.depth() == CV_16U ? 1.0 / 257.0 : 1.0);
      grey = eight;
    }
  } catch (const cv::Exception& e) {
    return Error{Errc::kIo, fmt::format("{}: cannot convert to mono8: {}", what, e.what())};
  }
  return grey.isContinuous() ? grey : grey.clone();
}

}  // namespace

const std::string& CameraSource::mount_robot_id() const noexcept { return none_; }

SimSource::SimSource(render::CameraDescription camera, std::optional<kinematics::RobotModel> robot,
                     render::Renderer renderer, render::RenderOptions options)
    : camera_(std::move(camera)),
      robot_(std::move(robot)),
      renderer_(std::move(renderer)),
      options_(options) {}

Result<std::unique_ptr<SimSource>> SimSource::create(const CameraConfig& config) {
  auto camera = render::load_camera(config.camera_file);
  if (!camera) {
    return std::move(camera).error();
  }
  if (camera->id != config.camera_id) {
    return Error{Errc::kConfig,
                 fmt::format("{}: describes camera '{}', but camera_id is '{}'",
                             config.camera_file, camera->id, config.camera_id)};
  }
  std::optional<kinematics::RobotModel> robot;
  if (camera->mount == render::MountKind::kEyeInHand) {
    const std::string path = config.sim.robot_config.empty()
                                 ? service::resolve_path("config/robots/" +
                                                         camera->robot.robot_id + ".yaml")
                                 : config.sim.robot_config;
    auto model = kinematics::load_robot(path);
    if (!model) {
      return Error{Errc::kConfig, fmt::format("camera '{}' rides robot '{}': {}", camera->id,
                                              camera->robot.robot_id, model.error().message)};
    }
    if (model->id() != camera->robot.robot_id) {
      return Error{Errc::kConfig, fmt::format("{} describes robot '{}', the camera rides '{}'",
                                              path, model->id(), camera->robot.robot_id)};
    }
    robot = std::move(*model);
  }
  auto renderer = render::Renderer::create(camera->truth.model, camera->lighting);
  if (!renderer) {
    return Error{Errc::kConfig, fmt::format("{}: {}", config.camera_file,
                                            renderer.error().message)};
  }
  render::RenderOptions options;
  options.exposure_s = config.sim.exposure_s >= 0 ? config.sim.exposure_s : camera->exposure_s;
  options.noise_sigma = config.sim.noise_sigma;
  options.gain = config.sim.gain;
  options.seed = config.sim.seed;
  return std::unique_ptr<SimSource>(
      new SimSource(std::move(*camera), std::move(robot), std::move(*renderer), options));
}

const std::string& SimSource::mount_robot_id() const noexcept {
  return camera_.robot.robot_id;
}

Result<Eigen::Isometry3d> SimSource::true_pose(const GrabContext& ctx) const {
  if (camera_.mount == render::MountKind::kFixed) {
    return camera_.truth.pose;
  }
  if (!ctx.joints) {
    return Error{Errc::kNotReady, fmt::format("no joints of robot '{}' at the exposure",
                                              camera_.robot.robot_id)};
  }
  auto mount = render::base_T_mount(*robot_, camera_.robot.frame, *ctx.joints);
  if (!mount) {
    return with_context(std::move(mount).error(), "robot '" + camera_.robot.robot_id + "'");
  }
  return camera_.world_T_camera(camera_.truth, *mount);
}

Result<Frame> SimSource::grab(const GrabContext& ctx) {
  if (ctx.scene == nullptr) {
    return Error{Errc::kNotReady, "no world state received yet (is sim-world running?)"};
  }
  auto pose = true_pose(ctx);
  if (!pose) {
    return std::move(pose).error();
  }
  render::RenderOptions options = options_;
  options.seed = frame_seed(options_.seed, ctx.frame_index);
  Frame frame;
  frame.exposure_ns = ctx.exposure_ns;
  auto stats = renderer_.render(*ctx.scene, *pose, options, frame.image);
  if (!stats) {
    return std::move(stats).error();
  }
  frame.parts_skipped = stats->parts_skipped;
  if (ctx.want_truth) {
    FrameTruth truth;
    truth.world_T_camera = *pose;
    truth.model = camera_.truth.model;
    truth.parts = render::ground_truth(*ctx.scene, camera_.truth.model, *pose);
    frame.truth = std::move(truth);
  }
  return frame;
}

Result<std::unique_ptr<FileSource>> FileSource::create(const FileOptions& options) {
  namespace fs = std::filesystem;
  std::error_code ec;
  std::vector<std::string> files;
  fs::directory_iterator it(options.directory, ec);
  if (ec) {
    return Error{Errc::kIo, fmt::format("files.directory {}: {}", options.directory, ec.message())};
  }
  static const std::vector<std::string> kExtensions = {".png", ".jpg", ".jpeg", ".bmp", ".pgm",
                                                       ".ppm", ".tif", ".tiff"};
  for (const auto& entry : it) {
    std::string ext = entry.path().extension().string();
    std::transform(ext.begin(), ext.end(), ext.begin(),
                   [](unsigned char ch) { return static_cast<char>(std::tolower(ch)); });
    if (entry.is_regular_file(ec) &&
        std::find(kExtensions.begin(), kExtensions.end(), ext) != kExtensions.end()) {
      files.push_back(entry.path().string());
    }
  }
  if (files.empty()) {
    return Error{Errc::kIo, fmt::format("files.directory {}: no images (png, jpg, bmp, pgm, ppm, "
                                        "tif)",
                                        options.directory)};
  }
  std::sort(files.begin(), files.end());
  return std::unique_ptr<FileSource>(new FileSource(std::move(files), options.loop));
}

Result<Frame> FileSource::grab(const GrabContext& ctx) {
  if (next_ >= files_.size()) {
    if (!loop_) {
      return Error{Errc::kNotReady, fmt::format("all {} files replayed", files_.size())};
    }
    next_ = 0;
  }
  const std::string& path = files_[next_++];
  cv::Mat raw;
  try {
    raw = cv::imread(path, cv::IMREAD_UNCHANGED);
  } catch (const cv::Exception& e) {
    return Error{Errc::kIo, fmt::format("{}: {}", path, e.what())};
  }
  if (raw.empty()) {
    return Error{Errc::kIo, fmt::format("{}: cannot read the image", path)};
  }
  auto mono = to_mono8(raw, path);
  if (!mono) {
    return std::move(mono).error();
  }
  Frame frame;
  frame.image = *mono;
  frame.exposure_ns = ctx.exposure_ns;
  return frame;
}

struct DeviceSource::Capture {
  cv::VideoCapture capture;
  cv::Mat raw;
};

DeviceSource::DeviceSource(std::unique_ptr<Capture> capture, std::string name)
    : capture_(std::move(capture)), name_(std::move(name)) {}

DeviceSource::~DeviceSource() = default;

Result<std::unique_ptr<DeviceSource>> DeviceSource::create(const DeviceOptions& options) {
  auto capture = std::make_unique<Capture>();
  const std::string name =
      options.path.empty() ? fmt::format("device index {}", options.index) : options.path;
  try {
    const bool opened = options.path.empty() ? capture->capture.open(options.index)
                                             : capture->capture.open(options.path);
    if (!opened || !capture->capture.isOpened()) {
      return Error{Errc::kIo, fmt::format("cv::VideoCapture cannot open {}", name)};
    }
  } catch (const cv::Exception& e) {
    return Error{Errc::kIo, fmt::format("cv::VideoCapture {}: {}", name, e.what())};
  }
  return std::unique_ptr<DeviceSource>(new DeviceSource(std::move(capture), name));
}

Result<Frame> DeviceSource::grab(const GrabContext& ctx) {
  (void)ctx;
  bool ok = false;
  try {
    ok = capture_->capture.read(capture_->raw);
  } catch (const cv::Exception& e) {
    return Error{Errc::kIo, fmt::format("{}: {}", name_, e.what())};
  }
  const std::int64_t stamp = wall_time_ns();
  if (!ok || capture_->raw.empty()) {
    return Error{Errc::kIo, fmt::format("{}: no frame (end of stream or device gone)", name_)};
  }
  auto mono = to_mono8(capture_->raw, name_);
  if (!mono) {
    return std::move(mono).error();
  }
  Frame frame;
  frame.image = mono->data == capture_->raw.data ? mono->clone() : *mono;
  frame.exposure_ns = stamp;  // the read returned: the exposure ended just before
  return frame;
}

Result<std::unique_ptr<CameraSource>> make_source(const CameraConfig& config) {
  switch (config.source) {
    case SourceKind::kSim: {
      auto s = SimSource::create(config);
      if (!s) {
        return std::move(s).error();
      }
      return std::unique_ptr<CameraSource>(std::move(*s));
    }
    case SourceKind::kFiles: {
      auto s = FileSource::create(config.files);
      if (!s) {
        return std::move(s).error();
      }
      return std::unique_ptr<CameraSource>(std::move(*s));
    }
    case SourceKind::kDevice: {
      auto s = DeviceSource::create(config.device);
      if (!s) {
        return std::move(s).error();
      }
      return std::unique_ptr<CameraSource>(std::move(*s));
    }
  }
  return Error{Errc::kConfig, "unknown source"};
}

}  // namespace cell::camera
