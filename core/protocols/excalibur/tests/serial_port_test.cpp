#include "cell/protocols/excalibur/serial_port.hpp"

#include <gmock/gmock.h>
#include <gtest/gtest.h>
#include <poll.h>
#include <unistd.h>

#include <chrono>
#include <thread>
#include <vector>

#include "cell/protocols/excalibur/pty.hpp"
#include "cell/testing/matchers.hpp"

namespace cell::protocols::excalibur {
namespace {

using namespace std::chrono_literals;
using ::cell::testing::IsErr;
using ::cell::testing::IsErrWith;
using ::cell::testing::IsOk;
using Clock = std::chrono::steady_clock;

bool starts_with_bang(std::string_view line) { return !line.empty() && line[0] == '!'; }

/// The far end of the line: the pty's master side.
struct Peer {
  PseudoTerminal pty = *PseudoTerminal::create();

  void send(std::string_view bytes) const {
    ASSERT_EQ(::write(pty.master_fd(), bytes.data(), bytes.size()),
              static_cast<ssize_t>(bytes.size()));
  }
  /// Reads `n` bytes, with the arrival time of each (polls; generous 5 s deadline).
  std::vector<std::pair<char, Clock::time_point>> receive(std::size_t n) const {
    std::vector<std::pair<char, Clock::time_point>> out;
    const auto deadline = Clock::now() + 5s;
    while (out.size() < n && Clock::now() < deadline) {
      pollfd p{pty.master_fd(), POLLIN, 0};
      if (::poll(&p, 1, 50) <= 0) {
        continue;
      }
      char c = 0;
      while (out.size() < n && ::read(pty.master_fd(), &c, 1) == 1) {
        out.emplace_back(c, Clock::now());
      }
    }
    return out;
  }
};

std::unique_ptr<SerialPort> open_port(const Peer& peer, SerialOptions options = {}) {
  options.device = peer.pty.slave_path();
  auto port = SerialPort::open(options, &starts_with_bang);
  EXPECT_THAT(port, IsOk());
  return std::move(*port);
}

TEST(SerialPort, SplitsLinesOnAnyEndCharacterAndIgnoresEmptyOnes) {
  Peer peer;
  auto port = open_port(peer);
  peer.send("OK\r\nJA 1\rER 2\n\r\n");
  for (const char* expected : {"OK", "JA 1", "ER 2"}) {
    auto line = port->wait_reply(2s);
    ASSERT_THAT(line, IsOk());
    EXPECT_EQ(line->text, expected);
  }
  EXPECT_THAT(port->wait_reply(50ms), IsErr(Errc::kTimeout));
}

TEST(SerialPort, RoutesUnsolicitedMessagesArrivingInTheMiddleOfAnExchange) {
  Peer peer;
  auto port = open_port(peer);
  ASSERT_THAT(port->write_line("QJ\r"), IsOk());
  // The controller interjects "move not achieved" before (and a line error after) its reply.
  peer.send("!NA 1\r\nJA 1.00 2.00\r\n!LE 1\r\n");
  auto reply = port->wait_reply(2s);
  ASSERT_THAT(reply, IsOk());
  EXPECT_EQ(reply->text, "JA 1.00 2.00");
  ASSERT_TRUE(port->wait_unsolicited(2s));
  ReceivedLine u;
  ASSERT_TRUE(port->pop_unsolicited(u));
  EXPECT_EQ(u.text, "!NA 1");
  ASSERT_TRUE(port->wait_unsolicited(2s));
  ASSERT_TRUE(port->pop_unsolicited(u));
  EXPECT_EQ(u.text, "!LE 1");
  EXPECT_FALSE(port->pop_unsolicited(u));
  const SerialStats stats = port->stats();
  EXPECT_EQ(stats.replies_in, 1U);
  EXPECT_EQ(stats.unsolicited_in, 2U);
}

TEST(SerialPort, PacesEveryCharacterAtTheEmulatedByteTimePlusTheDelay) {
  Peer peer;
  SerialOptions options;
  options.baud = 9600;
  options.emulate_baud = true;
  options.char_delay_s = 0.001;
  auto port = open_port(peer, options);
  EXPECT_NEAR(port->char_period_s(), 10.0 / 9600 + 0.001, 1e-12);
  const std::string line = "MJ 10.00 0.00 0.00 5.00 5.00 5.00\r";
  std::vector<std::pair<char, Clock::time_point>> bytes;
  std::thread reader([&] { bytes = peer.receive(line.size()); });
  const auto start = Clock::now();
  ASSERT_THAT(port->write_line(line), IsOk());
  const double took_s = std::chrono::duration<double>(Clock::now() - start).count();
  reader.join();
  ASSERT_EQ(bytes.size(), line.size());
  // Sleeping never ends early: the n characters take at least n - 1 periods (a lower bound
  // only: it catches a pacing that does nothing).
  EXPECT_GE(took_s, static_cast<double>(line.size() - 1) * port->char_period_s());
  const double span_s =
      std::chrono::duration<double>(bytes.back().second - bytes.front().second).count();
  EXPECT_GT(span_s, 0.5 * static_cast<double>(line.size() - 1) * port->char_period_s());
}

TEST(SerialPort, KeepsTheCommandDelayAfterTheLastReply) {
  Peer peer;
  SerialOptions options;
  options.command_delay_s = 0.05;
  auto port = open_port(peer, options);
  peer.send("OK\r\n");
  auto reply = port->wait_reply(2s);
  ASSERT_THAT(reply, IsOk());
  ASSERT_THAT(port->write_line("QJ\r"), IsOk());
  const auto written = Clock::now();
  EXPECT_GE(std::chrono::duration<double>(written - reply->received).count(), 0.05);
}

TEST(SerialPort, WritesRawWithoutPacing) {
  Peer peer;
  SerialOptions options;
  options.emulate_baud = true;
  options.baud = 1200;  // 8.3 ms per character when paced
  auto port = open_port(peer, options);
  const auto start = Clock::now();
  ASSERT_THAT(port->write_raw("0123456789\r"), IsOk());
  EXPECT_LT(std::chrono::duration<double>(Clock::now() - start).count(), 11 * 10.0 / 1200);
  EXPECT_EQ(peer.receive(11).size(), 11U);
}

TEST(SerialPort, FlagsOverlongLinesAsGarbage) {
  Peer peer;
  SerialOptions options;
  options.max_line_chars = 8;
  auto port = open_port(peer, options);
  peer.send("0123456789ABCDEF\r\nOK\r\n");
  auto line = port->wait_reply(2s);
  ASSERT_THAT(line, IsOk());
  EXPECT_TRUE(line->overlong);
  EXPECT_EQ(line->text, "01234567");
  line = port->wait_reply(2s);
  ASSERT_THAT(line, IsOk());
  EXPECT_FALSE(line->overlong);
  EXPECT_EQ(line->text, "OK");
}

TEST(SerialPort, DiscardsStaleRepliesBeforeAnExchange) {
  Peer peer;
  auto port = open_port(peer);
  peer.send("OK\r\nOK\r\n");
  ASSERT_THAT(port->wait_reply(2s), IsOk());
  std::this_thread::sleep_for(50ms);
  EXPECT_EQ(port->discard_replies(), 1U);
  EXPECT_THAT(port->wait_reply(20ms), IsErr(Errc::kTimeout));
}

TEST(SerialPort, ReportsALostLinkAndReopens) {
  auto peer = std::make_unique<Peer>();
  auto port = open_port(*peer);
  // A port reset while the line is up: same device, exchanges go on.
  ASSERT_THAT(port->reopen(), IsOk());
  peer->send("OK\r\n");
  EXPECT_THAT(port->wait_reply(2s), IsOk());
  // The controller side disappears: waiters hear it at once.
  peer.reset();
  EXPECT_THAT(port->wait_reply(2s), IsErrWith(Errc::kIo, "link down"));
  EXPECT_FALSE(port->link_up());
  EXPECT_THAT(port->write_line("QJ\r"), IsErr(Errc::kIo));
  EXPECT_THAT(port->reopen(), IsErr(Errc::kIo));
  EXPECT_GE(port->stats().reopens, 2U);
}

TEST(SerialPort, OpenFailuresNameTheDevice) {
  SerialOptions options;
  options.device = "/nonexistent/ttyS9";
  EXPECT_THAT(SerialPort::open(options, nullptr),
              IsErrWith(Errc::kIo, "serial port /nonexistent/ttyS9: cannot open"));
  options.device = "/dev/null";
  EXPECT_THAT(SerialPort::open(options, nullptr), IsErrWith(Errc::kIo, "not a terminal"));
  options.baud = 9601;
  EXPECT_THAT(SerialPort::open(options, nullptr),
              IsErrWith(Errc::kInvalidArgument, "unsupported baud rate 9601"));
}

}  // namespace
}  // namespace cell::protocols::excalibur
