#include "cell/protocols/excalibur/pty.hpp"

#include <fcntl.h>
#include <fmt/format.h>
#include <termios.h>
#include <unistd.h>

#include <array>
#include <cerrno>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <system_error>
#include <utility>

namespace cell::protocols::excalibur {
namespace {

Error io_error(std::string_view what) {
  return Error{Errc::kIo, fmt::format("pseudo-terminal: {}: {}", what, std::strerror(errno))};
}

}  // namespace

Result<PseudoTerminal> PseudoTerminal::create() {
  PseudoTerminal pty;
  pty.master_ = ::posix_openpt(O_RDWR | O_NOCTTY | O_CLOEXEC);
  if (pty.master_ < 0) {
    return io_error("posix_openpt");
  }
  if (::grantpt(pty.master_) != 0) {
    return io_error("grantpt");
  }
  if (::unlockpt(pty.master_) != 0) {
    return io_error("unlockpt");
  }
  std::array<char, 128> name{};
  if (::ptsname_r(pty.master_, name.data(), name.size()) != 0) {
    return io_error("ptsname_r");
  }
  pty.slave_path_ = name.data();
  const int flags = ::fcntl(pty.master_, F_GETFL);
  if (flags < 0 || ::fcntl(pty.master_, F_SETFL, flags | O_NONBLOCK) != 0) {
    return io_error("fcntl O_NONBLOCK");
  }
  pty.slave_ = ::open(pty.slave_path_.c_str(), O_RDWR | O_NOCTTY | O_NONBLOCK | O_CLOEXEC);
  if (pty.slave_ < 0) {
    return io_error("open " + pty.slave_path_);
  }
  // Raw mode from the start: with the default (cooked, echoing) settings, bytes written before
  // the gateway configures the port would be echoed back to the master.
  termios tio{};
  if (::tcgetattr(pty.slave_, &tio) != 0) {
    return io_error("tcgetattr");
  }
  ::cfmakeraw(&tio);
  tio.c_cflag |= CLOCAL | CREAD;
  if (::tcsetattr(pty.slave_, TCSANOW, &tio) != 0) {
    return io_error("tcsetattr");
  }
  return pty;
}

PseudoTerminal::PseudoTerminal(PseudoTerminal&& other) noexcept
    : master_(std::exchange(other.master_, -1)),
      slave_(std::exchange(other.slave_, -1)),
      slave_path_(std::move(other.slave_path_)),
      link_path_(std::move(other.link_path_)) {
  other.link_path_.clear();
}

PseudoTerminal& PseudoTerminal::operator=(PseudoTerminal&& other) noexcept {
  if (this != &other) {
    reset();
    master_ = std::exchange(other.master_, -1);
    slave_ = std::exchange(other.slave_, -1);
    slave_path_ = std::move(other.slave_path_);
    link_path_ = std::move(other.link_path_);
    other.link_path_.clear();
  }
  return *this;
}

PseudoTerminal::~PseudoTerminal() { reset(); }

void PseudoTerminal::reset() noexcept {
  if (!link_path_.empty()) {
    // Remove the symlink only if it still points at our slave (a newer simulator may own it).
    std::error_code ec;
    const auto target = std::filesystem::read_symlink(link_path_, ec);
    if (!ec && target == slave_path_) {
      std::filesystem::remove(link_path_, ec);
    }
    link_path_.clear();
  }
  if (slave_ >= 0) {
    ::close(slave_);
    slave_ = -1;
  }
  if (master_ >= 0) {
    ::close(master_);
    master_ = -1;
  }
}

Status PseudoTerminal::publish(const std::string& link_path) {
  namespace fs = std::filesystem;
  std::error_code ec;
  const fs::path path(link_path);
  if (path.has_parent_path()) {
    fs::create_directories(path.parent_path(), ec);
    if (ec) {
      return Error{Errc::kIo, fmt::format("pseudo-terminal: cannot create {}: {}",
                                          path.parent_path().string(), ec.message())};
    }
  }
  const fs::file_status st = fs::symlink_status(path, ec);
  if (fs::exists(st)) {
    if (!fs::is_symlink(st)) {
      return Error{Errc::kInvalidArgument,
                   fmt::format("pseudo-terminal: {} exists and is not a symlink; refusing to "
                               "replace it",
                               link_path)};
    }
    fs::remove(path, ec);
  }
  // Create under a temporary name and rename over: a reader never sees the link missing.
  const std::string tmp = link_path + fmt::format(".{}.tmp", ::getpid());
  fs::remove(tmp, ec);
  fs::create_symlink(slave_path_, tmp, ec);
  if (ec) {
    return Error{Errc::kIo, fmt::format("pseudo-terminal: cannot create symlink {} -> {}: {}",
                                        link_path, slave_path_, ec.message())};
  }
  fs::rename(tmp, path, ec);
  if (ec) {
    fs::remove(tmp, ec);
    return Error{Errc::kIo,
                 fmt::format("pseudo-terminal: cannot publish {}: {}", link_path, ec.message())};
  }
  link_path_ = link_path;
  return ok_status();
}

}  // namespace cell::protocols::excalibur
