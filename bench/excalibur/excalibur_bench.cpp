// excalibur_bench: how fast is the Excalibur's serial link? Round trip of one command, from
// the moment it is handed to the serial port to the moment its reply is parsed, for a query
// (short command, long reply) and a move (long command, short reply), at 9600 and 19200 baud
// equivalents. A pty has no baud rate: both sides pace every character at the byte time of
// the baud rate (10 bits per character) in the serial layer (SerialPort on the host,
// SimulatedController on the controller side), and the host adds the dialect's per-character
// delay for the slow 6809. The peer: the raw pty round trip with no pacing at all, measured in
// the same run, and the same exchange with the simulated controller but no pacing.
#include <fmt/format.h>
#include <poll.h>
#include <unistd.h>

#include <CLI/CLI.hpp>
#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <exception>
#include <numeric>
#include <string>
#include <thread>
#include <vector>

#include "cell/protocols/excalibur/dialect.hpp"
#include "cell/protocols/excalibur/pty.hpp"
#include "cell/protocols/excalibur/serial_port.hpp"
#include "cell/protocols/excalibur/simulated_controller.hpp"

namespace {

namespace pe = cell::protocols::excalibur;
using Clock = std::chrono::steady_clock;

struct Stats {
  double min_ms = 0, p50_ms = 0, p90_ms = 0, p99_ms = 0, mean_ms = 0;
  std::size_t n = 0;
};

Stats summarize(std::vector<double> ms) {
  Stats s;
  if (ms.empty()) {
    return s;
  }
  std::sort(ms.begin(), ms.end());
  const auto at = [&](double q) {
    return ms[std::min(ms.size() - 1,
                       static_cast<std::size_t>(q * static_cast<double>(ms.size())))];
  };
  s.n = ms.size();
  s.min_ms = ms.front();
  s.p50_ms = at(0.5);
  s.p90_ms = at(0.9);
  s.p99_ms = at(0.99);
  s.mean_ms = std::accumulate(ms.begin(), ms.end(), 0.0) / static_cast<double>(ms.size());
  return s;
}

/// One measured configuration of the link.
struct Case {
  std::string name;
  int baud = 9600;
  bool paced = true;  ///< emulate the baud rate and the 6809's needs; false: raw pty speed
};

struct Row {
  std::string name;
  std::string command;
  std::size_t chars_out = 0;
  std::size_t chars_in = 0;
  double wire_ms = 0;  ///< characters x byte time, both ways (what the baud rate alone costs)
  Stats rtt;
  double exchanges_per_s = 0;  ///< 1 / (p50 + the dialect's command delay)
};

[[noreturn]] void broke(const std::string& why) {
  std::fprintf(stderr, "excalibur_bench: %s\nEXCALIBUR_BENCH_FAILED\n", why.c_str());
  std::exit(1);
}

std::vector<Row> measure_controller(const pe::Dialect& dialect, const Case& c, int count) {
  pe::ControllerSettings s;
  s.lower_deg = {-170, -75, -120, -180, -135, -180};
  s.upper_deg = {170, 195, 240, 180, 135, 180};
  s.speed_deg_s.fill(45.0);
  s.accuracy_deg = 0.3;
  if (c.paced) {  // the 6809 (config/sim-excalibur.yaml)
    s.min_char_interval_s = 0.0012;
    s.busy_after_line_s = 0.008;
    s.reply_delay_s = 0.002;
  }
  auto sim = pe::SimulatedController::start(dialect, s, {.baud = c.baud, .emulate_baud = c.paced});
  if (!sim) {
    broke(sim.error().message);
  }
  pe::SerialOptions o;
  o.device = (*sim)->slave_path();
  o.baud = c.baud;
  o.emulate_baud = c.paced;
  // The host's per-character gap: the dialect's, or more when the baud rate's own byte time
  // plus that gap would still be too fast for the 6809 (1.2 ms a character): at 19200 baud
  // the host must stretch every character to 1.5 ms, so the line is no faster than 9600.
  o.char_delay_s = c.paced ? std::max(dialect.timing().char_delay_s, 0.0015 - 10.0 / c.baud) : 0.0;
  o.command_delay_s = 0.0;  // kept by this loop, outside the timed part
  const double command_delay_s = c.paced ? dialect.timing().command_delay_s : 0.0;
  auto port =
      pe::SerialPort::open(o, [&](std::string_view l) { return dialect.looks_unsolicited(l); });
  if (!port) {
    broke(port.error().message);
  }
  std::this_thread::sleep_for(std::chrono::milliseconds(100));
  (*port)->discard_replies();
  const pe::Command query{};
  const pe::Command move{
      pe::CommandKind::kMoveJoints, {10.5, -30.25, 150.0, 5.0, -5.0, 45.75}, pe::Mode::kHost, 0, 0};
  std::vector<Row> rows;
  for (const pe::Command* cmd : {&query, &move}) {
    const std::string line = *dialect.format(*cmd) + dialect.framing().host_terminator;
    std::vector<double> ms;
    std::size_t chars_in = 0;
    for (int i = -5; i < count; ++i) {  // 5 warm-up exchanges
      std::this_thread::sleep_for(std::chrono::duration<double>(command_delay_s));
      const auto t0 = Clock::now();
      if (auto w = (*port)->write_line(line); !w) {
        broke(w.error().message);
      }
      auto reply = (*port)->wait_reply(std::chrono::seconds(2));
      if (!reply) {
        broke(fmt::format("{} at {} baud: {}", pe::to_string(cmd->kind), c.baud,
                          reply.error().message));
      }
      auto m = dialect.parse(reply->text);
      const auto t1 = Clock::now();
      if (!m || m->kind == pe::MessageKind::kError) {
        broke(fmt::format("{} at {} baud: bad reply {}", pe::to_string(cmd->kind), c.baud,
                          pe::quote_line(reply->text)));
      }
      chars_in = reply->text.size() + dialect.framing().controller_terminator.size();
      if (i >= 0) {
        ms.push_back(std::chrono::duration<double, std::milli>(t1 - t0).count());
      }
    }
    Row r;
    r.name = c.name;
    r.command = cmd->kind == pe::CommandKind::kQueryJoints ? "query QJ -> JA" : "move MJ -> OK";
    r.chars_out = line.size();
    r.chars_in = chars_in;
    r.wire_ms = c.paced ? static_cast<double>(r.chars_out + r.chars_in) * 10.0 / c.baud * 1e3 : 0.0;
    r.rtt = summarize(std::move(ms));
    r.exchanges_per_s = 1e3 / (r.rtt.p50_ms + command_delay_s * 1e3);
    rows.push_back(r);
  }
  return rows;
}

/// The peer: a pty with a trivial echo on the master side (each line answered "OK\r\n" at
/// once) and the host writing unpaced: the operating system's pty and thread wake-ups.
Row measure_raw_pty(int count) {
  auto pty = pe::PseudoTerminal::create();
  if (!pty) {
    broke(pty.error().message);
  }
  std::atomic<bool> stop{false};
  std::thread echo([&] {
    const int fd = pty->master_fd();
    char buf[256];
    while (!stop) {
      pollfd p{fd, POLLIN, 0};
      if (::poll(&p, 1, 50) <= 0) {
        continue;
      }
      const ssize_t n = ::read(fd, buf, sizeof buf);
      for (ssize_t i = 0; i < n; ++i) {
        if (buf[i] == '\r') {
          (void)!::write(fd, "OK\r\n", 4);
        }
      }
    }
  });
  pe::SerialOptions o;
  o.device = pty->slave_path();
  auto port = pe::SerialPort::open(o, nullptr);
  if (!port) {
    broke(port.error().message);
  }
  const std::string line = "QJ*3A0C\r";
  std::vector<double> ms;
  for (int i = -50; i < count * 10; ++i) {
    const auto t0 = Clock::now();
    (void)(*port)->write_raw(line);
    auto reply = (*port)->wait_reply(std::chrono::seconds(2));
    const auto t1 = Clock::now();
    if (!reply) {
      broke("raw pty: " + reply.error().message);
    }
    if (i >= 0) {
      ms.push_back(std::chrono::duration<double, std::milli>(t1 - t0).count());
    }
  }
  stop = true;
  echo.join();
  Row r;
  r.name = "raw pty, no pacing";
  r.command = "8 chars -> OK";
  r.chars_out = line.size();
  r.chars_in = 4;
  r.rtt = summarize(std::move(ms));
  r.exchanges_per_s = 1e3 / r.rtt.p50_ms;
  return r;
}

}  // namespace

static int main_body(int argc, char** argv) {
  CLI::App app{"excalibur_bench: Excalibur serial-link round trip (command sent -> reply parsed)"};
  bool quick = false;
  int count = 200;
  std::string dialect_path = CELL_SOURCE_DIR "/config/controllers/excalibur.yaml";
  app.add_flag("--quick", quick, "smoke run: 20 exchanges per case");
  app.add_option("--count", count, "measured exchanges per command and case")
      ->check(CLI::Range(1, 100000));
  app.add_option("--dialect", dialect_path, "dialect file");
  try {
    app.parse(argc, argv);
  } catch (const CLI::ParseError& e) {
    return app.exit(e) == 0 ? 0 : 2;
  }
  if (quick) {
    count = 20;
  }
  auto dialect = pe::Dialect::load(dialect_path);
  if (!dialect) {
    std::fprintf(stderr, "%s\n", dialect.error().message.c_str());
    return 2;
  }
  std::vector<Row> rows;
  for (const Case& c :
       {Case{"9600 baud, paced", 9600, true}, Case{"19200 baud, paced", 19200, true},
        Case{"sim, no pacing", 9600, false}}) {
    std::fprintf(stderr, "measuring %s ...\n", c.name.c_str());
    for (auto& r : measure_controller(*dialect, c, count)) {
      rows.push_back(r);
    }
  }
  std::fprintf(stderr, "measuring the raw pty ...\n");
  rows.push_back(measure_raw_pty(count));

  fmt::print(
      "Excalibur link round trip, command handed to the port -> reply parsed, ms "
      "(dialect '{}', {} exchanges per row)\n\n",
      dialect->name(), count);
  fmt::print(
      "| link | exchange | chars out/in | wire time | p50 | p90 | p99 | mean | min | "
      "exchanges/s |\n|---|---|---|---|---|---|---|---|---|---|\n");
  for (const Row& r : rows) {
    fmt::print("| {} | {} | {}/{} | {} | {:.3f} | {:.3f} | {:.3f} | {:.3f} | {:.3f} | {:.1f} |\n",
               r.name, r.command, r.chars_out, r.chars_in,
               r.wire_ms > 0 ? fmt::format("{:.1f}", r.wire_ms) : std::string("-"), r.rtt.p50_ms,
               r.rtt.p90_ms, r.rtt.p99_ms, r.rtt.mean_ms, r.rtt.min_ms, r.exchanges_per_s);
  }
  // One joint-following step = a move and a query (the driver streams a via point and reads the
  // angles back); the thesis's figures: 15 fps animation, 10 Hz teach sampling.
  const auto step_hz = [&](const std::string& name) {
    double ms = 0;
    for (const Row& r : rows) {
      if (r.name == name) {
        ms += r.rtt.p50_ms + dialect->timing().command_delay_s * 1e3;
      }
    }
    return 1e3 / ms;
  };
  fmt::print(
      "\nCompared with the thesis (digest 001 §1.1, §1.4): 15 fps animation, 10 Hz teach "
      "sampling, \"the serial link is the bottleneck\":\n");
  for (const char* name : {"9600 baud, paced", "19200 baud, paced"}) {
    double query_ms = 0;
    for (const Row& r : rows) {
      if (r.name == name && r.command.rfind("query", 0) == 0) {
        query_ms = r.rtt.p50_ms + dialect->timing().command_delay_s * 1e3;
      }
    }
    const double steps = step_hz(name);
    fmt::print(
        "  {}: {:.1f} angle readings/s ({:.1f} ms each, vs 15 fps and 10 Hz); {:.1f} "
        "move + read-back steps/s (streaming with the position read back){}\n",
        name, 1e3 / query_ms, query_ms, steps,
        steps < 10.0 ? ": below 10 Hz, so the link, not the host, limits on-line following" : "");
  }
  return 0;
}

// Nothing escapes main: an exception is printed and fails the run.
int main(int argc, char** argv) {
  try {
    return main_body(argc, argv);
  } catch (const std::exception& e) {
    std::fprintf(stderr, "excalibur_bench: %s\n", e.what());
  } catch (...) {
    std::fprintf(stderr, "excalibur_bench: an exception not derived from std::exception\n");
  }
  return 1;
}
