#pragma once

#include <atomic>
#include <chrono>
#include <condition_variable>
#include <cstdint>
#include <deque>
#include <functional>
#include <memory>
#include <mutex>
#include <string>
#include <string_view>
#include <thread>

#include "cell/common/result.hpp"

namespace cell::protocols::excalibur {

/// How to open and pace a serial line.
struct SerialOptions {
  std::string device;  ///< /dev/ttyS0, /dev/ttyUSB0, or a pseudo-terminal (or a symlink to one)
  int baud = 9600;     ///< termios speed: 1200 .. 230400 (a pty ignores it: see emulate_baud)
  /// Pace every character at the byte time of `baud` (10 bits per character: start, 8 data,
  /// stop). A pseudo-terminal has no baud rate and moves a line in microseconds; this makes a
  /// pty behave like the real wire. Leave false on a real port (the UART paces itself).
  bool emulate_baud = false;
  double char_delay_s = 0.0;  ///< extra gap after every character (the 6809 is slow)
  /// Quiet time before a line is written: measured from the end of the previous line written
  /// and from the last line received (the controller digests a command before the next).
  double command_delay_s = 0.0;
  std::string end_chars = "\r\n";      ///< any of these ends a received line; empty lines dropped
  std::size_t max_line_chars = 256;    ///< a longer received line is cut and flagged overlong
  std::size_t max_queued_lines = 256;  ///< per queue; the oldest line is dropped beyond it
  /// SCHED_FIFO priority of the reader thread (0: normal scheduling; refused silently without
  /// the privilege: the owner of the port warns once for its own threads).
  int realtime_priority = 0;
};

/// One received line (end characters removed).
struct ReceivedLine {
  std::string text;
  std::chrono::steady_clock::time_point received{};  ///< when its last byte was read
  bool overlong = false;                             ///< cut at max_line_chars: garbage
};

/// Counters since open (reopen does not reset them). Read with stats(); thread-safe.
struct SerialStats {
  std::uint64_t bytes_out = 0;
  std::uint64_t bytes_in = 0;
  std::uint64_t lines_out = 0;
  std::uint64_t replies_in = 0;
  std::uint64_t unsolicited_in = 0;
  std::uint64_t overlong_in = 0;
  std::uint64_t dropped_in = 0;  ///< lines lost because a queue was full
  std::uint64_t reopens = 0;
};

/// A termios serial port (or pseudo-terminal) in raw mode, 8N1, no flow control, with an
/// asynchronous reader thread that splits the input into lines and routes each one to either
/// the reply queue or the unsolicited queue (a `Classifier` decides), so that the controller's
/// unsolicited messages, which arrive at any time and also in the middle of a reply exchange,
/// never get mixed up with replies (digest 001 §1.2: EXCAL's interrupt-driven READCH/WRITECH).
/// Writing is paced: per character (emulated byte time plus char_delay_s) and per command
/// (command_delay_s), because the controller's 6809 cannot keep up with its own baud rate.
///
/// Threads: one writer at a time (write_line is serialised by a mutex); any thread may wait for
/// replies or pop unsolicited lines. The reader thread stops on close, reopen or a dead link
/// (EOF, EIO: e.g. the other end of a pty went away); waiters then get kIo.
class SerialPort {
 public:
  /// true: the line is unsolicited. Called on the reader thread for every line.
  using Classifier = std::function<bool(std::string_view line)>;

  /// Opens `options.device` and starts the reader. Errors: kIo naming the device and errno
  /// (no such file, not a terminal, permission), kInvalidArgument for an unsupported baud.
  static Result<std::unique_ptr<SerialPort>> open(const SerialOptions& options,
                                                  Classifier classify);

  ~SerialPort();
  SerialPort(const SerialPort&) = delete;
  SerialPort& operator=(const SerialPort&) = delete;

  /// Writes `bytes` (a line with its terminator) with pacing; blocks for the pacing time (the
  /// byte time of each character at the emulated baud plus the delays). Errors: kIo when the
  /// link is down or write fails (EAGAIN is waited out for up to 1 s).
  Status write_line(std::string_view bytes);

  /// Writes `bytes` at once, with no pacing at all (benchmarks, fault injection).
  Status write_raw(std::string_view bytes);

  /// Waits up to `timeout` for the next reply line. Errors: kTimeout, or kIo once the link is
  /// down and no reply is queued.
  Result<ReceivedLine> wait_reply(std::chrono::nanoseconds timeout);

  /// Pops the oldest unsolicited line; false when none.
  bool pop_unsolicited(ReceivedLine& out);

  /// Waits up to `timeout` until an unsolicited line is queued, the link is down, or wake() was
  /// called; true when a line is queued.
  bool wait_unsolicited(std::chrono::nanoseconds timeout);

  /// Ends a wait_unsolicited early (another thread has work for the waiter). Allocation-free
  /// and short: callable from a real-time thread.
  void wake() noexcept;

  /// Drops every queued reply (stale answers of an earlier exchange); returns how many.
  std::size_t discard_replies();

  /// Port reset: stops the reader, closes the device, opens it again (same options), flushes
  /// both directions, clears the reply queue (unsolicited lines already received are kept).
  /// Errors: as open(); the port then stays down until a later reopen succeeds.
  Status reopen();

  /// False once the reader met EOF or an error (or a reopen failed).
  bool link_up() const noexcept { return link_up_.load(); }
  /// Why the link is down ("read: Input/output error"), empty while up.
  std::string link_error() const;

  /// Seconds one character occupies the wire at `baud` (10 bits), whether emulated or not.
  double byte_time_s() const noexcept { return 10.0 / options_.baud; }
  /// Seconds write_line spends per character (emulated byte time + char delay).
  double char_period_s() const noexcept;

  SerialStats stats() const;
  const SerialOptions& options() const noexcept { return options_; }

 private:
  SerialPort(SerialOptions options, Classifier classify);
  Status open_device();
  void start_reader();
  void stop_reader() noexcept;
  void close_device() noexcept;
  void reader_loop(int fd, int wake_fd);
  void finish_line(std::string& line, bool overlong);
  void mark_down(std::string why);
  Status write_bytes(std::string_view bytes, bool paced);

  SerialOptions options_;
  Classifier classify_;
  int fd_ = -1;
  int wake_fd_ = -1;  // eventfd: stops the reader
  std::thread reader_;
  std::atomic<bool> link_up_{false};

  mutable std::mutex mutex_;  // guards the queues, link_error_, last_rx_
  std::condition_variable cv_;
  std::deque<ReceivedLine> replies_;
  std::deque<ReceivedLine> unsolicited_;
  std::string link_error_;
  std::chrono::steady_clock::time_point last_rx_{};
  bool woken_ = false;

  std::mutex write_mutex_;  // one writer at a time; guards last_tx_
  std::chrono::steady_clock::time_point last_tx_{};

  std::atomic<std::uint64_t> bytes_out_{0};
  std::atomic<std::uint64_t> bytes_in_{0};
  std::atomic<std::uint64_t> lines_out_{0};
  std::atomic<std::uint64_t> replies_in_{0};
  std::atomic<std::uint64_t> unsolicited_in_{0};
  std::atomic<std::uint64_t> overlong_in_{0};
  std::atomic<std::uint64_t> dropped_in_{0};
  std::atomic<std::uint64_t> reopens_{0};
};

/// termios speed constant of a baud rate, or 0 when unsupported.
unsigned baud_constant(int baud) noexcept;

}  // namespace cell::protocols::excalibur
