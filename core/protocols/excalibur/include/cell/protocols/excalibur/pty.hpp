#pragma once

#include <string>

#include "cell/common/result.hpp"

namespace cell::protocols::excalibur {

/// A pseudo-terminal pair (posix_openpt, grantpt, unlockpt): the controller simulator owns the
/// master side and the gateway opens the slave side as its serial port. The slave is also held
/// open here, in raw mode: its settings then persist while the gateway closes and reopens its
/// port (a port reset), and the master never sees a hang-up in between. Move-only; closes
/// everything and removes its published symlink on destruction. Not thread-safe.
class PseudoTerminal {
 public:
  /// Creates the pair. Errors: kIo naming the failing call and errno.
  static Result<PseudoTerminal> create();

  PseudoTerminal() = default;
  PseudoTerminal(PseudoTerminal&& other) noexcept;
  PseudoTerminal& operator=(PseudoTerminal&& other) noexcept;
  PseudoTerminal(const PseudoTerminal&) = delete;
  PseudoTerminal& operator=(const PseudoTerminal&) = delete;
  ~PseudoTerminal();

  /// Publishes the slave's path as a symlink at `link_path` (parent directories are created),
  /// replacing an older symlink there (e.g. left by a killed simulator). Errors: kIo, or
  /// kInvalidArgument when `link_path` exists and is not a symlink (never deleted).
  Status publish(const std::string& link_path);

  /// The master side (non-blocking, close-on-exec), or -1.
  int master_fd() const noexcept { return master_; }
  /// "/dev/pts/N".
  const std::string& slave_path() const noexcept { return slave_path_; }
  /// The published symlink, empty when none.
  const std::string& link_path() const noexcept { return link_path_; }

 private:
  void reset() noexcept;
  int master_ = -1;
  int slave_ = -1;
  std::string slave_path_;
  std::string link_path_;
};

}  // namespace cell::protocols::excalibur
