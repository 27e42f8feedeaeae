#pragma once

#include <chrono>
#include <cstdint>
#include <map>
#include <memory>
#include <optional>
#include <set>
#include <string>
#include <vector>

#include "camera_config.hpp"
#include "cell/bus/reader.hpp"
#include "cell/bus/topic.hpp"
#include "cell/bus/writer.hpp"
#include "cell/service/runtime.hpp"
#include "sources.hpp"
#include "world_view.hpp"

namespace cell::camera {

/// The camera service: one camera of the cell, whatever its source (the simulated renderer,
/// replayed files, a real device). Publishes Image (mono8; header stamp = mid-exposure; the
/// carrying robot's joints at the exposure, interpolated from its RobotState stream; the belt's
/// encoder count latched at the exposure, interpolated from BeltState) when triggered: freely
/// at a rate, at each photocell edge (plus a delay), or on ImageRequest (NOW, or at the next
/// photocell edge). Answers every ImageRequest for its camera: with the Image (request_id set)
/// and, when asked, the frame's ImageTruth (simulator only), or with an ImageTruth whose status
/// refuses and says why (no world state yet, no robot state, no photocell edge in time, an
/// unknown camera id when refuse_unknown_cameras). Malformed world parts are skipped with a log
/// line, never a crash.
///
/// Topics: in cell/vision/image_request (command), cell/world/state (stream),
/// cell/robot/state (stream), cell/world/belt (stream), cell/world/photocell (command);
/// out cell/vision/image (stream), cell/vision/image_truth (recent).
class CameraService {
 public:
  /// Throws std::runtime_error when the source cannot be set up (the framework exits 1 and
  /// logs the reason).
  CameraService(service::Context& ctx, const CameraConfig& config);
  void run(service::Context& ctx);

  /// Images published so far (tests).
  std::uint64_t images_published() const noexcept { return image_seq_; }

 private:
  struct RequestKey {
    std::string client_id;
    std::uint64_t seq = 0;
  };
  struct PendingPhotocell {  // a PHOTOCELL request waiting for its edge
    RequestKey key;
    bool with_truth = false;
    std::int64_t received_ns = 0;
    std::chrono::steady_clock::time_point deadline;
  };
  struct Scheduled {  // an exposure fixed by a photocell edge
    std::int64_t exposure_ns = 0;
    std::optional<RequestKey> key;
    bool with_truth = false;
  };

  void take_inputs();
  void handle_request(const cell_vision_ImageRequest& request);
  void handle_photocell(const cell_world_PhotocellEvent& event);
  void take_due_exposures();
  void expire_pending();
  /// Grabs at `exposure_ns` and publishes; answers `key` (if any) either way.
  void take(std::int64_t exposure_ns, const std::optional<RequestKey>& key, bool with_truth);
  void publish_image(const Frame& frame, const std::optional<RequestKey>& key,
                     const std::vector<double>& joints, std::int64_t belt_count);
  void publish_truth(const Frame& frame, const RequestKey& key);
  void refuse(const RequestKey& key, const Error& error);
  /// Steady-clock deadline of the next scheduled or free-running exposure.
  std::chrono::steady_clock::time_point next_wakeup() const;

  CameraConfig config_;
  std::unique_ptr<CameraSource> source_;
  std::string robot_id_;         // joints at exposure ("" when none)
  std::string lights_robot_id_;  // switches the lights (sim)
  render::LightSwitches default_lights_;
  std::string frame_id_;
  std::set<std::string> known_cameras_;

  std::optional<WorldSnapshot> world_;
  std::uint64_t logged_world_seq_ = ~0ULL;
  std::map<std::string, RobotHistory> robots_;
  BeltHistory belt_;
  std::vector<PendingPhotocell> pending_;
  std::vector<Scheduled> scheduled_;
  std::chrono::steady_clock::time_point next_free_;
  std::uint64_t image_seq_ = 0;
  std::chrono::steady_clock::time_point last_failure_log_{};
  bool warned_dark_ = false;

  bus::Topic<cell_vision_ImageRequest> request_topic_;
  bus::Topic<cell_vision_Image> image_topic_;
  bus::Topic<cell_vision_Image> preview_topic_;
  bus::Topic<cell_vision_ImageTruth> truth_topic_;
  bus::Topic<cell_world_WorldState> world_topic_;
  bus::Topic<cell_robot_RobotState> robot_topic_;
  bus::Topic<cell_world_BeltState> belt_topic_;
  bus::Topic<cell_world_PhotocellEvent> photocell_topic_;
  bus::Reader<cell_vision_ImageRequest> request_reader_;
  bus::Writer<cell_vision_Image> image_writer_;
  bus::Writer<cell_vision_Image> preview_writer_;
  std::chrono::steady_clock::time_point next_preview_{};
  bus::Writer<cell_vision_ImageTruth> truth_writer_;
  bus::Reader<cell_world_WorldState> world_reader_;
  bus::Reader<cell_robot_RobotState> robot_reader_;
  bus::Reader<cell_world_BeltState> belt_reader_;
  bus::Reader<cell_world_PhotocellEvent> photocell_reader_;
};

}  // namespace cell::camera
