#include "cell/protocols/excalibur/simulated_controller.hpp"

#include <fmt/format.h>
#include <poll.h>
#include <sys/eventfd.h>
#include <unistd.h>

#include <array>
#include <cerrno>
#include <cmath>
#include <cstring>

#include "cell/common/realtime.hpp"

namespace cell::protocols::excalibur {
namespace {

/// Output kept while nobody reads the line (the gateway not connected): beyond this, the
/// oldest bytes are dropped, as a controller's transmit buffer would overflow.
constexpr std::size_t kMaxPendingOut = 4096;

timespec to_timespec(double s) {
  s = std::max(0.0, s);
  const double whole = std::floor(s);
  return timespec{static_cast<time_t>(whole), static_cast<long>((s - whole) * 1e9)};
}

}  // namespace

Result<std::unique_ptr<SimulatedController>> SimulatedController::start(Dialect dialect,
                                                                        ControllerSettings settings,
                                                                        SimulatedLinkOptions link,
                                                                        NoiseSettings noise) {
  CELL_TRY(settings.validate());
  CELL_TRY(noise.validate());
  if (!(link.baud >= 300 && link.baud <= 4'000'000) ||
      !(link.poll_period_s > 0 && link.poll_period_s <= 0.1)) {
    return Error{Errc::kInvalidArgument,
                 fmt::format("simulated link: baud must be in [300, 4000000] and the poll period "
                             "in (0, 0.1] s, got {} and {}",
                             link.baud, link.poll_period_s)};
  }
  auto pty = PseudoTerminal::create();
  if (!pty) {
    return std::move(pty).error();
  }
  if (!link.link_path.empty()) {
    CELL_TRY(pty->publish(link.link_path));
  }
  ControllerModel model(std::move(dialect), settings, 0.0);
  std::unique_ptr<SimulatedController> sim(
      new SimulatedController(std::move(*pty), std::move(model), std::move(link), noise));
  sim->wake_fd_ = ::eventfd(0, EFD_CLOEXEC | EFD_NONBLOCK);
  if (sim->wake_fd_ < 0) {
    return Error{Errc::kIo, fmt::format("eventfd: {}", std::strerror(errno))};
  }
  sim->thread_ = std::thread([s = sim.get()] {
    s->realtime_.store(set_thread_fifo(s->link_.realtime_priority) ? kRealtimeSettled
                                                                   : kRealtimeRefused);
    s->loop();
  });
  while (sim->realtime_.load() == kRealtimePending) {
    std::this_thread::sleep_for(std::chrono::microseconds(200));
  }
  return sim;
}

SimulatedController::SimulatedController(PseudoTerminal pty,
                                         ControllerModel model,
                                         SimulatedLinkOptions link,
                                         NoiseSettings noise)
    : pty_(std::move(pty)),
      link_(std::move(link)),
      epoch_(std::chrono::steady_clock::now()),
      model_(std::move(model)),
      noise_(noise) {
  model_.set_noise(noise_);
}

SimulatedController::~SimulatedController() {
  if (thread_.joinable()) {
    const std::uint64_t one = 1;
    (void)!::write(wake_fd_, &one, sizeof one);
    thread_.join();
  }
  if (wake_fd_ >= 0) {
    ::close(wake_fd_);
  }
}

double SimulatedController::now_s() const {
  return std::chrono::duration<double>(std::chrono::steady_clock::now() - epoch_).count();
}

void SimulatedController::loop() {
  const int fd = pty_.master_fd();
  const double byte_time = link_.emulate_baud ? 10.0 / link_.baud : 0.0;
  std::array<char, 1024> buf{};
  std::string in;
  std::string pending;  // bytes waiting for their slot on the wire
  std::string line;
  double last_read = now_s();
  double next_char = last_read;
  std::uint64_t errors_seen = 0;
  for (;;) {
    double now = now_s();
    double wake = now + link_.poll_period_s;
    {
      std::lock_guard lock(mutex_);
      wake = std::min(wake, model_.next_event_s());
    }
    if (!pending.empty()) {
      wake = std::min(wake, next_char);
    }
    std::array<pollfd, 2> fds{pollfd{fd, POLLIN, 0}, pollfd{wake_fd_, POLLIN, 0}};
    const timespec timeout = to_timespec(wake - now);
    const int n = ::ppoll(fds.data(), fds.size(), &timeout, nullptr);
    if (n < 0 && errno != EINTR) {
      return;
    }
    if ((fds[1].revents & POLLIN) != 0) {
      return;
    }
    in.clear();
    // Bytes read now arrived after the previous pass's last read(), which came after that
    // pass's read_start: the window (previous read_start, now] holds them. The end of the
    // previous pass's reads would not do: a preemption between a drained read() and the clock
    // read put a byte that arrived in between after its true arrival, and the 6809's generous
    // reading then counted a false overrun (excalibur_bench.smoke: ER 3 under load).
    const double read_start = now_s();
    for (;;) {
      const ssize_t got = ::read(fd, buf.data(), buf.size());
      if (got <= 0) {
        break;  // EAGAIN: drained (EIO cannot happen: we hold the slave open ourselves)
      }
      in.append(buf.data(), static_cast<std::size_t>(got));
    }
    now = now_s();
    {
      std::lock_guard lock(mutex_);
      if (!in.empty()) {
        model_.receive(in, last_read, now);
      }
      last_read = read_start;
      model_.advance(now);
      while (model_.pop_output(now, line)) {
        if (pending.empty()) {
          next_char = std::max(next_char, now);
        }
        pending += line;
      }
      const ControllerStatus status = model_.status(now);
      if (status.counters.errors_sent != errors_seen) {
        errors_seen = status.counters.errors_sent;
        if (rejections_.size() < 1000) {
          rejections_.push_back(status.last_rejected);
        }
      }
    }
    if (pending.size() > kMaxPendingOut) {
      pending.erase(0, pending.size() - kMaxPendingOut);
    }
    // Write what is due: one character per byte time when emulating the baud rate (a late
    // wake-up writes the characters that are due at once, so the average rate stays exact).
    std::size_t due = pending.size();
    if (byte_time > 0) {
      due = 0;
      while (due < pending.size() && next_char + static_cast<double>(due) * byte_time <= now) {
        ++due;
      }
    }
    if (due > 0) {
      const ssize_t wrote = ::write(fd, pending.data(), due);
      if (wrote > 0) {
        pending.erase(0, static_cast<std::size_t>(wrote));
        next_char += static_cast<double>(wrote) * byte_time;
      }
    }
  }
}

ControllerStatus SimulatedController::status() const {
  std::lock_guard lock(mutex_);
  return model_.status(now_s());
}

Status SimulatedController::set_noise(const NoiseSettings& noise) {
  CELL_TRY(noise.validate());
  std::lock_guard lock(mutex_);
  noise_ = noise;
  model_.set_noise(noise);
  return ok_status();
}

NoiseSettings SimulatedController::noise() const {
  std::lock_guard lock(mutex_);
  return noise_;
}

void SimulatedController::set_reply_delay(double seconds) {
  std::lock_guard lock(mutex_);
  model_.set_reply_delay(seconds);
}

void SimulatedController::set_move_not_achieved_probability(double p) {
  std::lock_guard lock(mutex_);
  model_.set_move_not_achieved_probability(p);
}

std::vector<std::string> SimulatedController::take_rejections() {
  std::lock_guard lock(mutex_);
  return std::exchange(rejections_, {});
}

}  // namespace cell::protocols::excalibur
