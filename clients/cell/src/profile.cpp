#include "profile.hpp"

#include <arpa/inet.h>
#include <unistd.h>

#include <cctype>

#include <cstdlib>
#include <filesystem>
#include <map>

#include <fmt/format.h>

#include "cell/config/yaml.hpp"
#include "cell/service/paths.hpp"

namespace cell::launcher {
namespace {

namespace fs = std::filesystem;

constexpr std::uint32_t kMaxDomainId = 230;  // Cyclone's port mapping limit for domain ids
constexpr std::size_t kMaxNameLength = 64;

bool valid_service_name(const std::string& name) {
  if (name.empty() || name.size() > kMaxNameLength) {
    return false;
  }
  const auto ok = [](char c, bool first) {
    const bool alnum = (c >= 'a' && c <= 'z') || (c >= 'A' && c <= 'Z') || (c >= '0' && c <= '9');
    return alnum || (!first && (c == '_' || c == '-' || c == '.'));
  };
  for (std::size_t i = 0; i < name.size(); ++i) {
    if (!ok(name[i], i == 0)) {
      return false;
    }
  }
  return true;
}

bool valid_env_name(const std::string& name) {
  if (name.empty() || (name[0] >= '0' && name[0] <= '9')) {
    return false;
  }
  for (const char c : name) {
    const bool ok =
        (c >= 'a' && c <= 'z') || (c >= 'A' && c <= 'Z') || (c >= '0' && c <= '9') || c == '_';
    if (!ok) {
      return false;
    }
  }
  return true;
}

void read_env(config::MapReader& service, ServiceSpec& spec) {
  config::MapReader env = service.child("env", false);
  for (const auto& entry : env.node()) {
    const std::string key = entry.first.as<std::string>("");
    std::string value;
    env.required(key, value);
    if (!valid_env_name(key)) {
      env.fail(key, "not a valid environment variable name (letters, digits, '_')");
      continue;
    }
    spec.env.emplace_back(key, value);
  }
  service.absorb(env);
}

void read_services(config::MapReader& root, Profile& profile) {
  const bool present = root.has("services");
  const std::vector<YAML::Node> nodes = root.sequence("services", true);
  if (present && nodes.empty() && root.node()["services"].IsSequence()) {
    root.fail("services", "must list at least one service");
  }
  std::map<std::string, std::string> first_seen;  // name -> where
  for (std::size_t i = 0; i < nodes.size(); ++i) {
    config::MapReader s = root.element(nodes[i], fmt::format("services[{}]", i));
    ServiceSpec spec;
    spec.where = config::location(s.path(), nodes[i]);
    s.required("name", spec.name);
    s.required("exec", spec.exec);
    s.optional("config", spec.config);
    s.optional("args", spec.args);
    s.optional("host", spec.host);
    read_env(s, spec);
    config::MapReader limits = s.child("limits", false);
    limits.optional("memory_mib", spec.memory_max_mib);
    limits.optional("cpu_percent", spec.cpu_quota_percent);
    if (spec.memory_max_mib < 0 || spec.cpu_quota_percent < 0) {
      limits.fail(spec.memory_max_mib < 0 ? "memory_mib" : "cpu_percent", "must be >= 0");
    }
    s.absorb(limits);
    if (s.has("name") && !valid_service_name(spec.name)) {
      s.fail("name", fmt::format("'{}' is not a valid service name (1..{} letters, digits, "
                                 "'_', '-', '.', starting with a letter or digit)",
                                 spec.name, kMaxNameLength));
    } else if (!spec.name.empty()) {
      const auto [it, inserted] = first_seen.emplace(spec.name, spec.where);
      if (!inserted) {
        s.fail("name",
               fmt::format("duplicate service name '{}' (first at {})", spec.name, it->second));
      }
    }
    if (s.has("exec") && spec.exec.empty()) {
      s.fail("exec", "must not be empty");
    }
    if (s.has("host") && spec.host.empty()) {
      s.fail("host", "must not be empty (use 'local')");
    } else if (!profile.hosts.empty() && profile.host(spec.host) == nullptr) {
      std::string names;
      for (const auto& h : profile.hosts) {
        names += (names.empty() ? "" : ", ") + h.name;
      }
      s.fail(s.has("host") ? "host" : "name",
             fmt::format("service '{}' must run on one of the profile's hosts ({}), not '{}'",
                         spec.name, names, spec.host));
    }
    root.absorb(s);
    profile.services.push_back(std::move(spec));
  }
}

bool valid_ipv4(const std::string& text) {
  in_addr addr{};
  return inet_pton(AF_INET, text.c_str(), &addr) == 1;
}

void read_hosts(config::MapReader& root, Profile& profile) {
  config::MapReader hosts = root.child("hosts", false);
  for (const auto& entry : hosts.node()) {
    const std::string key = entry.first.as<std::string>("");
    config::MapReader h = hosts.child(key, true);
    HostSpec spec;
    spec.name = key;
    spec.where = config::location(h.path(), entry.second);
    h.required("address", spec.address);
    h.optional("interface", spec.interface);
    if (!valid_service_name(key)) {
      hosts.fail(key, "not a valid host name (letters, digits, '_', '-', '.')");
    }
    if (h.has("address") && !valid_ipv4(spec.address)) {
      h.fail("address", fmt::format("'{}' is not an IPv4 address", spec.address));
    }
    hosts.absorb(h);
    profile.hosts.push_back(std::move(spec));
  }
  root.absorb(hosts);
}

std::string host_variable(const std::string& host) {
  std::string name = "CELL_HOST_";
  for (const char c : host) {
    name += (c == '-' || c == '.') ? '_' : static_cast<char>(std::toupper(static_cast<unsigned char>(c)));
  }
  return name + "_ADDRESS";
}

}  // namespace

const HostSpec* Profile::host(const std::string& host_name) const {
  for (const auto& h : hosts) {
    if (h.name == host_name) {
      return &h;
    }
  }
  return nullptr;
}

std::string default_profile_path() { return service::resolve_path("deploy/local.yaml"); }

std::string home_path(const std::string& path) {
  if (path.empty() || fs::path(path).is_absolute()) {
    return path;
  }
  return (fs::path(home_dir()) / path).lexically_normal().string();
}

std::string home_dir() {
  std::error_code ec;
  const fs::path home = fs::absolute(service::cell_home(), ec);
  return ec ? service::cell_home() : home.lexically_normal().string();
}

std::string run_dir_of(const Profile& profile) { return home_path(profile.run_dir); }

std::string this_host() {
  char host[256] = {};
  gethostname(host, sizeof host - 1);
  return host;
}

Result<std::string> select_host(const Profile& profile, const std::string& requested) {
  std::string names;
  for (const auto& h : profile.hosts) {
    names += (names.empty() ? "" : ", ") + h.name;
  }
  if (!requested.empty()) {
    if (profile.host(requested) != nullptr) {
      return requested;
    }
    return Error{Errc::kConfig,
                 profile.hosts.empty()
                     ? fmt::format("{}: --host {}: this profile has no `hosts:` section (every "
                                   "service runs on one machine)",
                                   profile.path, requested)
                     : fmt::format("{}: --host {}: no such host in the profile (it has: {})",
                                   profile.path, requested, names)};
  }
  if (profile.hosts.empty()) {
    return std::string();
  }
  if (profile.host(this_host()) != nullptr) {
    return this_host();
  }
  return Error{Errc::kConfig,
               fmt::format("{}: this profile spreads the cell over hosts ({}); say which one this "
                           "machine ('{}') is with --host NAME",
                           profile.path, names, this_host())};
}

bool runs_on(const ServiceSpec& spec, const std::string& host) {
  return host.empty() ? is_local_host(spec.host) : spec.host == host;
}

bool is_local_host(const std::string& host) {
  return host == "local" || host == "localhost" || host == this_host();
}

Result<Profile> load_profile(const std::string& path) {
  auto doc = config::load_file(path);
  if (!doc) {
    return std::move(doc).error();
  }
  Profile profile;
  std::error_code ec;
  profile.path = fs::absolute(path, ec).lexically_normal().string();
  if (ec) {
    profile.path = path;
  }
  profile.name = fs::path(path).stem().string();

  config::MapReader root(*doc, doc->root, "");
  root.optional("profile", profile.name);
  config::MapReader bus = root.child("bus", false);
  bus.optional("domain_id", profile.bus.domain_id);
  bus.optional("partition", profile.bus.partition);
  bus.optional("cyclonedds_config", profile.bus.cyclonedds_config);
  bus.optional("multicast", profile.bus.multicast);
  bus.optional("receive_buffer_mib", profile.bus.receive_buffer_mib);
  bus.optional("images_across_hosts", profile.bus.images_across_hosts);
  if (!(profile.bus.receive_buffer_mib >= 0.0625 && profile.bus.receive_buffer_mib <= 1024.0)) {
    bus.fail("receive_buffer_mib",
             fmt::format("must be in [0.0625, 1024], got {}", profile.bus.receive_buffer_mib));
  }
  if (profile.bus.domain_id > kMaxDomainId) {
    bus.fail("domain_id",
             fmt::format("must be 0..{}, got {}", kMaxDomainId, profile.bus.domain_id));
  }
  if (bus.has("partition") && profile.bus.partition.empty()) {
    bus.fail("partition", "must not be empty");
  }
  if (bus.has("cyclonedds_config") && profile.bus.cyclonedds_config.empty()) {
    bus.fail("cyclonedds_config", "must not be empty");
  }
  root.absorb(bus);

  root.optional("run_dir", profile.run_dir);
  if (root.has("run_dir") && profile.run_dir.empty()) {
    root.fail("run_dir", "must not be empty");
  }

  config::MapReader restart = root.child("restart", false);
  restart.optional("backoff_initial_s", profile.restart.backoff_initial_s);
  restart.optional("backoff_max_s", profile.restart.backoff_max_s);
  restart.optional("stable_after_s", profile.restart.stable_after_s);
  if (!(profile.restart.backoff_initial_s > 0.0)) {
    restart.fail("backoff_initial_s",
                 fmt::format("must be > 0, got {}", profile.restart.backoff_initial_s));
  }
  if (!(profile.restart.backoff_max_s >= profile.restart.backoff_initial_s)) {
    restart.fail("backoff_max_s",
                 fmt::format("must be >= backoff_initial_s ({}), got {}",
                             profile.restart.backoff_initial_s, profile.restart.backoff_max_s));
  }
  if (!(profile.restart.stable_after_s >= 0.0)) {
    restart.fail("stable_after_s",
                 fmt::format("must be >= 0, got {}", profile.restart.stable_after_s));
  }
  root.absorb(restart);

  root.optional("stop_grace_s", profile.stop_grace_s);
  if (!(profile.stop_grace_s > 0.0 && profile.stop_grace_s <= 600.0)) {
    root.fail("stop_grace_s", fmt::format("must be in (0, 600], got {}", profile.stop_grace_s));
  }

  read_hosts(root, profile);
  config::MapReader security = root.child("security", false);
  security.optional("enabled", profile.security.enabled);
  security.optional("dir", profile.security.dir);
  if (security.has("dir") && profile.security.dir.empty()) {
    security.fail("dir", "must not be empty");
  }
  root.absorb(security);

  read_services(root, profile);
  CELL_TRY(root.finish());
  return profile;
}

Status apply_environment(Profile& profile) {
  if (const char* domain = std::getenv("CELL_DOMAIN_ID"); domain != nullptr && *domain != '\0') {
    char* end = nullptr;
    const unsigned long value = std::strtoul(domain, &end, 10);
    if (*end != '\0' || value > kMaxDomainId) {
      return Error{Errc::kConfig, fmt::format("environment CELL_DOMAIN_ID must be 0..{}, got '{}'",
                                              kMaxDomainId, domain)};
    }
    profile.bus.domain_id = static_cast<std::uint32_t>(value);
  }
  if (const char* partition = std::getenv("CELL_PARTITION");
      partition != nullptr && *partition != '\0') {
    profile.bus.partition = partition;
  }
  for (auto& host : profile.hosts) {
    const std::string variable = host_variable(host.name);
    if (const char* address = std::getenv(variable.c_str()); address != nullptr && *address != '\0') {
      if (!valid_ipv4(address)) {
        return Error{Errc::kConfig, fmt::format("environment {} must be an IPv4 address, got '{}'",
                                                variable, address)};
      }
      host.address = address;
    }
  }
  return ok_status();
}

}  // namespace cell::launcher
