#pragma once

#include <cstdint>
#include <string>

#include "cell/common/result.hpp"
#include "cell/config/yaml.hpp"
#include "cell/service/common_config.hpp"

namespace cell::camera {

/// Where frames come from.
enum class SourceKind : std::uint8_t {
  kSim,     ///< the renderer (core/render) drawing the simulated world through the TRUE camera
  kFiles,   ///< a directory of image files, replayed in name order
  kDevice,  ///< a real camera (or a video file) through cv::VideoCapture
};

/// When frames are taken, besides ImageRequests (always answered).
enum class TriggerMode : std::uint8_t {
  kRequest,    ///< only on ImageRequest
  kFree,       ///< free-running at rate_hz
  kPhotocell,  ///< at every photocell edge of the camera's belt (plus the delay)
};

/// config/camera-<id>.yaml (services/camera/README.md documents every key).
///
///   service: {id: camera.ibm7545_eye}
///   camera_id: ibm7545_eye            # answers ImageRequests for this id
///   source: sim                       # sim | files | device
///   camera_file: config/cameras/ibm7545_eye.yaml   # nominal + true camera (sim: required)
///   sim: {noise_sigma: 2.0, seed: 1, gain: 1.0, exposure_s: 0.01, robot_config: ...}
///   files: {directory: /data/frames, loop: true}
///   device: {index: 0}                # or {path: /dev/video2 | clip.avi | frames/%03d.png}
///   trigger: {mode: request, rate_hz: 5, photocell_edge: leave, delay_s: 0, delay_mm: 0,
///             photocell_timeout_s: 10}
///   belt_id: belt1                    # encoder count latched into each image; photocell
///   robot_id: ibm7545                 # joints at exposure (sim: the camera file's mount robot)
///   robot_state_timeout_s: 1.0
///   world_state_timeout_s: 1.0
///   refuse_unknown_cameras: true      # answer requests for ids with no config/cameras file
struct SimOptions {
  double noise_sigma = 2.0;  ///< grey levels
  std::uint64_t seed = 1;    ///< frame k uses a seed mixed from (seed, k): frames differ, runs repeat
  double gain = 1.0;
  double exposure_s = -1.0;  ///< < 0: the camera file's exposure_s
  std::string robot_config;  ///< eye-in-hand: the carrying robot (default config/robots/<id>.yaml)
};

struct FileOptions {
  std::string directory;
  bool loop = true;  ///< start again after the last file (else: refuse with "no more files")
};

struct DeviceOptions {
  int index = -1;    ///< cv::VideoCapture index (when path is empty)
  std::string path;  ///< device node, video file or image-sequence pattern
};

struct TriggerOptions {
  TriggerMode mode = TriggerMode::kRequest;
  double rate_hz = 5.0;              ///< kFree
  bool on_leave = true;              ///< photocell edge: beam cleared (the part has passed,
                                     ///< digest 002 §1.3) or, when false, beam blocked
  double delay_s = 0.0;              ///< after the photocell edge
  double delay_mm = 0.0;             ///< or a belt travel after it (converted at the edge's speed)
  double photocell_timeout_s = 10.0; ///< a PHOTOCELL request with no edge by then is refused
};

struct CameraConfig {
  service::CommonConfig common;
  std::string camera_id;
  SourceKind source = SourceKind::kSim;
  std::string camera_file;  ///< resolved path; required for sim
  SimOptions sim;
  FileOptions files;
  DeviceOptions device;
  TriggerOptions trigger;
  std::string belt_id;
  std::string robot_id;
  double robot_state_timeout_s = 1.0;
  double world_state_timeout_s = 1.0;
  bool refuse_unknown_cameras = true;
  /// Copies on cell/vision/image_preview, at most this often, while a reader is matched
  /// (monitors on other PCs); 0: none.
  double preview_hz = 1.0;
};

/// Reads and validates the file. Errors: kConfig naming file:line:col, key, value and rule.
Result<CameraConfig> load_config(const config::Document& doc);

std::string_view to_string(SourceKind kind) noexcept;

}  // namespace cell::camera
