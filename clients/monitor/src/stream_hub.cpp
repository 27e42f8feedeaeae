#include "stream_hub.hpp"

namespace cell::monitor {

std::string StreamMessage::frame() const {
  std::string out;
  out.reserve(type.size() + data.size() + 16);
  out += "event: ";
  out += type;
  out += "\ndata: ";
  // SSE ends a data line at a newline: the JSON is one line (nlohmann's dump() without indent
  // escapes newlines inside strings), but guard against any raw one anyway.
  for (const char c : data) {
    if (c == '\n') {
      out += "\ndata: ";
    } else if (c != '\r') {
      out += c;
    }
  }
  out += "\n\n";
  return out;
}

void ClientQueue::push(std::shared_ptr<const std::string> frame) {
  {
    std::lock_guard lock(mutex_);
    if (closed_) {
      return;
    }
    if (frames_.size() >= capacity_) {
      frames_.pop_front();
      ++dropped_;
    }
    frames_.push_back(std::move(frame));
  }
  cv_.notify_one();
}

bool ClientQueue::pop_all(std::vector<std::shared_ptr<const std::string>>& out,
                          std::chrono::milliseconds timeout) {
  std::unique_lock lock(mutex_);
  cv_.wait_for(lock, timeout, [&] { return closed_ || !frames_.empty(); });
  while (!frames_.empty()) {
    out.push_back(std::move(frames_.front()));
    frames_.pop_front();
  }
  return !(closed_ && out.empty());
}

void ClientQueue::close() {
  {
    std::lock_guard lock(mutex_);
    closed_ = true;
  }
  cv_.notify_all();
}

std::uint64_t ClientQueue::dropped() const {
  std::lock_guard lock(mutex_);
  return dropped_;
}

std::size_t ClientQueue::size() const {
  std::lock_guard lock(mutex_);
  return frames_.size();
}

StreamHub::StreamHub(std::size_t capacity, std::size_t max_clients)
    : capacity_(capacity), max_clients_(max_clients) {}

std::optional<std::uint64_t> StreamHub::connect() {
  std::lock_guard lock(mutex_);
  if (clients_.size() >= max_clients_) {
    return std::nullopt;
  }
  auto queue = std::make_shared<ClientQueue>(capacity_ + sticky_.size());
  for (const auto& [key, frame] : sticky_) {
    queue->push(frame);
  }
  const std::uint64_t id = next_id_++;
  clients_.emplace(id, std::move(queue));
  return id;
}

std::shared_ptr<ClientQueue> StreamHub::queue(std::uint64_t id) const {
  std::lock_guard lock(mutex_);
  auto it = clients_.find(id);
  return it == clients_.end() ? nullptr : it->second;
}

void StreamHub::disconnect(std::uint64_t id) {
  std::shared_ptr<ClientQueue> queue;
  {
    std::lock_guard lock(mutex_);
    auto it = clients_.find(id);
    if (it == clients_.end()) {
      return;
    }
    queue = std::move(it->second);
    clients_.erase(it);
    dropped_gone_ += queue->dropped();
  }
  queue->close();
}

void StreamHub::publish(const StreamMessage& message, const std::string& sticky_key) {
  auto frame = std::make_shared<const std::string>(message.frame());
  std::vector<std::shared_ptr<ClientQueue>> targets;
  {
    std::lock_guard lock(mutex_);
    if (!sticky_key.empty()) {
      sticky_[sticky_key] = frame;
    }
    targets.reserve(clients_.size());
    for (const auto& [id, queue] : clients_) {
      targets.push_back(queue);
    }
  }
  for (const auto& queue : targets) {
    queue->push(frame);
  }
}

void StreamHub::remember(const StreamMessage& message, const std::string& sticky_key) {
  auto frame = std::make_shared<const std::string>(message.frame());
  std::lock_guard lock(mutex_);
  sticky_[sticky_key] = std::move(frame);
}

void StreamHub::forget(const std::string& sticky_key) {
  std::lock_guard lock(mutex_);
  sticky_.erase(sticky_key);
}

void StreamHub::close_all() {
  std::lock_guard lock(mutex_);
  for (const auto& [id, queue] : clients_) {
    queue->close();
  }
}

std::size_t StreamHub::client_count() const {
  std::lock_guard lock(mutex_);
  return clients_.size();
}

std::uint64_t StreamHub::dropped_total() const {
  std::lock_guard lock(mutex_);
  std::uint64_t total = dropped_gone_;
  for (const auto& [id, queue] : clients_) {
    total += queue->dropped();
  }
  return total;
}

}  // namespace cell::monitor
