// cell-netlab-router: the three-PC lab's "switch". It opens a tun device named cell0 inside each
// host's network namespace and forwards IPv4 packets between them by destination address, each
// one held for a configurable one-way delay (the kernel here has no netem qdisc, so delay cannot
// be added with tc). Loss and partitions are not the router's business: the lab puts nftables
// rules inside the host namespaces for those.
//
//   cell-netlab-router --control SOCK --host NAME=NETNS=ADDRESS [--host ...] [--delay-ms N] [--rt]
//
//   NAME     the host's name in the counters (vision, control, operations)
//   NETNS    a namespace in /run/netns (ip netns add NETNS)
//   ADDRESS  the host's IPv4 address on cell0; packets to it go to that host's tun
//
// Prints "ready" on stdout once every tun is open (the lab then adds the addresses). The control
// socket (UNIX stream) takes one command per line and answers one line:
//   delay MS   set the one-way delay for packets arriving from now on -> "ok delay_ms=MS"
//   stats      counters as one JSON object (per link packets/bytes, drops, hold times)
//   reset      zero the counters -> "ok reset"
//   quit       exit -> "ok quit"
// Packets are queued with their release time (arrival + delay) and written by a timerfd set to
// the earliest release, so each packet leaves at arrival + delay, not on a polling tick.
#include <arpa/inet.h>
#include <fcntl.h>
#include <linux/if.h>
#include <linux/if_tun.h>
#include <sched.h>
#include <sys/epoll.h>
#include <sys/ioctl.h>
#include <sys/socket.h>
#include <sys/timerfd.h>
#include <sys/un.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <ctime>
#include <map>
#include <queue>
#include <string>
#include <vector>

namespace {

struct Host {
  std::string name;
  std::string netns;
  std::uint32_t address = 0;  // network byte order
  int tun = -1;
};

struct Link {
  std::uint64_t packets = 0;
  std::uint64_t bytes = 0;
};

struct Queued {
  std::int64_t release_ns = 0;
  std::int64_t arrival_ns = 0;
  std::uint64_t seq = 0;
  std::size_t to = 0;
  std::size_t from = 0;
  std::vector<std::uint8_t> packet;
};

struct Later {
  bool operator()(const Queued& a, const Queued& b) const {
    return a.release_ns != b.release_ns ? a.release_ns > b.release_ns : a.seq > b.seq;
  }
};

std::int64_t now_ns() {
  timespec ts{};
  clock_gettime(CLOCK_MONOTONIC, &ts);
  return static_cast<std::int64_t>(ts.tv_sec) * 1000000000LL + ts.tv_nsec;
}

[[noreturn]] void die(const std::string& what) {
  std::fprintf(stderr, "cell-netlab-router: %s\n", what.c_str());
  std::exit(1);
}

/// Opens /dev/net/tun inside /run/netns/<netns> as "cell0" (IFF_TUN | IFF_NO_PI) and returns to
/// the router's own namespace. The fd keeps the device in the host's namespace.
int open_tun_in(const std::string& netns, int home_ns) {
  const std::string path = "/run/netns/" + netns;
  const int ns = open(path.c_str(), O_RDONLY | O_CLOEXEC);
  if (ns < 0) {
    die("cannot open namespace " + path + ": " + std::strerror(errno));
  }
  if (setns(ns, CLONE_NEWNET) != 0) {
    die("setns into " + path + ": " + std::strerror(errno));
  }
  close(ns);
  const int fd = open("/dev/net/tun", O_RDWR | O_NONBLOCK | O_CLOEXEC);
  if (fd < 0) {
    die("open /dev/net/tun in " + netns + ": " + std::strerror(errno));
  }
  ifreq ifr{};
  ifr.ifr_flags = IFF_TUN | IFF_NO_PI;
  std::strncpy(ifr.ifr_name, "cell0", IFNAMSIZ - 1);
  if (ioctl(fd, TUNSETIFF, &ifr) != 0) {
    die("TUNSETIFF cell0 in " + netns + ": " + std::strerror(errno));
  }
  if (setns(home_ns, CLONE_NEWNET) != 0) {
    die(std::string("setns back to the router's namespace: ") + std::strerror(errno));
  }
  return fd;
}

Host parse_host(const std::string& spec) {
  const auto a = spec.find('=');
  const auto b = a == std::string::npos ? a : spec.find('=', a + 1);
  if (b == std::string::npos) {
    die("--host '" + spec + "': expected NAME=NETNS=ADDRESS");
  }
  Host h;
  h.name = spec.substr(0, a);
  h.netns = spec.substr(a + 1, b - a - 1);
  const std::string address = spec.substr(b + 1);
  in_addr addr{};
  if (inet_pton(AF_INET, address.c_str(), &addr) != 1) {
    die("--host '" + spec + "': '" + address + "' is not an IPv4 address");
  }
  h.address = addr.s_addr;
  return h;
}

class Router {
 public:
  Router(std::vector<Host> hosts, double delay_ms) : hosts_(std::move(hosts)) {
    set_delay(delay_ms);
    links_.assign(hosts_.size() * hosts_.size(), Link{});
  }

  void set_delay(double ms) { delay_ns_ = static_cast<std::int64_t>(ms * 1e6); }

  /// A packet that host `from` sent on its cell0.
  void arrived(std::size_t from, const std::uint8_t* data, std::size_t size, std::int64_t now) {
    if (size < 20 || (data[0] >> 4) != 4) {
      ++not_ipv4_;
      return;
    }
    std::uint32_t dst = 0;
    std::memcpy(&dst, data + 16, 4);
    std::size_t to = hosts_.size();
    for (std::size_t i = 0; i < hosts_.size(); ++i) {
      if (hosts_[i].address == dst) {
        to = i;
      }
    }
    if (to == hosts_.size() || to == from) {
      ++no_route_;
      return;
    }
    Queued q;
    q.arrival_ns = now;
    q.release_ns = now + delay_ns_;
    q.seq = seq_++;
    q.to = to;
    q.from = from;
    q.packet.assign(data, data + size);
    queue_.push(std::move(q));
  }

  /// Writes every packet due by `now`; returns the next release time (0: queue empty).
  std::int64_t release(std::int64_t now) {
    while (!queue_.empty() && queue_.top().release_ns <= now) {
      const Queued& q = queue_.top();
      const ssize_t n = write(hosts_[q.to].tun, q.packet.data(), q.packet.size());
      if (n == static_cast<ssize_t>(q.packet.size())) {
        Link& link = links_[q.from * hosts_.size() + q.to];
        ++link.packets;
        link.bytes += q.packet.size();
        const double held_ms = static_cast<double>(now - q.arrival_ns) / 1e6;
        const double late_ms = static_cast<double>(now - q.release_ns) / 1e6;
        max_held_ms_ = std::max(max_held_ms_, held_ms);
        min_held_ms_ = std::min(min_held_ms_, held_ms);
        max_late_ms_ = std::max(max_late_ms_, late_ms);
        sum_late_ms_ += late_ms;
        late_over_1ms_ += late_ms > 1.0 ? 1 : 0;
        ++released_;
      } else {
        ++write_failed_;
      }
      queue_.pop();
    }
    return queue_.empty() ? 0 : queue_.top().release_ns;
  }

  std::string stats() const {
    std::string out = "{\"delay_ms\":" + number(static_cast<double>(delay_ns_) / 1e6) +
                      ",\"links\":[";
    bool first = true;
    for (std::size_t f = 0; f < hosts_.size(); ++f) {
      for (std::size_t t = 0; t < hosts_.size(); ++t) {
        if (f == t) {
          continue;
        }
        const Link& l = links_[f * hosts_.size() + t];
        out += std::string(first ? "" : ",") + "{\"from\":\"" + hosts_[f].name + "\",\"to\":\"" +
               hosts_[t].name + "\",\"packets\":" + std::to_string(l.packets) +
               ",\"bytes\":" + std::to_string(l.bytes) + "}";
        first = false;
      }
    }
    out += "],\"released\":" + std::to_string(released_) +
           ",\"queued\":" + std::to_string(queue_.size()) +
           ",\"no_route\":" + std::to_string(no_route_) +
           ",\"not_ipv4\":" + std::to_string(not_ipv4_) +
           ",\"write_failed\":" + std::to_string(write_failed_) +
           ",\"min_held_ms\":" + number(released_ > 0 ? min_held_ms_ : 0.0) +
           ",\"max_held_ms\":" + number(max_held_ms_) +
           ",\"max_late_ms\":" + number(max_late_ms_) +
           ",\"late_over_1ms\":" + std::to_string(late_over_1ms_) + ",\"mean_late_ms\":" +
           number(released_ > 0 ? sum_late_ms_ / static_cast<double>(released_) : 0.0) + "}";
    return out;
  }

  void reset() {
    links_.assign(links_.size(), Link{});
    no_route_ = not_ipv4_ = write_failed_ = released_ = late_over_1ms_ = 0;
    max_held_ms_ = max_late_ms_ = sum_late_ms_ = 0.0;
    min_held_ms_ = 1e18;
  }

  const std::vector<Host>& hosts() const { return hosts_; }

 private:
  static std::string number(double v) {
    char buf[64];
    std::snprintf(buf, sizeof buf, "%.3f", v);
    return buf;
  }

  std::vector<Host> hosts_;
  std::int64_t delay_ns_ = 0;
  std::vector<Link> links_;
  std::priority_queue<Queued, std::vector<Queued>, Later> queue_;
  std::uint64_t seq_ = 0;
  std::uint64_t no_route_ = 0, not_ipv4_ = 0, write_failed_ = 0, released_ = 0,
                late_over_1ms_ = 0;  // released more than 1 ms after their time (a host stall)
  double max_held_ms_ = 0.0, min_held_ms_ = 1e18, max_late_ms_ = 0.0, sum_late_ms_ = 0.0;
};

void arm_timer(int timer, std::int64_t at_ns) {
  itimerspec spec{};
  if (at_ns > 0) {
    spec.it_value.tv_sec = at_ns / 1000000000LL;
    spec.it_value.tv_nsec = at_ns % 1000000000LL;
  }
  if (timerfd_settime(timer, TFD_TIMER_ABSTIME, &spec, nullptr) != 0) {
    die(std::string("timerfd_settime: ") + std::strerror(errno));
  }
}

struct Client {
  int fd = -1;
  std::string buffer;
};

}  // namespace

int main(int argc, char** argv) {
  std::string control;
  std::vector<Host> hosts;
  double delay_ms = 0.0;
  bool realtime = false;
  for (int i = 1; i < argc; ++i) {
    const std::string arg = argv[i];
    auto value = [&]() -> std::string {
      if (i + 1 >= argc) {
        die("option " + arg + " needs a value");
      }
      return argv[++i];
    };
    if (arg == "--control") {
      control = value();
    } else if (arg == "--host") {
      hosts.push_back(parse_host(value()));
    } else if (arg == "--delay-ms") {
      delay_ms = std::atof(value().c_str());
    } else if (arg == "--rt") {
      realtime = true;
    } else {
      die("unknown argument '" + arg +
          "' (usage: --control SOCK --host NAME=NETNS=ADDRESS... [--delay-ms N] [--rt])");
    }
  }
  if (control.empty() || hosts.size() < 2) {
    die("need --control SOCK and at least two --host NAME=NETNS=ADDRESS");
  }
  if (realtime) {  // hold times to the millisecond on a loaded 2-core machine
    sched_param param{};
    param.sched_priority = 10;
    if (sched_setscheduler(0, SCHED_FIFO, &param) != 0) {
      std::fprintf(stderr, "cell-netlab-router: SCHED_FIFO refused (%s); running normally\n",
                   std::strerror(errno));
    }
  }
  const int home_ns = open("/proc/self/ns/net", O_RDONLY | O_CLOEXEC);
  if (home_ns < 0) {
    die(std::string("open /proc/self/ns/net: ") + std::strerror(errno));
  }
  for (Host& h : hosts) {
    h.tun = open_tun_in(h.netns, home_ns);
  }
  Router router(hosts, delay_ms);

  const int listener = socket(AF_UNIX, SOCK_STREAM | SOCK_CLOEXEC | SOCK_NONBLOCK, 0);
  sockaddr_un addr{};
  addr.sun_family = AF_UNIX;
  if (control.size() >= sizeof addr.sun_path) {
    die("control socket path '" + control + "' is too long");
  }
  std::strncpy(addr.sun_path, control.c_str(), sizeof addr.sun_path - 1);
  unlink(control.c_str());
  if (bind(listener, reinterpret_cast<sockaddr*>(&addr), sizeof addr) != 0 ||
      listen(listener, 8) != 0) {
    die("control socket " + control + ": " + std::strerror(errno));
  }
  const int timer = timerfd_create(CLOCK_MONOTONIC, TFD_NONBLOCK | TFD_CLOEXEC);
  const int ep = epoll_create1(EPOLL_CLOEXEC);
  if (timer < 0 || ep < 0) {
    die(std::string("timerfd/epoll: ") + std::strerror(errno));
  }
  // epoll data: 0..n-1 tun of host i, 1000 timer, 1001 listener, 2000+fd a client.
  auto watch = [&](int fd, std::uint64_t tag) {
    epoll_event ev{};
    ev.events = EPOLLIN;
    ev.data.u64 = tag;
    if (epoll_ctl(ep, EPOLL_CTL_ADD, fd, &ev) != 0) {
      die(std::string("epoll_ctl: ") + std::strerror(errno));
    }
  };
  for (std::size_t i = 0; i < hosts.size(); ++i) {
    watch(hosts[i].tun, i);
  }
  watch(timer, 1000);
  watch(listener, 1001);
  std::map<int, Client> clients;
  std::printf("ready\n");
  std::fflush(stdout);

  std::vector<std::uint8_t> buf(65536);
  std::int64_t armed_at = 0;
  bool running = true;
  while (running) {
    epoll_event events[16];
    const int n = epoll_wait(ep, events, 16, -1);
    if (n < 0) {
      if (errno == EINTR) {
        continue;
      }
      die(std::string("epoll_wait: ") + std::strerror(errno));
    }
    for (int e = 0; e < n; ++e) {
      const std::uint64_t tag = events[e].data.u64;
      if (tag < hosts.size()) {
        for (;;) {  // drain this tun
          const ssize_t got = read(hosts[tag].tun, buf.data(), buf.size());
          if (got <= 0) {
            break;
          }
          router.arrived(tag, buf.data(), static_cast<std::size_t>(got), now_ns());
        }
      } else if (tag == 1000) {
        std::uint64_t expirations = 0;
        (void)!read(timer, &expirations, sizeof expirations);
        armed_at = 0;
      } else if (tag == 1001) {
        const int fd = accept4(listener, nullptr, nullptr, SOCK_CLOEXEC | SOCK_NONBLOCK);
        if (fd >= 0) {
          clients[fd].fd = fd;
          watch(fd, 2000 + static_cast<std::uint64_t>(fd));
        }
      } else {
        const int fd = static_cast<int>(tag - 2000);
        Client& c = clients[fd];
        char text[512];
        const ssize_t got = read(fd, text, sizeof text);
        if (got <= 0) {
          if (got < 0 && errno == EAGAIN) {
            continue;
          }
          epoll_ctl(ep, EPOLL_CTL_DEL, fd, nullptr);
          close(fd);
          clients.erase(fd);
          continue;
        }
        c.buffer.append(text, static_cast<std::size_t>(got));
        for (auto nl = c.buffer.find('\n'); nl != std::string::npos; nl = c.buffer.find('\n')) {
          const std::string line = c.buffer.substr(0, nl);
          c.buffer.erase(0, nl + 1);
          std::string reply;
          if (line.rfind("delay ", 0) == 0) {
            char* end = nullptr;
            const double ms = std::strtod(line.c_str() + 6, &end);
            if (end == line.c_str() + 6 || ms < 0 || ms > 10000) {
              reply = "error: 'delay' needs milliseconds in [0, 10000], got '" +
                      line.substr(6) + "'";
            } else {
              router.set_delay(ms);
              reply = "ok delay_ms=" + line.substr(6);
            }
          } else if (line == "stats") {
            reply = router.stats();
          } else if (line == "reset") {
            router.reset();
            reply = "ok reset";
          } else if (line == "quit") {
            reply = "ok quit";
            running = false;
          } else {
            reply = "error: unknown command '" + line + "' (delay MS, stats, reset, quit)";
          }
          reply += "\n";
          (void)!write(fd, reply.data(), reply.size());
        }
      }
    }
    const std::int64_t next = router.release(now_ns());
    if (next != armed_at) {
      arm_timer(timer, next);
      armed_at = next;
    }
  }
  unlink(control.c_str());
  return 0;
}
