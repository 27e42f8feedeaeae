#pragma once

#include <chrono>
#include <condition_variable>
#include <cstdint>
#include <deque>
#include <map>
#include <memory>
#include <mutex>
#include <optional>
#include <string>
#include <vector>

/// The fan-out from the bus to the browsers: one bounded queue per connected client, so that a
/// slow browser never blocks the bus thread nor the other browsers.
namespace cell::monitor {

/// One Server-Sent-Events message: `event: <type>\ndata: <json>\n\n`.
struct StreamMessage {
  std::string type;  ///< "robots", "world", "health", "event", ...
  std::string data;  ///< one line of JSON
  /// Serialised SSE frame.
  std::string frame() const;
};

/// One client's queue. Bounded: when full, the oldest message is dropped (a stream's newest
/// sample matters more than an old one) and counted. Thread-safe.
class ClientQueue {
 public:
  explicit ClientQueue(std::size_t capacity) : capacity_(capacity) {}

  /// Appends; drops the oldest when full. Never blocks beyond the queue's own mutex.
  void push(std::shared_ptr<const std::string> frame);

  /// Waits until a frame is queued, the queue is closed, or `timeout` passes; moves every
  /// queued frame into `out` (oldest first). Returns false once closed and drained.
  bool pop_all(std::vector<std::shared_ptr<const std::string>>& out,
               std::chrono::milliseconds timeout);

  /// Wakes the reader for good (server stopping, client gone).
  void close();

  /// Frames dropped because this client was too slow.
  std::uint64_t dropped() const;
  /// Frames queued now.
  std::size_t size() const;

 private:
  std::size_t capacity_;
  mutable std::mutex mutex_;
  std::condition_variable cv_;
  std::deque<std::shared_ptr<const std::string>> frames_;
  std::uint64_t dropped_ = 0;
  bool closed_ = false;
};

/// Every client queue plus the latest message of each "sticky" kind (health, jobs, world, ...),
/// which a newly connected client receives first so that it sees the current cell at once
/// (the bus's transient-local state, carried to the browser). Thread-safe.
class StreamHub {
 public:
  /// `capacity`: per-client queue size; `max_clients`: connections at once.
  StreamHub(std::size_t capacity, std::size_t max_clients);

  /// Registers a client and queues the sticky messages for it. nullopt when max_clients are
  /// connected already.
  std::optional<std::uint64_t> connect();
  /// The queue of client `id` (nullptr when gone).
  std::shared_ptr<ClientQueue> queue(std::uint64_t id) const;
  /// Removes a client (its queue is closed).
  void disconnect(std::uint64_t id);

  /// Sends to every client. `sticky_key` non-empty: also remembered as the latest of that key
  /// for clients that connect later (e.g. "health", "jobs/<job_id>").
  void publish(const StreamMessage& message, const std::string& sticky_key = {});
  /// Remembers `message` as the latest of `sticky_key` for clients that connect later, without
  /// sending it now (the clients have it already in another form, e.g. a batch).
  void remember(const StreamMessage& message, const std::string& sticky_key);
  /// Forgets a sticky key (a job that is gone).
  void forget(const std::string& sticky_key);

  /// Closes every queue (the server is stopping).
  void close_all();

  std::size_t client_count() const;
  /// Total frames dropped for slow clients since start.
  std::uint64_t dropped_total() const;

 private:
  std::size_t capacity_;
  std::size_t max_clients_;
  mutable std::mutex mutex_;
  std::uint64_t next_id_ = 1;
  std::map<std::uint64_t, std::shared_ptr<ClientQueue>> clients_;
  std::map<std::string, std::shared_ptr<const std::string>> sticky_;
  std::uint64_t dropped_gone_ = 0;  // drops of clients that disconnected
};

}  // namespace cell::monitor
