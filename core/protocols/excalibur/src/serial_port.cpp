#include "cell/protocols/excalibur/serial_port.hpp"

#include <fcntl.h>
#include <fmt/format.h>
#include <poll.h>
#include <sys/eventfd.h>
#include <termios.h>
#include <unistd.h>

#include <array>
#include <cerrno>
#include <cstring>

#include "cell/common/realtime.hpp"

namespace cell::protocols::excalibur {
namespace {

using Clock = std::chrono::steady_clock;

Clock::duration seconds(double s) {
  return std::chrono::duration_cast<Clock::duration>(std::chrono::duration<double>(s));
}

void sleep_until(Clock::time_point t) {
  if (t > Clock::now()) {
    std::this_thread::sleep_until(t);
  }
}

}  // namespace

unsigned baud_constant(int baud) noexcept {
  switch (baud) {
    case 1200:
      return B1200;
    case 2400:
      return B2400;
    case 4800:
      return B4800;
    case 9600:
      return B9600;
    case 19200:
      return B19200;
    case 38400:
      return B38400;
    case 57600:
      return B57600;
    case 115200:
      return B115200;
    case 230400:
      return B230400;
    default:
      return 0;
  }
}

SerialPort::SerialPort(SerialOptions options, Classifier classify)
    : options_(std::move(options)), classify_(std::move(classify)) {}

Result<std::unique_ptr<SerialPort>> SerialPort::open(const SerialOptions& options,
                                                     Classifier classify) {
  if (baud_constant(options.baud) == 0) {
    return Error{Errc::kInvalidArgument,
                 fmt::format("serial port {}: unsupported baud rate {} (1200, 2400, 4800, 9600, "
                             "19200, 38400, 57600, 115200, 230400)",
                             options.device, options.baud)};
  }
  if (!(options.char_delay_s >= 0) || !(options.command_delay_s >= 0) ||
      options.end_chars.empty() || options.max_line_chars == 0) {
    return Error{Errc::kInvalidArgument,
                 fmt::format("serial port {}: delays must be >= 0, end_chars and max_line_chars "
                             "non-empty",
                             options.device)};
  }
  std::unique_ptr<SerialPort> port(new SerialPort(options, std::move(classify)));
  CELL_TRY(port->open_device());
  port->start_reader();
  return port;
}

SerialPort::~SerialPort() {
  stop_reader();
  close_device();
}

Status SerialPort::open_device() {
  const int fd = ::open(options_.device.c_str(), O_RDWR | O_NOCTTY | O_NONBLOCK | O_CLOEXEC);
  if (fd < 0) {
    const int e = errno;
    mark_down(fmt::format("open {}: {}", options_.device, std::strerror(e)));
    return Error{Errc::kIo,
                 fmt::format("serial port {}: cannot open: {}", options_.device, std::strerror(e))};
  }
  termios tio{};
  if (!::isatty(fd) || ::tcgetattr(fd, &tio) != 0) {
    const int e = errno;
    ::close(fd);
    mark_down(fmt::format("{} is not a terminal", options_.device));
    return Error{Errc::kIo, fmt::format("serial port {}: not a terminal: {}", options_.device,
                                        std::strerror(e))};
  }
  ::cfmakeraw(&tio);
  tio.c_cflag |= CLOCAL | CREAD;
  tio.c_cflag &= ~static_cast<tcflag_t>(CRTSCTS | CSTOPB | PARENB);
  tio.c_cflag = (tio.c_cflag & ~static_cast<tcflag_t>(CSIZE)) | CS8;
  tio.c_iflag &= ~static_cast<tcflag_t>(IXON | IXOFF | IXANY);
  tio.c_cc[VMIN] = 0;
  tio.c_cc[VTIME] = 0;
  const auto speed = static_cast<speed_t>(baud_constant(options_.baud));
  ::cfsetispeed(&tio, speed);
  ::cfsetospeed(&tio, speed);
  if (::tcsetattr(fd, TCSANOW, &tio) != 0) {
    const int e = errno;
    ::close(fd);
    mark_down(fmt::format("tcsetattr {}: {}", options_.device, std::strerror(e)));
    return Error{Errc::kIo, fmt::format("serial port {}: cannot set raw mode at {} baud: {}",
                                        options_.device, options_.baud, std::strerror(e))};
  }
  ::tcflush(fd, TCIOFLUSH);
  fd_ = fd;
  {
    std::lock_guard lock(mutex_);
    link_error_.clear();
    replies_.clear();
    link_up_ = true;
  }
  return ok_status();
}

void SerialPort::close_device() noexcept {
  if (fd_ >= 0) {
    ::close(fd_);
    fd_ = -1;
  }
}

void SerialPort::start_reader() {
  wake_fd_ = ::eventfd(0, EFD_CLOEXEC | EFD_NONBLOCK);
  reader_ = std::thread([this, fd = fd_, wake = wake_fd_, priority = options_.realtime_priority] {
    (void)set_thread_fifo(priority);
    reader_loop(fd, wake);
  });
}

void SerialPort::stop_reader() noexcept {
  if (reader_.joinable()) {
    const std::uint64_t one = 1;
    (void)!::write(wake_fd_, &one, sizeof one);
    reader_.join();
  }
  if (wake_fd_ >= 0) {
    ::close(wake_fd_);
    wake_fd_ = -1;
  }
}

void SerialPort::mark_down(std::string why) {
  {
    std::lock_guard lock(mutex_);  // under the lock: a waiter cannot miss the change
    if (link_error_.empty()) {
      link_error_ = std::move(why);
    }
    link_up_ = false;
  }
  cv_.notify_all();
}

std::string SerialPort::link_error() const {
  std::lock_guard lock(mutex_);
  return link_error_;
}

void SerialPort::finish_line(std::string& line, bool overlong) {
  if (line.empty() && !overlong) {
    return;  // "\r\n" gives an empty line after "\r": ignore
  }
  ReceivedLine received{std::move(line), Clock::now(), overlong};
  line.clear();
  const bool unsolicited = !overlong && classify_ && classify_(received.text);
  {
    std::lock_guard lock(mutex_);
    auto& queue = unsolicited ? unsolicited_ : replies_;
    if (queue.size() >= options_.max_queued_lines) {
      queue.pop_front();
      ++dropped_in_;
    }
    queue.push_back(std::move(received));
    last_rx_ = Clock::now();
  }
  ++(unsolicited ? unsolicited_in_ : replies_in_);
  if (overlong) {
    ++overlong_in_;
  }
  cv_.notify_all();
}

void SerialPort::reader_loop(int fd, int wake_fd) {
  std::array<char, 512> buf{};
  std::string line;
  line.reserve(options_.max_line_chars + 1);
  bool overlong = false;
  for (;;) {
    std::array<pollfd, 2> fds{pollfd{fd, POLLIN, 0}, pollfd{wake_fd, POLLIN, 0}};
    const int n = ::poll(fds.data(), fds.size(), -1);
    if (n < 0) {
      if (errno == EINTR) {
        continue;
      }
      mark_down(fmt::format("poll: {}", std::strerror(errno)));
      return;
    }
    if ((fds[1].revents & POLLIN) != 0) {
      return;
    }
    if ((fds[0].revents & (POLLIN | POLLHUP | POLLERR)) == 0) {
      continue;
    }
    const ssize_t got = ::read(fd, buf.data(), buf.size());
    if (got < 0 && (errno == EAGAIN || errno == EINTR)) {
      continue;
    }
    if (got <= 0) {
      mark_down(got == 0 ? std::string("end of file (the other end closed)")
                         : fmt::format("read: {}", std::strerror(errno)));
      return;
    }
    bytes_in_ += static_cast<std::uint64_t>(got);
    for (ssize_t i = 0; i < got; ++i) {
      const char c = buf[static_cast<std::size_t>(i)];
      if (options_.end_chars.find(c) != std::string::npos) {
        finish_line(line, overlong);
        overlong = false;
      } else if (line.size() >= options_.max_line_chars) {
        overlong = true;  // keep the first max_line_chars for the message, drop the rest
      } else {
        line.push_back(c);
      }
    }
  }
}

double SerialPort::char_period_s() const noexcept {
  return (options_.emulate_baud ? byte_time_s() : 0.0) + options_.char_delay_s;
}

Status SerialPort::write_bytes(std::string_view bytes, bool paced) {
  std::lock_guard lock(write_mutex_);
  if (!link_up_ || fd_ < 0) {
    return Error{Errc::kIo,
                 fmt::format("serial port {}: link down: {}", options_.device, link_error())};
  }
  if (paced && options_.command_delay_s > 0) {
    Clock::time_point last_rx;
    {
      std::lock_guard q(mutex_);
      last_rx = last_rx_;
    }
    sleep_until(std::max(last_rx, last_tx_) + seconds(options_.command_delay_s));
  }
  const double period = paced ? char_period_s() : 0.0;
  const std::size_t chunk = period > 0 ? 1 : bytes.size();
  Clock::time_point next = Clock::now();
  std::size_t sent = 0;
  while (sent < bytes.size()) {
    const std::size_t want = std::min(chunk, bytes.size() - sent);
    const ssize_t n = ::write(fd_, bytes.data() + sent, want);
    if (n < 0) {
      if (errno == EINTR) {
        continue;
      }
      if (errno == EAGAIN) {
        pollfd p{fd_, POLLOUT, 0};
        if (::poll(&p, 1, 1000) <= 0) {
          return Error{Errc::kIo,
                       fmt::format("serial port {}: output blocked for 1 s", options_.device)};
        }
        continue;
      }
      const int e = errno;
      return Error{Errc::kIo,
                   fmt::format("serial port {}: write: {}", options_.device, std::strerror(e))};
    }
    sent += static_cast<std::size_t>(n);
    bytes_out_ += static_cast<std::uint64_t>(n);
    if (period > 0 && sent < bytes.size()) {
      // A minimum gap after each character, not an average rate: a late wake-up must not send
      // the next characters back to back (the 6809 would lose them).
      next = std::max(next + seconds(period), Clock::now() + seconds(0.9 * period));
      sleep_until(next);
    }
  }
  last_tx_ = Clock::now();
  ++lines_out_;
  return ok_status();
}

Status SerialPort::write_line(std::string_view bytes) { return write_bytes(bytes, true); }

Status SerialPort::write_raw(std::string_view bytes) { return write_bytes(bytes, false); }

Result<ReceivedLine> SerialPort::wait_reply(std::chrono::nanoseconds timeout) {
  std::unique_lock lock(mutex_);
  cv_.wait_for(lock, timeout, [&] { return !replies_.empty() || !link_up_; });
  if (!replies_.empty()) {
    ReceivedLine line = std::move(replies_.front());
    replies_.pop_front();
    return line;
  }
  if (!link_up_) {
    return Error{Errc::kIo,
                 fmt::format("serial port {}: link down: {}", options_.device, link_error_)};
  }
  return Error{Errc::kTimeout,
               fmt::format("serial port {}: no reply within {:.0f} ms", options_.device,
                           std::chrono::duration<double, std::milli>(timeout).count())};
}

bool SerialPort::pop_unsolicited(ReceivedLine& out) {
  std::lock_guard lock(mutex_);
  if (unsolicited_.empty()) {
    return false;
  }
  out = std::move(unsolicited_.front());
  unsolicited_.pop_front();
  return true;
}

bool SerialPort::wait_unsolicited(std::chrono::nanoseconds timeout) {
  std::unique_lock lock(mutex_);
  cv_.wait_for(lock, timeout, [&] { return !unsolicited_.empty() || !link_up_ || woken_; });
  woken_ = false;
  return !unsolicited_.empty();
}

void SerialPort::wake() noexcept {
  {
    std::lock_guard lock(mutex_);
    woken_ = true;
  }
  cv_.notify_all();
}

std::size_t SerialPort::discard_replies() {
  std::lock_guard lock(mutex_);
  const std::size_t n = replies_.size();
  replies_.clear();
  return n;
}

Status SerialPort::reopen() {
  std::lock_guard write_lock(write_mutex_);
  stop_reader();
  close_device();
  {
    std::lock_guard lock(mutex_);
    link_error_.clear();
    link_up_ = false;
  }
  ++reopens_;
  CELL_TRY(open_device());
  start_reader();
  return ok_status();
}

SerialStats SerialPort::stats() const {
  SerialStats s;
  s.bytes_out = bytes_out_;
  s.bytes_in = bytes_in_;
  s.lines_out = lines_out_;
  s.replies_in = replies_in_;
  s.unsolicited_in = unsolicited_in_;
  s.overlong_in = overlong_in_;
  s.dropped_in = dropped_in_;
  s.reopens = reopens_;
  return s;
}

}  // namespace cell::protocols::excalibur
