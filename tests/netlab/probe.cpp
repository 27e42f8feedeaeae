// cell-netlab-probe: a UDP echo and its pinger for the lab (the image has no ping(8)).
//
//   cell-netlab-probe echo --port P
//       answers every datagram on 0.0.0.0:P with itself, until killed
//   cell-netlab-probe ping --to ADDRESS --port P [--count N] [--interval-ms I] [--timeout-ms T]
//       sends N numbered datagrams I ms apart, waits T ms for the last answers, prints
//       "sent N received M loss X% rtt_median_ms Y rtt_max_ms Z"; exit 0 when any answer came,
//       1 when none did, 2 on a usage error
#include <arpa/inet.h>
#include <netinet/in.h>
#include <poll.h>
#include <sys/socket.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <chrono>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <string>
#include <vector>

namespace {

using Clock = std::chrono::steady_clock;

[[noreturn]] void usage(const std::string& what) {
  std::fprintf(stderr,
               "cell-netlab-probe: %s\nusage: cell-netlab-probe echo --port P | ping --to ADDRESS "
               "--port P [--count N] [--interval-ms I] [--timeout-ms T]\n",
               what.c_str());
  std::exit(2);
}

int echo(int port) {
  const int fd = socket(AF_INET, SOCK_DGRAM | SOCK_CLOEXEC, 0);
  sockaddr_in addr{};
  addr.sin_family = AF_INET;
  addr.sin_port = htons(static_cast<std::uint16_t>(port));
  if (fd < 0 || bind(fd, reinterpret_cast<sockaddr*>(&addr), sizeof addr) != 0) {
    std::fprintf(stderr, "cell-netlab-probe: bind udp port %d: %s\n", port, std::strerror(errno));
    return 1;
  }
  std::printf("echo on udp port %d\n", port);
  std::fflush(stdout);
  char buf[2048];
  for (;;) {
    sockaddr_in from{};
    socklen_t len = sizeof from;
    const ssize_t n = recvfrom(fd, buf, sizeof buf, 0, reinterpret_cast<sockaddr*>(&from), &len);
    if (n > 0) {
      (void)sendto(fd, buf, static_cast<std::size_t>(n), 0, reinterpret_cast<sockaddr*>(&from),
                   len);
    }
  }
}

int ping(const std::string& to, int port, int count, int interval_ms, int timeout_ms) {
  sockaddr_in addr{};
  addr.sin_family = AF_INET;
  addr.sin_port = htons(static_cast<std::uint16_t>(port));
  if (inet_pton(AF_INET, to.c_str(), &addr.sin_addr) != 1) {
    usage("--to '" + to + "' is not an IPv4 address");
  }
  const int fd = socket(AF_INET, SOCK_DGRAM | SOCK_CLOEXEC, 0);
  if (fd < 0) {
    std::fprintf(stderr, "cell-netlab-probe: socket: %s\n", std::strerror(errno));
    return 1;
  }
  std::vector<Clock::time_point> sent_at(static_cast<std::size_t>(count));
  std::vector<double> rtt_ms;
  std::vector<bool> seen(static_cast<std::size_t>(count), false);
  const auto start = Clock::now();
  int sent = 0;
  for (;;) {
    const auto now = Clock::now();
    const auto next_send = start + std::chrono::milliseconds(interval_ms) * sent;
    if (sent < count && now >= next_send) {
      std::uint32_t seq = static_cast<std::uint32_t>(sent);
      sent_at[static_cast<std::size_t>(sent)] = now;
      // Unreachable (a partition) is a lost datagram, not an error.
      (void)sendto(fd, &seq, sizeof seq, 0, reinterpret_cast<sockaddr*>(&addr), sizeof addr);
      ++sent;
      continue;
    }
    const auto deadline = sent < count ? next_send
                                       : start + std::chrono::milliseconds(interval_ms) * count +
                                             std::chrono::milliseconds(timeout_ms);
    if (sent >= count && (now >= deadline || static_cast<int>(rtt_ms.size()) == count)) {
      break;
    }
    pollfd p{fd, POLLIN, 0};
    const auto wait =
        std::chrono::duration_cast<std::chrono::milliseconds>(deadline - now).count() + 1;
    if (poll(&p, 1, static_cast<int>(wait)) > 0) {
      std::uint32_t seq = 0;
      if (recv(fd, &seq, sizeof seq, MSG_DONTWAIT) == sizeof seq &&
          seq < static_cast<std::uint32_t>(sent) && !seen[seq]) {
        seen[seq] = true;
        rtt_ms.push_back(std::chrono::duration<double, std::milli>(Clock::now() - sent_at[seq])
                             .count());
      }
    }
  }
  std::sort(rtt_ms.begin(), rtt_ms.end());
  const double median = rtt_ms.empty() ? 0.0 : rtt_ms[rtt_ms.size() / 2];
  const double worst = rtt_ms.empty() ? 0.0 : rtt_ms.back();
  const double loss = 100.0 * static_cast<double>(count - static_cast<int>(rtt_ms.size())) /
                      static_cast<double>(count);
  std::printf("sent %d received %zu loss %.1f%% rtt_median_ms %.3f rtt_max_ms %.3f\n", count,
              rtt_ms.size(), loss, median, worst);
  return rtt_ms.empty() ? 1 : 0;
}

}  // namespace

int main(int argc, char** argv) {
  if (argc < 2) {
    usage("no mode given");
  }
  const std::string mode = argv[1];
  std::string to;
  int port = 0, count = 1, interval_ms = 10, timeout_ms = 1000;
  for (int i = 2; i < argc; ++i) {
    const std::string arg = argv[i];
    if (i + 1 >= argc) {
      usage("option " + arg + " needs a value");
    }
    const std::string value = argv[++i];
    if (arg == "--to") {
      to = value;
    } else if (arg == "--port") {
      port = std::atoi(value.c_str());
    } else if (arg == "--count") {
      count = std::atoi(value.c_str());
    } else if (arg == "--interval-ms") {
      interval_ms = std::atoi(value.c_str());
    } else if (arg == "--timeout-ms") {
      timeout_ms = std::atoi(value.c_str());
    } else {
      usage("unknown option '" + arg + "'");
    }
  }
  if (port <= 0 || port > 65535) {
    usage("--port must be in 1..65535, got " + std::to_string(port));
  }
  if (mode == "echo") {
    return echo(port);
  }
  if (mode == "ping") {
    if (to.empty() || count < 1 || interval_ms < 0 || timeout_ms < 0) {
      usage("ping needs --to, --count >= 1, --interval-ms >= 0, --timeout-ms >= 0");
    }
    return ping(to, port, count, interval_ms, timeout_ms);
  }
  usage("unknown mode '" + mode + "' (echo, ping)");
}
