#pragma once

#include <atomic>
#include <chrono>
#include <condition_variable>
#include <deque>
#include <map>
#include <memory>
#include <mutex>
#include <optional>
#include <string>
#include <thread>
#include <vector>

#include <nlohmann/json.hpp>

#include "auth.hpp"
#include "cell/bus/reader.hpp"
#include "cell/bus/request_reply.hpp"
#include "cell/bus/sample.hpp"
#include "cell/bus/topic.hpp"
#include "cell/bus/writer.hpp"
#include "cell/kinematics/robot_model.hpp"
#include "cell/render/camera_file.hpp"
#include "cell/service/directory.hpp"
#include "cell/service/runtime.hpp"
#include "codec.hpp"
#include "commands.hpp"
#include "monitor_config.hpp"
#include "stream_hub.hpp"
#include "teach_session.hpp"

namespace httplib {
class Server;
struct Request;
struct Response;
}  // namespace httplib

namespace cell::monitor {

/// The monitor's bridge: subscribes to the bus and serves the web app (clients/monitor/web)
/// plus a live Server-Sent-Events stream (/api/stream) of everything the page shows, and
/// publishes the commands a signed-in operator makes on the page (clients/monitor/README.md
/// lists the endpoints and the stream's messages).
///
/// Threads.
///  - The bus loop (run()) waits on a waitset of every reader, copies samples into the
///    latest-value stores and queues small messages: it never waits on a browser.
///  - RobotState goes to the stream from the bus loop itself, at most stream.robot_hz per
///    robot: a sample that arrives after a quiet period goes out at once; one that comes too
///    soon goes at the end of the period (the loop's wait deadline), the newest of each robot.
///  - The publisher thread turns the other stores into stream messages at bounded rates:
///    WorldState at stream.world_hz, JPEG images at stream.image_hz per camera, the teach state
///    when it changed. It waits on a condition variable with a deadline (woken by the bus
///    loop), never polls.
///  - cpp-httplib's pool serves HTTP: one thread per open stream (at most
///    http.max_stream_clients), each draining its own bounded drop-oldest queue, so a slow
///    browser loses old samples instead of slowing the others. Command handlers run on HTTP
///    threads and publish through their own writers/requesters (one mutex each).
///
/// Topics: in cell/health/heartbeat, cell/health/event, cell/robot/state (+ state_latest),
/// cell/motion/status, cell/world/state, cell/vision/image, cell/vision/detections,
/// cell/vision/edge_result, cell/calibration/camera, cell/calibration/belt,
/// cell/task/job_status, cell/task/job_command_reply, cell/robot/command_reply; out
/// cell/robot/command, cell/motion/request, cell/task/job_request, cell/task/job_command,
/// cell/health/event (an info event per operator command).
///
/// Never crashes on input: a malformed request, body or sample gets an error (HTTP 400 with a
/// sentence naming the field) or is skipped; an exception in a handler becomes a 500 and a log
/// line.
class MonitorService {
 public:
  /// Loads the robot models and cameras of the config and binds the HTTP port. Throws
  /// std::runtime_error naming the file or the address when it cannot (a setup failure,
  /// STYLE.md §4): the framework exits with code 1.
  MonitorService(service::Context& ctx, const MonitorConfig& config);
  ~MonitorService();
  MonitorService(const MonitorService&) = delete;
  MonitorService& operator=(const MonitorService&) = delete;

  /// Serves until the context's stop is requested.
  void run(service::Context& ctx);

  /// The bound TCP port (useful with http.port 0).
  int port() const noexcept { return port_; }
  /// The stream hub (tests inspect drops and clients).
  const StreamHub& hub() const noexcept { return hub_; }
  /// The authenticator (tests make sessions).
  Authenticator& auth() noexcept { return auth_; }

 private:
  struct Robot {
    kinematics::RobotModel model;
    Eigen::Isometry3d world_T_base;
  };
  struct ImageSlot {
    std::optional<bus::Owned<cell_vision_Image>> latest;  // newest image, not yet encoded
    std::string jpeg;                                     // the last encoded frame
    std::uint64_t seq = 0;
    std::chrono::steady_clock::time_point last_encoded{};
  };
  using Clock = std::chrono::steady_clock;

  // bus side
  /// Takes every reader's samples; returns whether robot states wait for their rate slot.
  bool take_bus(bool robots_pending);
  void publish_health();
  void wake_publisher();
  // publisher side
  void publisher_loop();
  /// Publishes the fresh robot states if stream.robot_hz allows it now; false when not yet due.
  bool publish_robots_if_due(Clock::time_point now);
  Clock::time_point robots_due() const;
  void publish_robots();
  void publish_world();
  Clock::time_point publish_images(Clock::time_point now);
  void publish_teach();

  // http side
  void setup_routes();
  std::optional<SessionInfo> session_of(const httplib::Request& req);
  bool may_view(const httplib::Request& req, httplib::Response& res);
  bool require_operator(const httplib::Request& req, httplib::Response& res, SessionInfo& who);
  std::optional<nlohmann::json> body_json(const httplib::Request& req, httplib::Response& res);
  void handle_login(const httplib::Request& req, httplib::Response& res);
  void handle_stream(const httplib::Request& req, httplib::Response& res);
  void handle_motion(const httplib::Request& req, httplib::Response& res);
  void handle_goto_part(const httplib::Request& req, httplib::Response& res);
  void handle_robot_command(const httplib::Request& req, httplib::Response& res);
  void handle_job_submit(const httplib::Request& req, httplib::Response& res);
  void handle_job_command(const httplib::Request& req, httplib::Response& res);
  void handle_teach(const std::string& action, const httplib::Request& req,
                    httplib::Response& res);
  /// Sends (or previews) a motion; fills the HTTP answer.
  void send_motion(const MotionCommand& cmd, const SessionInfo& who, httplib::Response& res);
  /// The tool pose reaching detection `index` of `camera`'s last image. Errors name why not.
  Result<Eigen::Isometry3d> detection_target(const Robot& robot, const std::string& camera,
                                             long long index, double grasp_height_mm);
  /// Logs an operator's command and publishes it as an info CellEvent (the alarm log's audit).
  void audit(const SessionInfo& who, std::string_view what, std::string_view robot = {},
             std::string_view job = {});
  nlohmann::json config_json() const;
  std::optional<RobotSample> latest_sample(const std::string& robot_id) const;

  MonitorConfig config_;
  service::Context& ctx_;
  std::map<std::string, Robot> robots_;
  std::vector<render::CameraDescription> cameras_;
  nlohmann::json grasps_ = nlohmann::json::array();  // clear-grip models for the overlay
  Authenticator auth_;
  StreamHub hub_;
  std::unique_ptr<TeachSession> teach_;

  // Readers (bus thread only).
  service::ServiceDirectory directory_;
  bus::Topic<cell_robot_RobotState> state_topic_;
  bus::Topic<cell_robot_RobotState> state_latest_topic_;
  bus::Topic<cell_motion_MotionStatus> motion_status_topic_;
  bus::Topic<cell_world_WorldState> world_topic_;
  bus::Topic<cell_vision_Image> image_topic_;
  bus::Topic<cell_vision_Image> preview_topic_;
  bus::Topic<cell_vision_Detections> detections_topic_;
  bus::Topic<cell_vision_EdgeResult> edge_topic_;
  bus::Topic<cell_calibration_CameraCalibration> camera_cal_topic_;
  bus::Topic<cell_calibration_BeltCalibration> belt_cal_topic_;
  bus::Topic<cell_task_JobStatus> job_status_topic_;
  bus::Topic<cell_health_CellEvent> event_topic_;
  bus::Reader<cell_robot_RobotState> states_;
  bus::Reader<cell_robot_RobotState> states_latest_;
  bus::Reader<cell_motion_MotionStatus> motion_status_;
  bus::Reader<cell_world_WorldState> world_;
  bus::Reader<cell_vision_Image> images_;
  bus::Reader<cell_vision_Image> previews_;  ///< what reaches a monitor on another PC
  bus::Reader<cell_vision_Detections> detections_;
  bus::Reader<cell_vision_EdgeResult> edges_;
  bus::Reader<cell_calibration_CameraCalibration> camera_cals_;
  bus::Reader<cell_calibration_BeltCalibration> belt_cals_;
  bus::Reader<cell_task_JobStatus> job_status_;
  bus::Reader<cell_health_CellEvent> events_;

  // Requesters (HTTP threads, each with its mutex).
  std::mutex job_mutex_;
  bus::Requester<cell_task_JobRequest, cell_task_JobStatus> jobs_;
  std::mutex job_command_mutex_;
  bus::Requester<cell_task_JobCommand, cell_task_JobCommandReply> job_commands_;
  std::mutex motion_mutex_;
  bus::Requester<cell_motion_MotionRequest, cell_motion_MotionStatus> motion_;
  std::mutex robot_mutex_;
  bus::Requester<cell_robot_RobotCommand, cell_robot_RobotCommandReply> robot_commands_;

  // Latest values (bus thread writes, publisher and HTTP threads read).
  mutable std::mutex latest_mutex_;
  std::map<std::string, RobotSample> samples_;
  std::map<std::string, bool> sample_fresh_;
  std::optional<bus::Owned<cell_world_WorldState>> world_latest_;
  bool world_fresh_ = false;
  std::map<std::string, nlohmann::json> world_parts_;        // part id -> part json
  double table_height_mm_ = 0.0;                             // from WorldState
  std::map<std::string, nlohmann::json> detections_latest_;  // camera -> detections json
  std::map<std::string, double> plane_z_;                    // camera -> working plane z [mm]
  std::map<std::string, ImageSlot> images_latest_;           // camera -> image
  std::deque<nlohmann::json> event_log_;

  // Bus-thread-only bookkeeping.
  std::string health_signature_;
  std::int64_t health_published_ns_ = 0;
  std::deque<std::string> sticky_jobs_;

  // Publisher wake-up.
  std::mutex wake_mutex_;
  std::condition_variable wake_cv_;
  bool wake_ = false;
  mutable std::mutex robots_mutex_;  // robots_sent_; serialises publish_robots()
  Clock::time_point robots_sent_{};
  Clock::time_point world_sent_{};

  std::atomic<bool> teach_changed_{true};
  std::atomic<bool> stopping_{false};
  std::atomic<std::uint64_t> motion_counter_{0};
  std::unique_ptr<httplib::Server> server_;
  int port_ = 0;
  std::thread http_thread_;
  std::thread publisher_thread_;
  std::int64_t started_ns_ = 0;
};

}  // namespace cell::monitor
