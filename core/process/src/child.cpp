#include "cell/process/child.hpp"

#include <fcntl.h>
#include <fmt/format.h>
#include <poll.h>
#include <sys/prctl.h>
#include <sys/wait.h>
#include <unistd.h>

#include <cerrno>
#include <csignal>
#include <cstring>
#include <thread>

extern char** environ;

namespace cell::process {
namespace {

std::string errno_text(int err) { return std::strerror(err); }

void set_nonblocking_cloexec(int fd) {
  const int flags = fcntl(fd, F_GETFL);
  fcntl(fd, F_SETFL, flags | O_NONBLOCK);
  fcntl(fd, F_SETFD, FD_CLOEXEC);
}

ExitInfo from_status(int status) {
  ExitInfo info;
  if (WIFEXITED(status)) {
    info.exited = true;
    info.code = WEXITSTATUS(status);
  } else if (WIFSIGNALED(status)) {
    info.signal = WTERMSIG(status);
  }
  return info;
}

}  // namespace

std::string ExitInfo::describe() const {
  if (exited) {
    return fmt::format("exit {}", code);
  }
  return fmt::format("signal {} ({})", signal, strsignal(signal));
}

std::string which(const std::string& name) {
  if (name.find('/') != std::string::npos) {
    return name;
  }
  const char* path = std::getenv("PATH");
  if (path == nullptr) {
    return name;
  }
  std::string_view rest(path);
  while (!rest.empty()) {
    const auto colon = rest.find(':');
    const std::string dir(rest.substr(0, colon));
    std::string candidate = (dir.empty() ? std::string(".") : dir) + "/" + name;
    if (access(candidate.c_str(), X_OK) == 0) {
      return candidate;
    }
    if (colon == std::string_view::npos) {
      break;
    }
    rest.remove_prefix(colon + 1);
  }
  return name;
}

bool pid_alive(pid_t pid) noexcept { return pid > 0 && (kill(pid, 0) == 0 || errno == EPERM); }

Result<Child> Child::spawn(const SpawnOptions& options) {
  const std::string exe = which(options.executable);
  // Build argv/envp before fork: only async-signal-safe calls are allowed in the child.
  std::vector<std::string> argv_store;
  argv_store.push_back(exe);
  argv_store.insert(argv_store.end(), options.args.begin(), options.args.end());
  std::vector<char*> argv;
  argv.reserve(argv_store.size() + 1);
  for (auto& a : argv_store) {
    argv.push_back(a.data());
  }
  argv.push_back(nullptr);

  std::vector<std::string> env_store;
  for (char** e = environ; *e != nullptr; ++e) {
    const std::string entry(*e);
    const auto eq = entry.find('=');
    bool overridden = false;
    for (const auto& extra : options.env) {
      if (extra.compare(0, eq + 1, entry, 0, eq + 1) == 0) {
        overridden = true;
        break;
      }
    }
    if (!overridden) {
      env_store.push_back(entry);
    }
  }
  // Within options.env a later entry for a key replaces an earlier one (a test adds its own
  // CYCLONEDDS_URI after the defaults): getenv() would otherwise see the first.
  for (std::size_t i = 0; i < options.env.size(); ++i) {
    const std::string& entry = options.env[i];
    const auto eq = entry.find('=');
    bool replaced_later = false;
    for (std::size_t k = i + 1; k < options.env.size() && !replaced_later; ++k) {
      replaced_later = options.env[k].compare(0, eq + 1, entry, 0, eq + 1) == 0;
    }
    if (!replaced_later) {
      env_store.push_back(entry);
    }
  }
  std::vector<char*> envp;
  envp.reserve(env_store.size() + 1);
  for (auto& e : env_store) {
    envp.push_back(e.data());
  }
  envp.push_back(nullptr);

  const bool to_file = !options.output_path.empty();
  const bool capture = options.capture_output && !to_file;
  int out_file = -1;
  if (to_file) {
    out_file = ::open(options.output_path.c_str(), O_WRONLY | O_CREAT | O_APPEND | O_CLOEXEC,
                      0644);
    if (out_file < 0) {
      return Error{Errc::kIo,
                   fmt::format("cannot open '{}' for the output of '{}': {}",
                               options.output_path, exe, errno_text(errno))};
    }
  }
  // Closes what was opened so far when the start fails before the child runs.
  int out_pipe[2] = {-1, -1};
  int exec_pipe[2] = {-1, -1};  // reports exec failure: closes on successful exec
  auto fail = [&](const char* what) {
    const int err = errno;
    for (int fd : {out_file, out_pipe[0], out_pipe[1], exec_pipe[0], exec_pipe[1]}) {
      if (fd >= 0) {
        close(fd);
      }
    }
    return Error{Errc::kIo, std::string(what) + ": " + errno_text(err)};
  };
  if (capture && pipe2(out_pipe, O_CLOEXEC) != 0) {
    return fail("pipe");
  }
  if (pipe2(exec_pipe, O_CLOEXEC) != 0) {
    return fail("pipe");
  }
  const pid_t parent = getpid();
  const pid_t pid = fork();
  if (pid < 0) {
    return fail("fork");
  }
  if (pid == 0) {
    if (options.new_process_group) {
      setpgid(0, 0);
    }
    if (options.die_with_parent) {
      prctl(PR_SET_PDEATHSIG, SIGTERM);
      if (getppid() != parent) {
        _exit(127);
      }
    }
    sigset_t none;
    sigemptyset(&none);
    sigprocmask(SIG_SETMASK, &none, nullptr);  // launchers block signals; children must not
    if (capture) {
      dup2(out_pipe[1], STDOUT_FILENO);
      dup2(out_pipe[1], STDERR_FILENO);
    } else if (to_file) {
      dup2(out_file, STDOUT_FILENO);
      dup2(out_file, STDERR_FILENO);
    }
    if (!options.working_dir.empty() && chdir(options.working_dir.c_str()) != 0) {
      const int err = errno;
      (void)!::write(exec_pipe[1], &err, sizeof err);
      _exit(127);
    }
    execve(argv[0], argv.data(), envp.data());
    const int err = errno;
    (void)!::write(exec_pipe[1], &err, sizeof err);
    _exit(127);
  }
  if (options.new_process_group) {
    setpgid(pid, pid);  // also in the parent: no race with an early signal
  }
  close(exec_pipe[1]);
  int child_errno = 0;
  ssize_t n;
  do {
    n = ::read(exec_pipe[0], &child_errno, sizeof child_errno);
  } while (n < 0 && errno == EINTR);
  close(exec_pipe[0]);
  if (capture) {
    close(out_pipe[1]);
  }
  if (out_file >= 0) {
    close(out_file);
  }
  if (n == static_cast<ssize_t>(sizeof child_errno)) {
    waitpid(pid, nullptr, 0);
    if (capture) {
      close(out_pipe[0]);
    }
    return Error{Errc::kIo, fmt::format("cannot start '{}': {}", exe, errno_text(child_errno))};
  }
  Child child;
  child.pid_ = pid;
  child.group_leader_ = options.new_process_group;
  if (capture) {
    child.output_fd_ = out_pipe[0];
    set_nonblocking_cloexec(child.output_fd_);
  }
  return child;
}

Child::Child(Child&& other) noexcept
    : pid_(std::exchange(other.pid_, -1)),
      output_fd_(std::exchange(other.output_fd_, -1)),
      group_leader_(other.group_leader_),
      exit_(other.exit_),
      output_(std::move(other.output_)) {}

Child& Child::operator=(Child&& other) noexcept {
  if (this != &other) {
    if (running()) {
      (void)stop(std::chrono::milliseconds(0));
    }
    close_fd();
    pid_ = std::exchange(other.pid_, -1);
    output_fd_ = std::exchange(other.output_fd_, -1);
    group_leader_ = other.group_leader_;
    exit_ = other.exit_;
    output_ = std::move(other.output_);
  }
  return *this;
}

Child::~Child() {
  if (running()) {
    signal(SIGKILL);
    int status = 0;
    waitpid(pid_, &status, 0);
  }
  close_fd();
}

void Child::close_fd() noexcept {
  if (output_fd_ >= 0) {
    close(output_fd_);
    output_fd_ = -1;
  }
}

bool Child::read_available(std::string& out) {
  if (output_fd_ < 0) {
    return false;
  }
  char buf[4096];
  for (;;) {
    const ssize_t n = ::read(output_fd_, buf, sizeof buf);
    if (n > 0) {
      out.append(buf, static_cast<std::size_t>(n));
      continue;
    }
    if (n == 0) {
      close_fd();
      return false;
    }
    if (errno == EINTR) {
      continue;
    }
    return true;  // EAGAIN: nothing more now
  }
}

std::optional<ExitInfo> Child::poll() {
  if (exit_) {
    return exit_;
  }
  if (pid_ <= 0) {
    return std::nullopt;
  }
  int status = 0;
  const pid_t r = waitpid(pid_, &status, WNOHANG);
  if (r == pid_) {
    exit_ = from_status(status);
  }
  return exit_;
}

std::optional<ExitInfo> Child::wait_for(std::chrono::milliseconds timeout) {
  const auto deadline = std::chrono::steady_clock::now() + timeout;
  for (;;) {
    read_available(output_);
    if (auto info = poll()) {
      read_available(output_);
      return info;
    }
    const auto now = std::chrono::steady_clock::now();
    if (now >= deadline) {
      return std::nullopt;
    }
    const auto left = std::chrono::duration_cast<std::chrono::milliseconds>(deadline - now);
    // Wake on output or every 10 ms to reap (there is no portable fd for child exit here).
    if (output_fd_ >= 0) {
      pollfd pfd{output_fd_, POLLIN, 0};
      ::poll(&pfd, 1, static_cast<int>(std::min<long>(left.count(), 10)));
    } else {
      std::this_thread::sleep_for(std::min(left, std::chrono::milliseconds(10)));
    }
  }
}

void Child::signal(int sig) const noexcept {
  if (pid_ <= 0 || exit_) {
    return;
  }
  if (group_leader_) {
    if (kill(-pid_, sig) == 0) {
      return;
    }
  }
  kill(pid_, sig);
}

ExitInfo Child::stop(std::chrono::milliseconds grace) {
  if (auto info = poll()) {
    return *info;
  }
  signal(SIGTERM);
  if (auto info = wait_for(grace)) {
    return *info;
  }
  signal(SIGKILL);
  int status = 0;
  waitpid(pid_, &status, 0);
  read_available(output_);
  exit_ = from_status(status);
  return *exit_;
}

}  // namespace cell::process
