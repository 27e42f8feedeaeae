#pragma once

#include <pthread.h>

namespace cell {

/// A mutex with priority inheritance (PTHREAD_PRIO_INHERIT), for data shared between a
/// real-time thread (SCHED_FIFO) and ordinary ones. With a plain std::mutex, a normal thread
/// that holds the lock can be preempted by any other normal thread while the real-time thread
/// waits for it: an unbounded priority inversion, which on a loaded machine stalls a 1 kHz
/// loop for milliseconds. With inheritance, the holder runs at the waiter's priority until it
/// unlocks. BasicLockable and Lockable: use it with std::lock_guard / std::unique_lock.
/// Not copyable or movable. lock() and unlock() never allocate.
class PiMutex {
 public:
  PiMutex() noexcept {
    pthread_mutexattr_t attr;
    pthread_mutexattr_init(&attr);
    pthread_mutexattr_setprotocol(&attr, PTHREAD_PRIO_INHERIT);
    pthread_mutex_init(&mutex_, &attr);
    pthread_mutexattr_destroy(&attr);
  }
  ~PiMutex() { pthread_mutex_destroy(&mutex_); }
  PiMutex(const PiMutex&) = delete;
  PiMutex& operator=(const PiMutex&) = delete;

  void lock() noexcept { pthread_mutex_lock(&mutex_); }
  void unlock() noexcept { pthread_mutex_unlock(&mutex_); }
  bool try_lock() noexcept { return pthread_mutex_trylock(&mutex_) == 0; }

 private:
  pthread_mutex_t mutex_;
};

}  // namespace cell
