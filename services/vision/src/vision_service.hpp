#pragma once

#include <chrono>
#include <cstdint>
#include <deque>
#include <map>
#include <memory>
#include <opencv2/core.hpp>
#include <optional>
#include <string>
#include <vector>

#include "cell/bus/reader.hpp"
#include "cell/bus/topic.hpp"
#include "cell/bus/topics.hpp"
#include "cell/bus/writer.hpp"
#include "cell/calibration/camera_calibration.hpp"
#include "cell/kinematics/robot_model.hpp"
#include "cell/service/runtime.hpp"
#include "cell/vision/locate.hpp"
#include "vision_config.hpp"

namespace cell::vision {

/// The vision service. For every Image it publishes Detections (the camera, the exposure's
/// stamp, the robot's joints and the belt count latched with the image, and per part: class,
/// pixel centre, angle, corners, size, robot-base pose, clear-grip verdict, quality), or
/// Detections carrying an error when the image cannot be processed (malformed, unknown camera,
/// wrong size). It answers every EdgeRequest with an EdgeResult: measured, or refused with the
/// reason (unknown camera, window off the image, no edge, image no longer held, none in time).
///
/// Calibration: each camera starts with the NOMINAL calibration of its camera file
/// (calibration::nominal_calibration; logged as such); a CameraCalibration on
/// cell/calibration/camera replaces it at once, and the camera's last image is mapped again and
/// its Detections republished.
///
/// Topics: in cell/vision/image (stream), cell/vision/edge_request (command),
/// cell/calibration/camera (state); out cell/vision/detections (stream), cell/vision/edge_result
/// (recent). One thread: everything runs in run()'s loop; nothing input can cause throws.
class VisionService {
 public:
  /// Throws std::runtime_error for options the locator refuses (the framework exits 1).
  VisionService(service::Context& ctx, const VisionConfig& config);
  void run(service::Context& ctx);

  /// Counters for tests.
  std::uint64_t images_processed() const noexcept { return images_; }
  std::uint64_t edge_replies() const noexcept { return edge_replies_; }

 private:
  struct Frame {
    std::uint64_t seq = 0;
    std::int64_t stamp_ns = 0;
    cv::Mat image;
    std::vector<double> joints;
    std::string robot_id;
    std::int64_t belt_count = 0;
    std::string belt_id;
    std::string request_client;  ///< Image.request_id: the ImageRequest the frame answers
    std::uint64_t request_seq = 0;
  };
  struct Camera {
    std::string id;
    std::optional<calibration::CameraCalibration> nominal;
    std::string nominal_problem;  ///< why there is no nominal calibration
    std::optional<calibration::CameraCalibration> published;
    std::optional<PixelMapper> mapper;  ///< for the current calibration (its lens grid)
    std::string mapper_problem;
    std::deque<Frame> history;
  };
  struct PendingEdge {
    cell_vision_EdgeRequest request{};  ///< numbers only: its strings are the fields below
    std::string client_id;
    std::string camera_id;
    std::uint64_t image_sequence = 0;  ///< 0: the next image after `after_seq`
    std::uint64_t after_seq = 0;
    std::chrono::steady_clock::time_point deadline;
  };

  void take_calibrations();
  void take_images();
  void take_edge_requests();
  void expire_edges();

  /// The camera's state, created on first use (nominal calibration from its file). nullptr for
  /// an unknown camera (no config entry, no camera file, no published calibration): `why` says.
  Camera* camera(const std::string& id, std::string& why);
  void rebuild_mapper(Camera& cam);
  const kinematics::RobotModel* robot(const std::string& id, std::string& why);

  void handle_image(const cell_vision_Image& image);
  void process(Camera& cam, const Frame& frame);
  void publish_error(const cell_vision_Image& image,
                     const std::string& camera_id,
                     const Error& error);
  void serve_pending(const Camera& cam, const Frame& frame);
  void answer(const PendingEdge& edge, const Frame* frame, const Error* error);

  service::Context& ctx_;
  VisionConfig config_;
  Locator locator_;  ///< the global locate options
  std::map<std::string, Locator> camera_locators_;  ///< cameras with their own locate keys
  Locator& locator_for(const std::string& camera_id);
  std::map<std::string, Camera> cameras_;
  std::map<std::string, std::optional<kinematics::RobotModel>> robots_;
  std::map<std::string, std::string> robot_problems_;
  std::vector<PendingEdge> pending_;
  std::map<std::string, std::chrono::steady_clock::time_point> last_warned_;
  std::uint64_t detections_seq_ = 0;
  std::uint64_t images_ = 0;
  std::uint64_t edge_replies_ = 0;

  bus::Topic<cell_vision_Image> image_topic_;
  bus::Topic<cell_vision_Detections> detections_topic_;
  bus::Topic<cell_vision_EdgeRequest> edge_request_topic_;
  bus::Topic<cell_vision_EdgeResult> edge_result_topic_;
  bus::Topic<cell_calibration_CameraCalibration> calibration_topic_;
  bus::Reader<cell_vision_Image> images_reader_;
  bus::Reader<cell_vision_EdgeRequest> edge_reader_;
  bus::Reader<cell_calibration_CameraCalibration> calibration_reader_;
  bus::Writer<cell_vision_Detections> detections_writer_;
  bus::Writer<cell_vision_EdgeResult> edge_writer_;
};

}  // namespace cell::vision
