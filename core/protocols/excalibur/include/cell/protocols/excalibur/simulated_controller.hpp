#pragma once

#include <atomic>
#include <chrono>
#include <memory>
#include <mutex>
#include <string>
#include <thread>
#include <vector>

#include "cell/common/result.hpp"
#include "cell/protocols/excalibur/controller_model.hpp"
#include "cell/protocols/excalibur/dialect.hpp"
#include "cell/protocols/excalibur/line_noise.hpp"
#include "cell/protocols/excalibur/pty.hpp"

namespace cell::protocols::excalibur {

/// How the simulated controller meets its serial line.
struct SimulatedLinkOptions {
  /// Publish the pty's slave as this symlink (the gateway's `device`); empty: do not publish.
  std::string link_path;
  /// Pace the controller's output at the byte time of this baud rate (10 bits per character):
  /// a pty has no baud rate of its own, so this is what makes it a 9600-baud line.
  int baud = 9600;
  bool emulate_baud = true;
  /// The loop looks at the line at least this often. It bounds the window in which the
  /// model must judge how fast characters arrived (ControllerModel::receive).
  double poll_period_s = 0.005;
  /// SCHED_FIFO priority of the controller's thread (0: normal scheduling). The simulator
  /// stands for a controller that owns its processor; on a loaded host a normal thread can
  /// answer hundreds of milliseconds late and the host counts the line as lost.
  int realtime_priority = 0;
};

/// The Excalibur controller on a pseudo-terminal: a ControllerModel run on its own thread
/// against the pty's master side, with the output paced at the emulated baud rate and line
/// noise on demand in both directions. The gateway opens slave_path() (or the published
/// symlink) as its serial port. All public methods are thread-safe.
class SimulatedController {
 public:
  /// Creates the pty, publishes the symlink, powers the controller up and starts the thread.
  /// Errors: kIo (pty, symlink), kInvalidArgument (settings, noise, a path that exists and is
  /// not a symlink).
  static Result<std::unique_ptr<SimulatedController>> start(Dialect dialect,
                                                            ControllerSettings settings,
                                                            SimulatedLinkOptions link,
                                                            NoiseSettings noise = {});
  ~SimulatedController();
  SimulatedController(const SimulatedController&) = delete;
  SimulatedController& operator=(const SimulatedController&) = delete;

  /// "/dev/pts/N".
  const std::string& slave_path() const noexcept { return pty_.slave_path(); }
  /// The published symlink (empty when none).
  const std::string& link_path() const noexcept { return pty_.link_path(); }

  /// The controller now: true angles, mode, counters.
  ControllerStatus status() const;
  /// Changes the injected noise at once (both directions). Errors: kInvalidArgument.
  Status set_noise(const NoiseSettings& noise);
  NoiseSettings noise() const;
  void set_move_not_achieved_probability(double p);
  /// See ControllerModel::set_reply_delay.
  void set_reply_delay(double seconds);
  /// Lines the controller answered with an error since the last call, each with the reason
  /// (for the simulator's log).
  std::vector<std::string> take_rejections();
  /// True when link.realtime_priority was asked for and the system refused it (the thread
  /// runs with normal scheduling). Settled before start() returns.
  bool realtime_refused() const noexcept { return realtime_.load() == kRealtimeRefused; }

 private:
  SimulatedController(PseudoTerminal pty,
                      ControllerModel model,
                      SimulatedLinkOptions link,
                      NoiseSettings noise);
  void loop();
  double now_s() const;

  PseudoTerminal pty_;
  SimulatedLinkOptions link_;
  std::chrono::steady_clock::time_point epoch_;
  int wake_fd_ = -1;
  static constexpr int kRealtimePending = 0;
  static constexpr int kRealtimeSettled = 1;
  static constexpr int kRealtimeRefused = 2;
  std::atomic<int> realtime_{kRealtimePending};
  std::thread thread_;

  mutable std::mutex mutex_;  // guards model_, noise_, rejections_
  ControllerModel model_;
  NoiseSettings noise_;
  std::vector<std::string> rejections_;
};

}  // namespace cell::protocols::excalibur
