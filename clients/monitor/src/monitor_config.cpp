#include "monitor_config.hpp"

#include <array>
#include <filesystem>
#include <fstream>
#include <set>
#include <sstream>

#include <fmt/format.h>

#include "cell/geometry/angles.hpp"
#include "cell/geometry/pose.hpp"
#include "cell/service/paths.hpp"

namespace cell::monitor {
namespace {

const std::set<std::string> kJobKinds = {"table_pick_place", "conveyor_pick", "assembly",
                                         "task_file"};

/// Reads a job file into the template: its text, and kind/robot/camera/belt where the template
/// does not say. Errors: kConfig (unreadable, not YAML, not a map) naming the file.
Status read_spec_file(JobTemplate& jt, const std::string& path) {
  std::ifstream in(path);
  if (!in) {
    return Error{Errc::kConfig, fmt::format("cannot read job file '{}'", path)};
  }
  std::stringstream text;
  text << in.rdbuf();
  jt.spec_yaml = text.str();
  auto doc = config::load_string(jt.spec_yaml, path);
  if (!doc) {
    return std::move(doc).error();
  }
  if (!doc->root.IsMap()) {
    return Error{Errc::kConfig, fmt::format("job file '{}' is not a YAML map", path)};
  }
  auto fill = [&](const char* key, std::string& out) {
    const YAML::Node node = doc->root[key];
    if (out.empty() && node.IsDefined() && node.IsScalar()) {
      out = node.as<std::string>();
    }
  };
  fill("kind", jt.kind);
  fill("robot", jt.robot_id);
  fill("camera", jt.camera_id);
  fill("belt", jt.belt_id);
  return ok_status();
}

}  // namespace

std::string default_web_root() {
  std::error_code ec;
  const auto exe = std::filesystem::read_symlink("/proc/self/exe", ec);
  if (ec) {
    return {};
  }
  return (exe.parent_path().parent_path() / "share" / "cell-monitor" / "web").string();
}

Status MonitorConfig::validate() const {
  if (port < 0 || port > 65535) {
    return Error{Errc::kConfig, fmt::format("http.port must be 0..65535, got {}", port)};
  }
  if (max_stream_clients < 1) {
    return Error{Errc::kConfig, "http.max_stream_clients must be >= 1"};
  }
  if (client_queue < 16) {
    return Error{Errc::kConfig, fmt::format("http.client_queue must be >= 16, got {}",
                                            client_queue)};
  }
  for (const auto& [key, hz] : std::array<std::pair<const char*, double>, 3>{
           {{"stream.robot_hz", stream_hz}, {"stream.world_hz", world_hz},
            {"stream.image_hz", image_hz}}}) {
    if (!(hz > 0.0 && hz <= 1000.0)) {
      return Error{Errc::kConfig, fmt::format("{} must be in (0, 1000] Hz, got {}", key, hz)};
    }
  }
  if (!(session_ttl_s > 0.0)) {
    return Error{Errc::kConfig, "auth.session_ttl_s must be > 0"};
  }
  return ok_status();
}

Result<MonitorConfig> load_config(const config::Document& doc) {
  MonitorConfig c;
  config::MapReader root(doc, doc.root, "");
  service::read_common(root, c.common);

  config::MapReader http = root.child("http", false);
  http.optional("bind", c.bind_address);
  http.optional("port", c.port);
  http.optional("web_root", c.web_root);
  http.optional("max_stream_clients", c.max_stream_clients);
  int queue = static_cast<int>(c.client_queue);
  http.optional("client_queue", queue);
  if (queue < 16) {
    http.fail("client_queue", fmt::format("must be >= 16, got {}", queue));
  } else {
    c.client_queue = static_cast<std::size_t>(queue);
  }
  if (c.port < 0 || c.port > 65535) {
    http.fail("port", fmt::format("must be 0..65535, got {}", c.port));
  }
  if (c.max_stream_clients < 1) {
    http.fail("max_stream_clients", "must be >= 1");
  }
  c.web_root = c.web_root.empty() ? default_web_root() : service::resolve_path(c.web_root);
  root.absorb(http);

  config::MapReader stream = root.child("stream", false);
  stream.optional("robot_hz", c.stream_hz);
  stream.optional("world_hz", c.world_hz);
  stream.optional("image_hz", c.image_hz);
  for (const auto& [key, hz] : std::array<std::pair<const char*, double>, 3>{
           {{"robot_hz", c.stream_hz}, {"world_hz", c.world_hz}, {"image_hz", c.image_hz}}}) {
    if (!(hz > 0.0 && hz <= 1000.0)) {
      stream.fail(key, fmt::format("must be in (0, 1000] Hz, got {}", hz));
    }
  }
  root.absorb(stream);

  config::MapReader auth = root.child("auth", false);
  auth.optional("session_ttl_s", c.session_ttl_s);
  auth.optional("secure_cookie", c.secure_cookie);
  auth.optional("viewers_must_sign_in", c.viewers_must_sign_in);
  if (!(c.session_ttl_s > 0.0)) {
    auth.fail("session_ttl_s", fmt::format("must be > 0, got {}", c.session_ttl_s));
  }
  const auto users = auth.sequence("users", false);
  std::set<std::string> names;
  for (std::size_t i = 0; i < users.size(); ++i) {
    config::MapReader u = auth.element(users[i], fmt::format("users[{}]", i));
    UserEntry user;
    u.required("name", user.name);
    u.optional("role", user.role);
    u.required("password_hash", user.password_hash);
    if (user.role != "operator" && user.role != "viewer") {
      u.fail("role", fmt::format("must be operator or viewer, got '{}'", user.role));
    }
    if (!user.password_hash.empty() && user.password_hash.rfind("pbkdf2-sha256$", 0) != 0) {
      u.fail("password_hash",
             "must be a 'pbkdf2-sha256$...' hash made by `cell-monitor --hash-password`");
    }
    if (!user.name.empty() && !names.insert(user.name).second) {
      u.fail("name", fmt::format("user '{}' is listed twice", user.name));
    }
    c.users.push_back(std::move(user));
    auth.absorb(u);
  }
  root.absorb(auth);

  const auto robots = root.sequence("robots");
  std::set<std::string> robot_ids;
  for (std::size_t i = 0; i < robots.size(); ++i) {
    config::MapReader r = root.element(robots[i], fmt::format("robots[{}]", i));
    RobotEntry entry;
    std::array<double, 3> xyz{};
    std::array<double, 3> rpy_deg{};
    r.required("id", entry.id);
    r.optional("config", entry.config);
    r.required("xyz_mm", xyz);
    r.optional("rpy_deg", rpy_deg);
    if (entry.config.empty()) {
      entry.config = "config/robots/" + entry.id + ".yaml";
    }
    entry.config = service::resolve_path(entry.config);
    entry.world_T_base = geometry::make_pose(
        Eigen::Vector3d(xyz[0], xyz[1], xyz[2]),
        {geometry::deg_to_rad(rpy_deg[0]), geometry::deg_to_rad(rpy_deg[1]),
         geometry::deg_to_rad(rpy_deg[2])});
    if (!entry.id.empty() && !robot_ids.insert(entry.id).second) {
      r.fail("id", fmt::format("robot '{}' is listed twice", entry.id));
    }
    c.robots.push_back(std::move(entry));
    root.absorb(r);
  }

  std::vector<std::string> cameras;
  root.optional("cameras", cameras);
  for (auto& path : cameras) {
    c.cameras.push_back(service::resolve_path(path));
  }

  const auto templates = root.sequence("job_templates", false);
  for (std::size_t i = 0; i < templates.size(); ++i) {
    config::MapReader t = root.element(templates[i], fmt::format("job_templates[{}]", i));
    JobTemplate jt;
    t.required("name", jt.name);
    t.optional("description", jt.description);
    t.optional("kind", jt.kind);
    t.optional("robot", jt.robot_id);
    t.optional("camera", jt.camera_id);
    t.optional("belt", jt.belt_id);
    t.optional("spec_yaml", jt.spec_yaml);
    t.optional("spec_file", jt.spec_file);
    t.optional("program_name", jt.program_name);
    if (!jt.spec_file.empty() && !jt.spec_yaml.empty()) {
      t.fail("spec_file", "give spec_yaml or spec_file, not both");
    } else if (!jt.spec_file.empty()) {
      if (auto s = read_spec_file(jt, service::resolve_path(jt.spec_file)); !s) {
        t.fail("spec_file", s.error().message);
      }
    }
    if (jt.kind.empty()) {
      t.fail("kind", "missing: neither the template nor its spec file says the job's kind");
    } else if (kJobKinds.count(jt.kind) == 0) {
      t.fail("kind", fmt::format("must be one of table_pick_place, conveyor_pick, assembly, "
                                 "task_file; got '{}'",
                                 jt.kind));
    }
    for (const auto& other : c.job_templates) {
      if (!jt.name.empty() && other.name == jt.name) {
        t.fail("name", fmt::format("template '{}' is listed twice", jt.name));
      }
    }
    c.job_templates.push_back(std::move(jt));
    root.absorb(t);
  }

  root.optional("vision_config", c.vision_config);
  c.vision_config = service::resolve_path(c.vision_config);

  config::MapReader table = root.child("table", false);
  table.optional("x_mm", c.table.x_mm);
  table.optional("y_mm", c.table.y_mm);
  table.optional("height_mm", c.table.height_mm);
  if (!(c.table.x_mm[0] < c.table.x_mm[1]) || !(c.table.y_mm[0] < c.table.y_mm[1])) {
    table.fail("", "x_mm and y_mm must each be [low, high] with low < high");
  }
  root.absorb(table);

  config::MapReader teach = root.child("teach", false);
  teach.optional("tasks_dir", c.tasks_dir);
  c.tasks_dir = service::resolve_path(c.tasks_dir);
  root.absorb(teach);
  config::MapReader go = root.child("goto_part", false);
  go.optional("approach_mm", c.approach_mm);
  go.optional("grasp_height_mm", c.grasp_height_mm);
  if (!(c.grasp_height_mm >= -100.0 && c.grasp_height_mm <= 500.0)) {
    go.fail("grasp_height_mm",
            fmt::format("must be in [-100, 500] mm, got {}", c.grasp_height_mm));
  }
  if (!(c.approach_mm >= 0.0 && c.approach_mm <= 500.0)) {
    go.fail("approach_mm", fmt::format("must be in [0, 500] mm, got {}", c.approach_mm));
  }
  root.absorb(go);
  CELL_TRY(root.finish());
  return c;
}

}  // namespace cell::monitor
