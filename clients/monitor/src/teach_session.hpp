#pragma once

#include <atomic>
#include <functional>
#include <map>
#include <memory>
#include <mutex>
#include <optional>
#include <string>
#include <thread>
#include <vector>

#include <nlohmann/json.hpp>

#include "cell/bus/participant.hpp"
#include "cell/kinematics/robot_model.hpp"
#include "cell/teach/bus_runner.hpp"
#include "cell/teach/playback.hpp"
#include "cell/teach/task_file.hpp"

namespace cell::monitor {

/// The page's teach pendant: one task being edited (shared by every operator, like the one
/// pendant of a cell), recorded from the robot's live joints, stepped forward and back or run,
/// in preview (off line, core/teach's simulate: the arm does not move) or on the robot
/// (core/teach's BusRunner on a worker thread). Files live in one directory (teach.tasks_dir);
/// the page names them, never paths.
///
/// Every method is thread-safe and returns at once (a robot run goes on in the background;
/// its progress reaches the page through `on_change`). Edits during a robot run are refused
/// (kNotReady).
class TeachSession {
 public:
  /// The newest joints of a robot (rad/mm), or nullopt when its state is unknown.
  using JointsFn = std::function<std::optional<kinematics::JointVector>(const std::string&)>;
  /// Called (from any thread, without the session's lock held) whenever the state changes.
  using ChangeFn = std::function<void()>;

  TeachSession(const bus::Participant& participant,
               std::map<std::string, kinematics::RobotModel> models, std::string tasks_dir,
               JointsFn joints, ChangeFn on_change);
  ~TeachSession();  ///< cancels and joins a running playback
  TeachSession(const TeachSession&) = delete;
  TeachSession& operator=(const TeachSession&) = delete;

  /// {"file", "dirty", "cursor", "running", "preview", "message", "task": {name, robot,
  /// speed_scale, steps: [{kind, name, move, speed_scale, joints (rad|mm), wait_s, action,
  /// text}]}, "files": [...]}.
  nlohmann::json state();

  /// Starts an empty task for `robot`. Errors: unknown robot, running.
  Status create(const std::string& robot, const std::string& name);
  /// Opens `file` (a name in tasks_dir, [A-Za-z0-9_.-]+.yaml). Errors: bad name, the loader's.
  Status open(const std::string& file);
  /// Saves to `file` ("" = the file it came from). Errors: no task, bad name, kIo.
  Status save(const std::string& file);

  /// Records the robot's current joints as a pose step inserted at the cursor ("" name: p<n>).
  Status record(const std::string& name, teach::MoveKind move);
  /// Inserts a gripper step / a wait at the cursor.
  Status add_gripper(teach::GripperAction action);
  Status add_wait(double seconds);
  /// Edits (indices 0-based).
  Status remove(std::size_t index);
  Status move(std::size_t from, std::size_t to);
  Status rename(std::size_t index, const std::string& name);
  /// Moves the cursor (no motion).
  Status seek(std::size_t position);

  /// One step forward or back. Preview: returns the simulated joints ({"samples": [[..]],
  /// "duration_s", "action"}) and moves the cursor; robot: starts it in the background.
  Result<nlohmann::json> step(teach::Direction direction, bool preview);
  /// From the cursor to the end. Preview: every step's samples; robot: in the background.
  Result<nlohmann::json> run(bool preview);
  /// Cancels a robot run (the arm is stopped).
  void stop();

  /// True while a robot run is going on.
  bool running() const noexcept { return running_; }

 private:
  Status editable() const;  // needs mutex_ held
  Result<nlohmann::json> simulate_locked(teach::PlaybackOptions options);
  Result<nlohmann::json> start_locked(teach::PlaybackOptions options);
  void changed();
  std::optional<std::string> file_path(const std::string& file) const;

  const bus::Participant& participant_;
  std::map<std::string, kinematics::RobotModel> models_;
  std::string tasks_dir_;
  JointsFn joints_;
  ChangeFn on_change_;

  mutable std::mutex mutex_;
  std::optional<teach::Task> task_;
  std::optional<kinematics::RobotModel> model_;
  std::string file_;
  bool dirty_ = false;
  teach::Cursor cursor_;
  std::string message_;
  std::atomic<bool> running_{false};
  std::unique_ptr<teach::BusRunner> runner_;
  std::string runner_robot_;  // the robot runner_ drives
  std::thread worker_;
};

}  // namespace cell::monitor
