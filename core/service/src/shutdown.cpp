#include "cell/service/shutdown.hpp"

#include <unistd.h>

#include <csignal>
#include <cstdio>
#include <cstdlib>

#include "cell/common/log.hpp"

namespace cell::service {
namespace {

// SIGUSR2 only wakes the signal thread for our own destructor.
sigset_t handled_signals() {
  sigset_t set;
  sigemptyset(&set);
  sigaddset(&set, SIGINT);
  sigaddset(&set, SIGTERM);
  sigaddset(&set, SIGUSR2);
  return set;
}

}  // namespace

ShutdownSignal::ShutdownSignal() {
  const sigset_t set = handled_signals();
  pthread_sigmask(SIG_BLOCK, &set, nullptr);
  thread_ = std::thread([this] { loop(); });
}

ShutdownSignal::~ShutdownSignal() {
  pthread_kill(thread_.native_handle(), SIGUSR2);
  thread_.join();
}

void ShutdownSignal::loop() {
  const sigset_t set = handled_signals();
  for (;;) {
    int sig = 0;
    if (sigwait(&set, &sig) != 0) {
      continue;
    }
    if (sig == SIGUSR2) {
      return;
    }
    if (stopping_.exchange(true)) {
      // Second signal while stopping: the operator insists. Leave now.
      std::fprintf(stderr, "second signal %d while stopping: exiting at once\n", sig);
      std::_Exit(128 + sig);
    }
    signal_ = sig;
    log::info("signal", "stop requested", {{"signal", sig == SIGINT ? "SIGINT" : "SIGTERM"}});
    fire();
  }
}

void ShutdownSignal::fire() {
  std::lock_guard lock(mutex_);
  for (auto& [handle, callback] : callbacks_) {
    callback();
  }
  // Set under the lock after the callbacks: whoever sees requested() sees their effects, and
  // on_stop() either lands in the list before fire() or sees requested_ and calls at once.
  requested_ = true;
}

int ShutdownSignal::on_stop(std::function<void()> callback) {
  std::lock_guard lock(mutex_);
  const int handle = next_handle_++;
  if (requested_) {
    callback();
  }
  callbacks_.emplace_back(handle, std::move(callback));
  return handle;
}

void ShutdownSignal::remove(int handle) {
  std::lock_guard lock(mutex_);
  std::erase_if(callbacks_, [handle](const auto& entry) { return entry.first == handle; });
}

void ShutdownSignal::request() {
  if (!stopping_.exchange(true)) {
    fire();
  }
}

}  // namespace cell::service
