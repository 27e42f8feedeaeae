// cell-monitor: the live web monitor's bridge (clients/monitor/README.md).
//   cell-monitor [--config config/monitor.yaml] [--id ID] [--domain N] [--partition P]
//   cell-monitor --hash-password [--iterations N]   (reads a password on stdin, prints its hash)
#include <termios.h>
#include <unistd.h>

#include <cstdio>
#include <cstring>
#include <exception>
#include <iostream>
#include <string>

#include "auth.hpp"
#include "monitor_service.hpp"

namespace {

int hash_password(int argc, char** argv) {
  int iterations = cell::monitor::kDefaultIterations;
  if (argc == 4 && std::strcmp(argv[2], "--iterations") == 0) {
    iterations = std::atoi(argv[3]);
  } else if (argc != 2) {
    std::cerr << "usage: cell-monitor --hash-password [--iterations N] < password\n";
    return 2;
  }
  termios saved{};
  const bool tty = isatty(STDIN_FILENO) == 1 && tcgetattr(STDIN_FILENO, &saved) == 0;
  if (tty) {
    std::cerr << "password: ";
    termios quiet = saved;
    quiet.c_lflag &= ~static_cast<tcflag_t>(ECHO);
    tcsetattr(STDIN_FILENO, TCSANOW, &quiet);
  }
  std::string password;
  std::getline(std::cin, password);
  if (tty) {
    tcsetattr(STDIN_FILENO, TCSANOW, &saved);
    std::cerr << "\n";
  }
  auto hash = cell::monitor::hash_password(password, iterations);
  if (!hash) {
    std::cerr << "cell-monitor: " << hash.error().message << "\n";
    return 2;
  }
  std::cout << *hash << "\n";
  return 0;
}

}  // namespace

int main(int argc, char** argv) {
  if (argc >= 2 && std::strcmp(argv[1], "--hash-password") == 0) {
    try {
      return hash_password(argc, argv);
    } catch (const std::exception& e) {
      std::fprintf(stderr, "cell-monitor: %s\n", e.what());
      return 1;
    }
  }
  using namespace cell;
  return service::run<monitor::MonitorConfig, monitor::MonitorService>(
      argc, argv,
      {"monitor", "live web monitor: 3-D cell view, teach and playback, jobs (HTTP bridge)",
       "config/monitor.yaml"},
      &monitor::load_config);
}
