#pragma once

#include <pthread.h>
#include <sched.h>

namespace cell {

/// Puts the calling thread under SCHED_FIFO at `priority` (1..99); 0 leaves its scheduling as
/// it is. For the threads that stand in for hardware that is never starved (a servo loop, a
/// simulated board or controller, a paced serial line): under SCHED_OTHER a loaded host can
/// hold them off the CPU for hundreds of milliseconds. Returns false when the system refused
/// (not root, no CAP_SYS_NICE); the thread then keeps normal scheduling and the caller says so
/// in its log. noexcept; no allocation.
inline bool set_thread_fifo(int priority) noexcept {
  if (priority <= 0) {
    return true;
  }
  sched_param param{};
  param.sched_priority = priority;
  return pthread_setschedparam(pthread_self(), SCHED_FIFO, &param) == 0;
}

/// The calling thread under SCHED_FIFO at `priority` (where permitted) for the object's life,
/// then back to its scheduling before. For a test thread that plays a real-time part (the
/// gateway's servo thread against a simulated board). Not copyable; construct and destroy on
/// the same thread.
class ScopedThreadFifo {
 public:
  explicit ScopedThreadFifo(int priority) noexcept {
    saved_ = pthread_getschedparam(pthread_self(), &policy_, &param_) == 0;
    (void)set_thread_fifo(priority);
  }
  ~ScopedThreadFifo() {
    if (saved_) {
      (void)pthread_setschedparam(pthread_self(), policy_, &param_);
    }
  }
  ScopedThreadFifo(const ScopedThreadFifo&) = delete;
  ScopedThreadFifo& operator=(const ScopedThreadFifo&) = delete;
  ScopedThreadFifo(ScopedThreadFifo&&) = delete;
  ScopedThreadFifo& operator=(ScopedThreadFifo&&) = delete;

 private:
  bool saved_ = false;
  int policy_ = SCHED_OTHER;
  sched_param param_{};
};

}  // namespace cell
