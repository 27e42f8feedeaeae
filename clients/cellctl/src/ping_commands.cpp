// `cellctl ping`: who is on the bus, from the heartbeats (topic cell/health/heartbeat), and
// with --rtt how fast each answers a PingRequest (cell/health/ping -> cell/health/pong).
#include <cstdlib>
#include <map>
#include <memory>
#include <set>

#include <fmt/format.h>
#include <nlohmann/json.hpp>

#include "cell/service/directory.hpp"
#include "cell/common/time.hpp"
#include "commands.hpp"
#include "table.hpp"

namespace cell::cellctl {
namespace {

using nlohmann::json;

int ping(Session& session, bool with_rtt) {
  service::ServiceDirectory directory(session.participant(), "cellctl");
  auto services = directory.wait_settled(session.timeout());
  if (!services) {
    return session.fail(services.error().message);
  }
  if (services->empty()) {
    const std::string uri = std::getenv("CYCLONEDDS_URI") != nullptr ? std::getenv("CYCLONEDDS_URI")
                                                                     : "<unset: Cyclone defaults>";
    const std::string message = fmt::format(
        "no service found on {} within {:.1f} s (is `cell up` running on this bus? "
        "CYCLONEDDS_URI={})",
        session.describe_bus(), static_cast<double>(session.timeout().count()) / 1e3, uri);
    if (session.json()) {
      session.out() << json{{"services", json::array()},
                            {"domain", session.domain_id()},
                            {"partition", session.partition()},
                            {"error", message}}
                           .dump(2)
                    << "\n";
    }
    return session.fail(message);
  }

  std::map<std::string, double> rtt_ms;
  std::set<std::string> silent;
  if (with_rtt) {
    std::set<std::string> alive;
    for (const auto& s : *services) {
      if (!s.lost) {
        alive.insert(s.service_id);
      }
    }
    // Two rounds: the first request after discovery pays Cyclone's first-contact delay
    // (about 10 ms on loopback), the second shows the steady round trip.
    for (int round = 0; round < 2 && !alive.empty(); ++round) {
      auto replies = directory.ping(session.timeout(), alive);
      if (!replies) {
        return session.fail(replies.error().message);
      }
      for (const auto& r : *replies) {
        rtt_ms[r.service_id] = r.rtt_ms;
      }
      if (replies->size() < alive.size()) {
        break;  // someone is silent: do not wait a second timeout for them
      }
    }
    for (const auto& id : alive) {
      if (rtt_ms.count(id) == 0) {
        silent.insert(id);
      }
    }
  }

  if (session.json()) {
    json rows = json::array();
    for (const auto& s : *services) {
      json row{{"id", s.service_id},
               {"kind", s.kind},
               {"host", s.host},
               {"pid", s.pid},
               {"state", std::string(s.status())},
               {"detail", s.detail},
               {"uptime_s", s.uptime_s},
               {"version", s.version},
               {"last_heartbeat_ns", s.last_heartbeat_ns},
               {"lost", s.lost}};
      if (with_rtt) {
        const auto it = rtt_ms.find(s.service_id);
        row["rtt_ms"] = it != rtt_ms.end() ? json(it->second) : json(nullptr);
      }
      rows.push_back(std::move(row));
    }
    session.out() << json{{"services", rows},
                          {"domain", session.domain_id()},
                          {"partition", session.partition()}}
                         .dump(2)
                  << "\n";
  } else {
    Table table({"SERVICE", "KIND", "HOST", "PID", "STATE", "UPTIME"});
    if (with_rtt) {
      table.add_column("RTT");
    }
    table.add_column("DETAIL");
    for (const auto& s : *services) {
      std::vector<std::string> row{s.service_id,
                                   s.kind,
                                   s.host,
                                   std::to_string(s.pid),
                                   std::string(s.status()),
                                   format_duration(s.uptime_s)};
      if (with_rtt) {
        const auto it = rtt_ms.find(s.service_id);
        row.push_back(it != rtt_ms.end() ? fmt::format("{:.2f} ms", it->second) : "-");
      }
      row.push_back(s.detail);
      table.add_row(std::move(row));
    }
    session.out() << fmt::format("{} service(s) on {}\n", services->size(), session.describe_bus());
    table.print(session.out());
  }
  if (!silent.empty()) {
    std::string names;
    for (const auto& id : silent) {
      names += (names.empty() ? "" : ", ") + id;
    }
    return session.fail(fmt::format("no ping reply within {:.1f} s from: {}",
                                    static_cast<double>(session.timeout().count()) / 1e3, names));
  }
  return kExitOk;
}

}  // namespace

void add_ping_commands(CLI::App& app, Commands& commands) {
  auto with_rtt = std::make_shared<bool>(false);
  CLI::App* sub = app.add_subcommand(
      "ping", "list every live service from its heartbeat (exit 1 when none is found)");
  sub->add_flag("--rtt", *with_rtt, "also ping each service and show the round trip");
  commands.add(sub, [with_rtt](Session& session) { return ping(session, *with_rtt); });
}

}  // namespace cell::cellctl
