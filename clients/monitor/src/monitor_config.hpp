#pragma once

#include <array>
#include <string>
#include <vector>

#include <Eigen/Geometry>

#include "cell/common/result.hpp"
#include "cell/config/yaml.hpp"
#include "cell/service/common_config.hpp"

namespace cell::monitor {

/// A robot the page draws: its model file and where its base stands in the world (must agree
/// with config/sim-world.yaml's `robots`).
struct RobotEntry {
  std::string id;
  std::string config;  ///< config/robots/<id>.yaml, resolved against CELL_HOME
  Eigen::Isometry3d world_T_base = Eigen::Isometry3d::Identity();  ///< [mm]
};

/// An operator: a name, a role and a password hash ("pbkdf2-sha256$<iter>$<salt>$<hash>",
/// made by `cell-monitor --hash-password`).
struct UserEntry {
  std::string name;
  std::string role = "operator";  ///< "operator" (may command) or "viewer" (may only watch)
  std::string password_hash;
};

/// A job the page can submit in one click: a JobRequest's fields (task.idl). Either the spec
/// is written inline (`spec_yaml`) or it is a job file (`spec_file`, e.g. config/jobs/*.yaml,
/// read at start-up); `kind`, `robot`, `camera` and `belt` default to the spec's own top-level
/// `kind:`, `robot:`, `camera:`, `belt:` keys.
struct JobTemplate {
  std::string name;         ///< shown on the page, e.g. "table_ics"
  std::string description;  ///< one line
  std::string kind;         ///< table_pick_place | conveyor_pick | assembly | task_file
  std::string robot_id;
  std::string camera_id;
  std::string belt_id;
  std::string spec_yaml;     ///< the job description, passed on verbatim
  std::string spec_file;     ///< where spec_yaml came from ("" when inline)
  std::string program_name;  ///< RAPT source name (assembly)
};

/// The table the page draws (world frame, mm): the scene's `table:` (config/scenes/*.yaml).
/// WorldState carries the top's height only, so the outline is configured here.
struct TableEntry {
  std::array<double, 2> x_mm{-600.0, 600.0};
  std::array<double, 2> y_mm{-150.0, 750.0};
  double height_mm = 750.0;  ///< until the world simulator says otherwise
};

/// config/monitor.yaml (clients/monitor/README.md has every key).
struct MonitorConfig {
  service::CommonConfig common;
  std::string bind_address = "127.0.0.1";  ///< `http.bind`: localhost only by default
  int port = 8080;                         ///< `http.port`; 0 picks a free port (tests)
  /// `http.web_root`: the built web app. Default: <directory of cell-monitor>/../share/
  /// cell-monitor/web, where the build puts it (clients/monitor/CMakeLists.txt).
  std::string web_root;
  int max_stream_clients = 16;     ///< `http.max_stream_clients`: SSE connections at once
  std::size_t client_queue = 512;  ///< `http.client_queue`: messages queued per client
  double stream_hz = 60.0;         ///< `stream.robot_hz`: RobotState to the browser (coalesced)
  double world_hz = 20.0;          ///< `stream.world_hz`: WorldState to the browser
  double image_hz = 2.0;           ///< `stream.image_hz`: camera images (JPEG) per camera
  double session_ttl_s = 8 * 3600.0;  ///< `auth.session_ttl_s`
  bool secure_cookie = false;      ///< `auth.secure_cookie`: set when served behind TLS
  /// `auth.viewers_must_sign_in`: false lets anyone who reaches the port watch (commands need
  /// an operator either way); true needs a session to see the stream, images and config.
  bool viewers_must_sign_in = false;
  std::vector<UserEntry> users;    ///< `auth.users`
  std::vector<RobotEntry> robots;  ///< `robots`
  std::vector<std::string> cameras;  ///< `cameras`: config/cameras/*.yaml to draw (frustums)
  std::vector<JobTemplate> job_templates;  ///< `job_templates`
  TableEntry table;                        ///< `table`
  std::string tasks_dir = "config/tasks";  ///< `teach.tasks_dir`: task files the page may open
  /// `vision_config`: the vision service's config, read (loosely: it is that service's file)
  /// for its clear-grip models (`locate.grasps`), which the page draws as fingerprints. Absent
  /// or unreadable: no fingerprints.
  std::string vision_config = "config/vision.yaml";
  double approach_mm = 20.0;       ///< `goto_part.approach_mm`: "go to part N" stops this high
  /// `goto_part.grasp_height_mm`: a detection's grasp point above the camera's working plane
  /// (detections carry no height; 3.81 mm is the top of the thesis's DIPs).
  double grasp_height_mm = 3.81;

  /// Ok, or kConfig naming the key and the rule.
  Status validate() const;
};

/// Reads config/monitor.yaml. Errors: kConfig, every problem at once, "file:line:col: ...".
Result<MonitorConfig> load_config(const config::Document& doc);

/// <directory of the running executable>/../share/cell-monitor/web (the build's output), or ""
/// when /proc/self/exe cannot be read.
std::string default_web_root();

}  // namespace cell::monitor
