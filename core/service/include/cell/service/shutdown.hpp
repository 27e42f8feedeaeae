#pragma once

#include <pthread.h>

#include <atomic>
#include <functional>
#include <mutex>
#include <thread>
#include <vector>

namespace cell::service {

/// Turns SIGINT/SIGTERM into an orderly stop. Construct it FIRST in main, before any thread
/// exists: it blocks those signals so every thread (Cyclone's included) inherits the mask, and
/// a dedicated thread takes them with sigwait() and runs the registered callbacks (which
/// trigger guard conditions). A second signal while stopping exits at once (code 128+sig).
class ShutdownSignal {
 public:
  ShutdownSignal();
  ~ShutdownSignal();
  ShutdownSignal(const ShutdownSignal&) = delete;
  ShutdownSignal& operator=(const ShutdownSignal&) = delete;

  /// Runs `callback` on the signal thread when a stop is requested (or at once if one was).
  /// Returns a handle for remove(); remove before whatever the callback touches dies.
  int on_stop(std::function<void()> callback);
  void remove(int handle);

  /// Requests a stop as if a signal had arrived (tests, fatal errors).
  void request();

  /// True once a stop was requested AND every callback registered by then has run.
  bool requested() const noexcept { return requested_.load(); }

  /// The signal number that requested the stop (0 when request() did).
  int signal_number() const noexcept { return signal_.load(); }

 private:
  void loop();
  void fire();

  std::atomic<bool> stopping_{false};   // first request taken (guards against a second)
  std::atomic<bool> requested_{false};  // set under mutex_ after the callbacks ran
  std::atomic<int> signal_{0};
  std::mutex mutex_;
  std::vector<std::pair<int, std::function<void()>>> callbacks_;
  int next_handle_ = 1;
  std::thread thread_;
};

}  // namespace cell::service
