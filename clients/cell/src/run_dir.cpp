#include "run_dir.hpp"

#include <fcntl.h>
#include <poll.h>
#include <sys/file.h>
#include <sys/stat.h>
#include <sys/syscall.h>
#include <unistd.h>

#include <cerrno>
#include <chrono>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <thread>

#include <fmt/format.h>
#include <nlohmann/json.hpp>

namespace cell::launcher {
namespace {

namespace fs = std::filesystem;
using nlohmann::json;

std::string errno_text(int err) { return std::strerror(err); }

/// Reads the pid written in an open pid file (0 when empty or garbage).
pid_t read_pid(int fd) {
  char buf[32] = {};
  const ssize_t n = pread(fd, buf, sizeof buf - 1, 0);
  if (n <= 0) {
    return 0;
  }
  return static_cast<pid_t>(std::strtol(buf, nullptr, 10));
}

json to_json(const ExitRecord& r) {
  return json{
      {"ended_ns", r.ended_ns}, {"exit", r.exit}, {"ran_s", r.ran_s}, {"backoff_s", r.backoff_s}};
}

json to_json(const ServiceStatus& s) {
  json history = json::array();
  for (const auto& r : s.history) {
    history.push_back(to_json(r));
  }
  return json{{"name", s.name},
              {"host", s.host},
              {"exec", s.exec},
              {"log", s.log},
              {"pid", s.pid},
              {"state", s.state},
              {"restarts", s.restarts},
              {"last_exit", s.last_exit},
              {"reason", s.reason},
              {"started_ns", s.started_ns},
              {"backoff_s", s.backoff_s},
              {"next_start_ns", s.next_start_ns},
              {"history", history},
              {"last_lines", s.last_lines}};
}

}  // namespace

RunPaths RunPaths::of(const std::string& dir) {
  RunPaths p;
  p.dir = dir;
  p.logs = (fs::path(dir) / "logs").string();
  p.pid_file = (fs::path(dir) / "cell.pid").string();
  p.status_file = (fs::path(dir) / "status.json").string();
  p.supervisor_log = (fs::path(p.logs) / "cell.log").string();
  return p;
}

std::string RunPaths::service_log(const std::string& service) const {
  return (fs::path(logs) / (service + ".log")).string();
}

Status make_run_dirs(const RunPaths& paths) {
  std::error_code ec;
  fs::create_directories(paths.logs, ec);
  if (ec) {
    return Error{Errc::kIo,
                 fmt::format("cannot create run directory '{}': {}", paths.logs, ec.message())};
  }
  return ok_status();
}

// ---------------------------------------------------------------------------------------------
Result<PidFileLock> PidFileLock::acquire(const std::string& pid_file) {
  // A `cell status`/`cell down` probing the lock holds it shared for a moment: retry briefly.
  constexpr int kAttempts = 25;
  for (int attempt = 0;; ++attempt) {
    const int fd = open(pid_file.c_str(), O_RDWR | O_CREAT | O_CLOEXEC, 0644);
    if (fd < 0) {
      return Error{Errc::kIo, fmt::format("cannot open '{}': {}", pid_file, errno_text(errno))};
    }
    if (flock(fd, LOCK_EX | LOCK_NB) != 0) {
      const int err = errno;
      const pid_t owner = read_pid(fd);
      close(fd);
      if (err != EWOULDBLOCK) {
        return Error{Errc::kIo, fmt::format("cannot lock '{}': {}", pid_file, errno_text(err))};
      }
      if (attempt + 1 >= kAttempts) {
        return Error{Errc::kNotReady,
                     fmt::format("a supervisor (pid {}) already owns run directory '{}'; stop "
                                 "it first with `cell down`",
                                 owner, fs::path(pid_file).parent_path().string())};
      }
      std::this_thread::sleep_for(std::chrono::milliseconds(20));
      continue;
    }
    // The previous owner unlinks the file before it lets go of the lock: make sure we locked
    // the file that is still in the directory, not its unlinked ghost.
    struct stat locked {};
    struct stat named {};
    if (fstat(fd, &locked) != 0 || stat(pid_file.c_str(), &named) != 0 ||
        locked.st_ino != named.st_ino || locked.st_dev != named.st_dev) {
      close(fd);
      continue;
    }
    const std::string text = fmt::format("{}\n", getpid());
    if (ftruncate(fd, 0) != 0 ||
        pwrite(fd, text.data(), text.size(), 0) != static_cast<ssize_t>(text.size())) {
      const int err = errno;
      close(fd);
      return Error{Errc::kIo, fmt::format("cannot write '{}': {}", pid_file, errno_text(err))};
    }
    PidFileLock lock;
    lock.path_ = pid_file;
    lock.fd_ = fd;
    return lock;
  }
}

PidFileLock::PidFileLock(PidFileLock&& other) noexcept
    : path_(std::move(other.path_)), fd_(std::exchange(other.fd_, -1)) {}

PidFileLock& PidFileLock::operator=(PidFileLock&& other) noexcept {
  if (this != &other) {
    release();
    path_ = std::move(other.path_);
    fd_ = std::exchange(other.fd_, -1);
  }
  return *this;
}

PidFileLock::~PidFileLock() { release(); }

void PidFileLock::release() noexcept {
  if (fd_ >= 0) {
    unlink(path_.c_str());  // while still locked: nobody can take over a file being removed
    close(fd_);
    fd_ = -1;
  }
}

std::optional<pid_t> live_supervisor(const std::string& pid_file) {
  const int fd = open(pid_file.c_str(), O_RDONLY | O_CLOEXEC);
  if (fd < 0) {
    return std::nullopt;
  }
  if (flock(fd, LOCK_SH | LOCK_NB) == 0) {
    flock(fd, LOCK_UN);
    close(fd);
    return std::nullopt;  // stale: its supervisor is gone
  }
  pid_t pid = 0;
  for (int attempt = 0; attempt < 50 && pid <= 0; ++attempt) {
    pid = read_pid(fd);  // empty for an instant between the owner's lock and its write
    if (pid <= 0) {
      std::this_thread::sleep_for(std::chrono::milliseconds(10));
    }
  }
  close(fd);
  if (pid <= 0) {
    return std::nullopt;
  }
  return pid;
}

// ---------------------------------------------------------------------------------------------
const ServiceStatus* StatusFile::find(const std::string& name) const {
  for (const auto& s : services) {
    if (s.name == name) {
      return &s;
    }
  }
  return nullptr;
}

Status write_file_atomically(const std::string& path, const std::string& text) {
  std::error_code ec;
  std::filesystem::create_directories(std::filesystem::path(path).parent_path(), ec);
  const std::string tmp = path + ".tmp";
  const int fd = open(tmp.c_str(), O_WRONLY | O_CREAT | O_TRUNC | O_CLOEXEC, 0644);
  if (fd < 0) {
    return Error{Errc::kIo, fmt::format("cannot write '{}': {}", tmp, errno_text(errno))};
  }
  std::size_t done = 0;
  while (done < text.size()) {
    const ssize_t n = ::write(fd, text.data() + done, text.size() - done);
    if (n < 0 && errno == EINTR) {
      continue;
    }
    if (n <= 0) {
      const int err = errno;
      close(fd);
      return Error{Errc::kIo, fmt::format("cannot write '{}': {}", tmp, errno_text(err))};
    }
    done += static_cast<std::size_t>(n);
  }
  close(fd);
  if (rename(tmp.c_str(), path.c_str()) != 0) {
    return Error{Errc::kIo,
                 fmt::format("cannot rename '{}' to '{}': {}", tmp, path, errno_text(errno))};
  }
  return ok_status();
}

Status write_status(const std::string& path, const StatusFile& status) {
  json services = json::array();
  for (const auto& s : status.services) {
    services.push_back(to_json(s));
  }
  const json doc{{"profile", status.profile},
                 {"profile_path", status.profile_path},
                 {"supervisor_pid", status.supervisor_pid},
                 {"state", status.state},
                 {"started_ns", status.started_ns},
                 {"updated_ns", status.updated_ns},
                 {"domain_id", status.domain_id},
                 {"partition", status.partition},
                 {"services", services}};
  const std::string text = doc.dump(2) + "\n";
  return write_file_atomically(path, text);
}

Result<StatusFile> read_status(const std::string& path) {
  std::ifstream in(path);
  if (!in) {
    return Error{Errc::kIo, fmt::format("cannot read '{}': {}", path, errno_text(errno))};
  }
  std::stringstream buffer;
  buffer << in.rdbuf();
  try {
    const json doc = json::parse(buffer.str());
    StatusFile status;
    status.profile = doc.at("profile").get<std::string>();
    status.profile_path = doc.at("profile_path").get<std::string>();
    status.supervisor_pid = doc.at("supervisor_pid").get<pid_t>();
    status.state = doc.at("state").get<std::string>();
    status.started_ns = doc.at("started_ns").get<std::int64_t>();
    status.updated_ns = doc.at("updated_ns").get<std::int64_t>();
    status.domain_id = doc.at("domain_id").get<std::uint32_t>();
    status.partition = doc.at("partition").get<std::string>();
    for (const auto& s : doc.at("services")) {
      ServiceStatus out;
      out.name = s.at("name").get<std::string>();
      out.host = s.at("host").get<std::string>();
      out.exec = s.at("exec").get<std::string>();
      out.log = s.at("log").get<std::string>();
      out.pid = s.at("pid").get<pid_t>();
      out.state = s.at("state").get<std::string>();
      out.restarts = s.at("restarts").get<int>();
      out.last_exit = s.at("last_exit").get<std::string>();
      out.reason = s.at("reason").get<std::string>();
      out.started_ns = s.at("started_ns").get<std::int64_t>();
      out.backoff_s = s.at("backoff_s").get<double>();
      out.next_start_ns = s.at("next_start_ns").get<std::int64_t>();
      for (const auto& r : s.at("history")) {
        out.history.push_back(
            ExitRecord{r.at("ended_ns").get<std::int64_t>(), r.at("exit").get<std::string>(),
                       r.at("ran_s").get<double>(), r.at("backoff_s").get<double>()});
      }
      out.last_lines = s.at("last_lines").get<std::vector<std::string>>();
      status.services.push_back(std::move(out));
    }
    return status;
  } catch (const json::exception& e) {
    return Error{Errc::kInvalidArgument,
                 fmt::format("'{}' is not a cell status file: {}", path, e.what())};
  }
}

// ---------------------------------------------------------------------------------------------
bool process_running(pid_t pid) noexcept {
  if (pid <= 0) {
    return false;
  }
  char path[64];
  std::snprintf(path, sizeof path, "/proc/%d/stat", static_cast<int>(pid));
  const int fd = open(path, O_RDONLY | O_CLOEXEC);
  if (fd < 0) {
    return false;
  }
  char buf[512] = {};
  const ssize_t n = read(fd, buf, sizeof buf - 1);
  close(fd);
  if (n <= 0) {
    return false;
  }
  // "pid (comm) S ...": the state follows the last ')' (comm may contain parentheses).
  const char* close_paren = std::strrchr(buf, ')');
  if (close_paren == nullptr || close_paren[1] == '\0' || close_paren[2] == '\0') {
    return true;
  }
  const char state = close_paren[2];
  return state != 'Z' && state != 'X';
}

bool process_is(pid_t pid, const std::string& exe) noexcept {
  if (!process_running(pid)) {
    return false;
  }
  char link[64];
  std::snprintf(link, sizeof link, "/proc/%d/exe", static_cast<int>(pid));
  char target[4096] = {};
  const ssize_t n = readlink(link, target, sizeof target - 1);
  if (n <= 0) {
    return false;
  }
  std::string_view actual(target, static_cast<std::size_t>(n));
  constexpr std::string_view kDeleted = " (deleted)";  // the binary was rebuilt meanwhile
  if (actual.ends_with(kDeleted)) {
    actual.remove_suffix(kDeleted.size());
  }
  std::error_code ec;
  const auto wanted = fs::weakly_canonical(exe, ec);
  return actual == (ec ? exe : wanted.string());
}

bool wait_process_exit(pid_t pid, int timeout_ms) noexcept {
  if (!process_running(pid)) {
    return true;
  }
#ifdef SYS_pidfd_open
  const int pidfd = static_cast<int>(syscall(SYS_pidfd_open, pid, 0));
  if (pidfd >= 0) {
    pollfd pfd{pidfd, POLLIN, 0};
    int rc;
    do {
      rc = ::poll(&pfd, 1, timeout_ms);  // readable once the process has exited
    } while (rc < 0 && errno == EINTR);
    close(pidfd);
    return rc > 0 || !process_running(pid);
  }
  if (errno == ESRCH) {
    return true;
  }
#endif
  const auto deadline = std::chrono::steady_clock::now() + std::chrono::milliseconds(timeout_ms);
  while (std::chrono::steady_clock::now() < deadline) {
    if (!process_running(pid)) {
      return true;
    }
    std::this_thread::sleep_for(std::chrono::milliseconds(20));
  }
  return !process_running(pid);
}

}  // namespace cell::launcher
