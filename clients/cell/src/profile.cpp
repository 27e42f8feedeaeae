#include "profile.hpp"

#include <unistd.h>

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
    }
    root.absorb(s);
    profile.services.push_back(std::move(spec));
  }
}

}  // namespace

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
  return ok_status();
}

}  // namespace cell::launcher
