#include "monitor_service.hpp"

#include <httplib.h>

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <stdexcept>
#include <utility>

#include <fmt/format.h>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>
#include <yaml-cpp/yaml.h>

#include "cell/bus/view.hpp"
#include "cell/common/log.hpp"
#include "cell/common/time.hpp"
#include "cell/common/version.hpp"
#include "cell/geometry/idl_pose.hpp"
#include "cell/kinematics/robot_config.hpp"

namespace cell::monitor {
namespace {

using nlohmann::json;
using Clock = std::chrono::steady_clock;
using namespace std::chrono_literals;

constexpr const char* kCookie = "cell_session";
constexpr std::size_t kEventLog = 200;
constexpr std::size_t kStickyJobs = 100;
constexpr auto kPreviewTimeout = 5s;
constexpr auto kMatchTimeout = 2s;
constexpr auto kJobReplyTimeout = 3s;
constexpr auto kHealthPeriod = 500ms;
constexpr std::int64_t kHealthRefreshNs = 5'000'000'000;  // uptimes, last heartbeats
constexpr auto kStreamKeepAlive = 10s;
// The demo users' hashes shipped in config/monitor.yaml (operator / cell-operator, viewer /
// cell-viewer): the bridge warns while they are in use.
constexpr std::string_view kShippedHashes[] = {
    "pbkdf2-sha256$200000$6JHwRVuIqEWsEJiy7bMgBw==$tpLODdn16LlWXbkfUsVjpQBkygDcWoXBnyeax8jKHKc=",
    "pbkdf2-sha256$200000$juTcdC5PtaG0hh/VS/k1/Q==$n6jV1va8P0nAE9v8on7DyjtLak0AybfPasMGQtjAjx0=",
};

enum Token : dds_attach_t {
  kStop = 1,
  kStates,
  kStatesLatest,
  kMotionStatus,
  kWorld,
  kImages,
  kDetections,
  kEdges,
  kCameraCal,
  kBeltCal,
  kJobStatus,
  kEvents,
};

int http_status(Errc code) {
  switch (code) {
    case Errc::kInvalidArgument:
    case Errc::kOutOfRange:
    case Errc::kConfig:
      return 400;
    case Errc::kNotReady:
      return 409;
    case Errc::kTimeout:
      return 504;
    case Errc::kBus:
    case Errc::kProtocol:
    case Errc::kIo:
      return 503;
  }
  return 500;
}

void reply_json(httplib::Response& res, int status, const json& body) {
  res.status = status;
  res.set_content(to_text(body), "application/json");
}

void reply_error(httplib::Response& res, const Error& error) {
  reply_json(res, http_status(error.code),
             {{"error", error.message}, {"code", std::string(to_string(error.code))}});
}

template <typename Duration>
std::chrono::milliseconds ms(Duration d) {
  return std::chrono::duration_cast<std::chrono::milliseconds>(d);
}

Clock::duration period_of(double hz) {
  return std::chrono::duration_cast<Clock::duration>(std::chrono::duration<double>(1.0 / hz));
}

/// The bridge's pose JSON ({"p": [3], "q": [4]}) back to a pose. Errors: kInvalidArgument.
Result<Eigen::Isometry3d> pose_from_json(const json& j) {
  const bool shaped = j.is_object() && j.contains("p") && j.contains("q") && j["p"].is_array() &&
                      j["q"].is_array() && j["p"].size() == 3 && j["q"].size() == 4;
  if (!shaped) {
    return Error{Errc::kInvalidArgument, "not a pose"};
  }
  cell_common_Pose p{};
  double* fields[7] = {&p.position_mm.x,  &p.position_mm.y,  &p.position_mm.z, &p.orientation.w,
                       &p.orientation.x,  &p.orientation.y,  &p.orientation.z};
  for (std::size_t i = 0; i < 7; ++i) {
    const json& v = i < 3 ? j["p"][i] : j["q"][i - 3];
    if (!v.is_number()) {
      return Error{Errc::kInvalidArgument, "not a pose"};
    }
    *fields[i] = v.get<double>();
  }
  return geometry::pose_from_idl(p);
}

kinematics::JointVector to_joint_vector(const std::vector<double>& v) {
  kinematics::JointVector q(static_cast<Eigen::Index>(v.size()));
  for (std::size_t i = 0; i < v.size(); ++i) {
    q[static_cast<Eigen::Index>(i)] = v[i];
  }
  return q;
}

json joints_array(const kinematics::JointVector& q) {
  json out = json::array();
  for (Eigen::Index i = 0; i < q.size(); ++i) {
    out.push_back(number(q[i]));
  }
  return out;
}

/// A boolean field that may be absent (then `fallback`). Errors: kInvalidArgument.
Result<bool> optional_bool(const json& body, const char* key, bool fallback) {
  if (!body.contains(key) || body[key].is_null()) {
    return fallback;
  }
  if (!body[key].is_boolean()) {
    return Error{Errc::kInvalidArgument, fmt::format("field '{}' must be true or false", key)};
  }
  return body[key].get<bool>();
}

/// The clear-grip models of the vision service's config (`locate.grasps`: class, finger sizes,
/// styles), as the page's fingerprint overlay wants them (angles in rad). The file belongs to
/// another service: anything unexpected in it means no fingerprints, never a failed start.
json read_grasp_models(const std::string& path) {
  json out = json::array();
  if (!std::filesystem::exists(path)) {
    return out;
  }
  try {
    const YAML::Node root = YAML::LoadFile(path);
    const YAML::Node grasps = root["locate"]["grasps"];
    if (!grasps.IsSequence()) {
      return out;
    }
    constexpr double kDeg = 3.14159265358979323846 / 180.0;
    for (const auto& g : grasps) {
      json styles = json::array();
      for (const auto& st : g["styles"]) {
        styles.push_back({{"name", st["name"].as<std::string>("")},
                          {"d_cg_mm", st["d_cg_mm"].as<double>(0.0)},
                          {"alpha_rad", st["alpha_deg"].as<double>(0.0) * kDeg},
                          {"rz_off_rad", st["rz_off_deg"].as<double>(0.0) * kDeg},
                          {"part_width_mm", st["part_width_mm"].as<double>(0.0)}});
      }
      out.push_back({{"class", g["class"].as<std::string>("")},
                     {"finger_width_mm", g["finger_width_mm"].as<double>(0.0)},
                     {"finger_height_mm", g["finger_height_mm"].as<double>(0.0)},
                     {"styles", styles}});
    }
  } catch (const YAML::Exception& e) {
    log::warn("config.vision", "cannot read the clear-grip models: no fingerprints",
              {{"file", path}, {"error", e.what()}});
    return json::array();
  }
  return out;
}

}  // namespace

MonitorService::MonitorService(service::Context& ctx, const MonitorConfig& config)
    : config_(config),
      ctx_(ctx),
      auth_(config.users, std::chrono::seconds(static_cast<long>(config.session_ttl_s))),
      hub_(config.client_queue, static_cast<std::size_t>(config.max_stream_clients)),
      directory_(ctx.participant(), "monitor"),
      state_topic_(ctx.participant(), bus::topics::kRobotState),
      state_latest_topic_(ctx.participant(), bus::topics::kRobotStateLatest),
      motion_status_topic_(ctx.participant(), bus::topics::kMotionStatus),
      world_topic_(ctx.participant(), bus::topics::kWorldState),
      image_topic_(ctx.participant(), bus::topics::kImage),
      preview_topic_(ctx.participant(), bus::topics::kImagePreview),
      detections_topic_(ctx.participant(), bus::topics::kDetections),
      edge_topic_(ctx.participant(), bus::topics::kEdgeResult),
      camera_cal_topic_(ctx.participant(), bus::topics::kCameraCalibration),
      belt_cal_topic_(ctx.participant(), bus::topics::kBeltCalibration),
      job_status_topic_(ctx.participant(), bus::topics::kJobStatus),
      event_topic_(ctx.participant(), bus::topics::kCellEvent),
      states_(ctx.participant(), state_topic_, bus::topics::kRobotState),
      states_latest_(ctx.participant(), state_latest_topic_, bus::topics::kRobotStateLatest),
      motion_status_(ctx.participant(), motion_status_topic_, bus::topics::kMotionStatus),
      world_(ctx.participant(), world_topic_, bus::topics::kWorldState),
      images_(ctx.participant(), image_topic_, bus::topics::kImage),
      previews_(ctx.participant(), preview_topic_, bus::topics::kImagePreview),
      detections_(ctx.participant(), detections_topic_, bus::topics::kDetections),
      edges_(ctx.participant(), edge_topic_, bus::topics::kEdgeResult),
      camera_cals_(ctx.participant(), camera_cal_topic_, bus::topics::kCameraCalibration),
      belt_cals_(ctx.participant(), belt_cal_topic_, bus::topics::kBeltCalibration),
      job_status_(ctx.participant(), job_status_topic_, bus::topics::kJobStatus),
      events_(ctx.participant(), event_topic_, bus::topics::kCellEvent),
      jobs_(ctx.participant(), bus::topics::kJobRequest, bus::topics::kJobStatus,
            bus::make_client_id("monitor")),
      job_commands_(ctx.participant(), bus::topics::kJobCommand, bus::topics::kJobCommandReply,
                    bus::make_client_id("monitor")),
      motion_(ctx.participant(), bus::topics::kMotionRequest, bus::topics::kMotionStatus,
              bus::make_client_id("monitor")),
      robot_commands_(ctx.participant(), bus::topics::kRobotCommand,
                      bus::topics::kRobotCommandReply, bus::make_client_id("monitor")) {
  started_ns_ = wall_time_ns();
  table_height_mm_ = config_.table.height_mm;
  std::map<std::string, kinematics::RobotModel> models;
  for (const auto& entry : config_.robots) {
    auto model = kinematics::load_robot(entry.config);
    if (!model) {
      throw std::runtime_error(fmt::format("robot '{}': {}", entry.id, model.error().message));
    }
    if (model->id() != entry.id) {
      throw std::runtime_error(fmt::format("robots: id '{}' but {} describes '{}'", entry.id,
                                           entry.config, model->id()));
    }
    models.emplace(entry.id, *model);
    robots_.emplace(entry.id, Robot{std::move(*model), entry.world_T_base});
  }
  for (const auto& path : config_.cameras) {
    auto camera = render::load_camera(path);
    if (!camera) {
      throw std::runtime_error(camera.error().message);
    }
    cameras_.push_back(std::move(*camera));
  }
  grasps_ = read_grasp_models(config_.vision_config);
  teach_ = std::make_unique<TeachSession>(
      ctx.participant(), std::move(models), config_.tasks_dir,
      [this](const std::string& id) -> std::optional<kinematics::JointVector> {
        auto sample = latest_sample(id);
        if (!sample || sample->q.empty()) {
          return std::nullopt;
        }
        return to_joint_vector(sample->q);
      },
      [this] {  // never calls back into the session
        teach_changed_ = true;
        wake_publisher();
      });

  server_ = std::make_unique<httplib::Server>();
  // One thread per open stream, plus room for the page's other requests (a browser keeps up
  // to six connections alive per host) and for commands that wait on the bus.
  const std::size_t pool = 2 * static_cast<std::size_t>(config_.max_stream_clients) + 8;
  server_->new_task_queue = [pool] { return new httplib::ThreadPool(pool); };
  server_->set_payload_max_length(std::size_t{64} * 1024);
  server_->set_keep_alive_max_count(1000);
  server_->set_keep_alive_timeout(2);  // an idle keep-alive connection holds a pool thread
  server_->set_read_timeout(10, 0);
  server_->set_write_timeout(5, 0);
  server_->set_default_headers(
      {{"X-Content-Type-Options", "nosniff"},
       {"X-Frame-Options", "DENY"},
       {"Referrer-Policy", "no-referrer"},
       {"Content-Security-Policy",
        "default-src 'self'; img-src 'self' blob: data:; style-src 'self'; script-src 'self'; "
        "connect-src 'self'; frame-ancestors 'none'"}});
  setup_routes();
  if (config_.port == 0) {
    port_ = server_->bind_to_any_port(config_.bind_address);
  } else {
    port_ = server_->bind_to_port(config_.bind_address, config_.port) ? config_.port : -1;
  }
  if (port_ <= 0) {
    throw std::runtime_error(fmt::format(
        "cannot listen on {}:{} (in use? not an address of this host?)", config_.bind_address,
        config_.port));
  }
  if (!std::filesystem::exists(config_.web_root + "/index.html")) {
    log::warn("web", "the web app is not built: the page says how to build it",
              {{"web_root", config_.web_root}});
  }
  for (const auto& user : config_.users) {
    if (std::find(std::begin(kShippedHashes), std::end(kShippedHashes), user.password_hash) !=
        std::end(kShippedHashes)) {
      log::warn("auth.default", "a user still has the demo password of config/monitor.yaml: "
                "replace its hash (cell-monitor --hash-password) before others can reach the port",
                {{"user", user.name}});
    }
  }
}

MonitorService::~MonitorService() {
  stopping_ = true;
  hub_.close_all();
  wake_publisher();
  if (server_) {
    server_->stop();
  }
  if (http_thread_.joinable()) {
    http_thread_.join();
  }
  if (publisher_thread_.joinable()) {
    publisher_thread_.join();
  }
  teach_.reset();
}

std::optional<RobotSample> MonitorService::latest_sample(const std::string& robot_id) const {
  std::lock_guard lock(latest_mutex_);
  auto it = samples_.find(robot_id);
  if (it == samples_.end()) {
    return std::nullopt;
  }
  return it->second;
}

void MonitorService::wake_publisher() {
  {
    std::lock_guard lock(wake_mutex_);
    wake_ = true;
  }
  wake_cv_.notify_one();
}

void MonitorService::run(service::Context& ctx) {
  http_thread_ = std::thread([this] {
    if (!server_->listen_after_bind() && !stopping_) {
      log::error("http", "the HTTP server stopped unexpectedly");
    }
  });
  publisher_thread_ = std::thread([this] { publisher_loop(); });
  log::info("http", "serving the monitor",
            {{"url", fmt::format("http://{}:{}/", config_.bind_address, port_)},
             {"web_root", config_.web_root}});
  bus::WaitSet waitset(ctx.participant());
  waitset.attach(ctx.stop_guard().get(), kStop);
  waitset.attach(states_.condition(), kStates);
  waitset.attach(states_latest_.condition(), kStatesLatest);
  waitset.attach(motion_status_.condition(), kMotionStatus);
  waitset.attach(world_.condition(), kWorld);
  waitset.attach(images_.condition(), kImages);
  waitset.attach(previews_.condition(), kImages);
  waitset.attach(detections_.condition(), kDetections);
  waitset.attach(edges_.condition(), kEdges);
  waitset.attach(camera_cals_.condition(), kCameraCal);
  waitset.attach(belt_cals_.condition(), kBeltCal);
  waitset.attach(job_status_.condition(), kJobStatus);
  waitset.attach(events_.condition(), kEvents);
  ctx.health().set(cell_health_HEALTH_SERVING);
  auto next_health = Clock::now();
  bool robots_pending = false;
  for (;;) {
    // Robot states held back by stream.robot_hz go out from this thread when their time
    // comes: no other thread to wake, so no extra scheduling delay on the way to the browser.
    const auto deadline = robots_pending ? std::min(next_health, robots_due()) : next_health;
    const bus::Fired fired = waitset.wait_until(deadline);
    if (fired.contains(kStop) || ctx.stopping()) {
      break;
    }
    robots_pending = take_bus(robots_pending);
    if (Clock::now() >= next_health) {
      publish_health();
      next_health = Clock::now() + kHealthPeriod;
    }
    ctx.health().tick();
  }
  stopping_ = true;
  hub_.close_all();
  wake_publisher();
  teach_->stop();
  server_->stop();
  http_thread_.join();
  publisher_thread_.join();
}

bool MonitorService::take_bus(bool robots_pending) {
  const std::int64_t now = wall_time_ns();
  bool robots = robots_pending;
  auto on_state = [&](const cell_robot_RobotState& s, const dds_sample_info_t&) {
    const std::string id(bus::str(s.robot_id));
    if (robots_.count(id) == 0) {
      return;  // a robot the page has no model of (e.g. a simulator's truth)
    }
    RobotSample sample = to_sample(s, now);
    std::lock_guard lock(latest_mutex_);
    auto it = samples_.find(id);
    if (it != samples_.end() && it->second.stamp_ns > sample.stamp_ns) {
      return;  // state_latest can deliver an older sample than the stream already did
    }
    samples_[id] = std::move(sample);
    sample_fresh_[id] = true;
    robots = true;
  };
  (void)states_.take_each(on_state);
  (void)states_latest_.take_each(on_state);
  // At once when the rate allows: before the other readers' work.
  if (robots && publish_robots_if_due(Clock::now())) {
    robots = false;
  }

  (void)motion_status_.take_each(
      [&](const cell_motion_MotionStatus& s, const dds_sample_info_t&) {
        hub_.publish({"motion", to_text(motion_status_json(s))});
      });
  bool world = false;
  if (auto worlds = world_.take_copies(4); worlds && !worlds->empty()) {
    std::lock_guard lock(latest_mutex_);
    world_latest_ = std::move(worlds->back());
    world_fresh_ = true;
    world = true;
  }
  bool images = false;
  // Full-rate images where the camera's PC lets them through, previews from elsewhere: the
  // newest of either per camera is what is shown.
  for (auto* reader : {&images_, &previews_}) {
    if (auto taken = reader->take_copies(4); taken) {
      std::lock_guard lock(latest_mutex_);
      for (auto& image : *taken) {
        auto& slot = images_latest_[std::string(bus::str(image->camera_id))].latest;
        if (!slot || image->header.stamp_ns >= (*slot)->header.stamp_ns) {
          slot = std::move(image);
        }
        images = true;
      }
    }
  }
  (void)detections_.take_each([&](const cell_vision_Detections& d, const dds_sample_info_t&) {
    json j = detections_json(d);
    const std::string camera(bus::str(d.camera_id));
    const std::string text = to_text(j);
    {
      std::lock_guard lock(latest_mutex_);
      detections_latest_[camera] = std::move(j);
    }
    hub_.publish({"detections", text}, "detections/" + camera);
  });
  (void)edges_.take_each([&](const cell_vision_EdgeResult& e, const dds_sample_info_t&) {
    hub_.publish({"edge", to_text(edge_result_json(e))},
                 "edge/" + std::string(bus::str(e.camera_id)));
  });
  (void)camera_cals_.take_each(
      [&](const cell_calibration_CameraCalibration& c, const dds_sample_info_t&) {
        const std::string camera(bus::str(c.camera_id));
        if (std::isfinite(c.working_plane_z_mm)) {
          std::lock_guard lock(latest_mutex_);
          plane_z_[camera] = c.working_plane_z_mm;
        }
        hub_.publish({"calibration",
                      to_text(json{{"type", "camera"}, {"data", camera_calibration_json(c)}})},
                     "calibration/camera/" + camera);
      });
  (void)belt_cals_.take_each(
      [&](const cell_calibration_BeltCalibration& c, const dds_sample_info_t&) {
        hub_.publish({"calibration",
                      to_text(json{{"type", "belt"}, {"data", belt_calibration_json(c)}})},
                     "calibration/belt/" + std::string(bus::str(c.belt_id)));
      });
  (void)job_status_.take_each([&](const cell_task_JobStatus& s, const dds_sample_info_t&) {
    const std::string key = "jobs/" + std::string(bus::str(s.job_id));
    if (std::find(sticky_jobs_.begin(), sticky_jobs_.end(), key) == sticky_jobs_.end()) {
      sticky_jobs_.push_back(key);
      if (sticky_jobs_.size() > kStickyJobs) {
        hub_.forget(sticky_jobs_.front());
        sticky_jobs_.pop_front();
      }
    }
    hub_.publish({"job", to_text(job_status_json(s))}, key);
  });
  bool new_events = false;
  (void)events_.take_each([&](const cell_health_CellEvent& e, const dds_sample_info_t&) {
    json j = event_json(e);
    hub_.publish({"event", to_text(j)});
    std::lock_guard lock(latest_mutex_);
    event_log_.push_back(std::move(j));
    if (event_log_.size() > kEventLog) {
      event_log_.pop_front();
    }
    new_events = true;
  });
  if (new_events) {
    std::lock_guard lock(latest_mutex_);
    hub_.remember({"events", to_text(json(event_log_))}, "events");
  }
  if (robots && publish_robots_if_due(Clock::now())) {
    robots = false;
  }
  if (world || images) {
    wake_publisher();
  }
  return robots;
}

bool MonitorService::publish_robots_if_due(Clock::time_point now) {
  std::lock_guard lock(robots_mutex_);
  if (now < robots_sent_ + period_of(config_.stream_hz)) {
    return false;
  }
  robots_sent_ = now;
  publish_robots();
  return true;
}

MonitorService::Clock::time_point MonitorService::robots_due() const {
  std::lock_guard lock(robots_mutex_);
  return robots_sent_ + period_of(config_.stream_hz);
}

void MonitorService::publish_health() {
  auto services = directory_.snapshot();
  if (!services) {
    return;
  }
  json list = json::array();
  std::string signature;
  for (const auto& s : *services) {
    list.push_back({{"id", s.service_id},
                    {"kind", s.kind},
                    {"host", s.host},
                    {"pid", s.pid},
                    {"state", std::string(s.status())},
                    {"detail", s.detail},
                    {"uptime_s", number(s.uptime_s)},
                    {"version", s.version},
                    {"last_heartbeat_ns", s.last_heartbeat_ns}});
    signature += s.service_id + "=" + std::string(s.status()) + ":" + s.detail + ";";
  }
  // On every change, and every few seconds anyway (uptimes, last heartbeats).
  const std::int64_t now = wall_time_ns();
  if (signature == health_signature_ && now - health_published_ns_ < kHealthRefreshNs) {
    return;
  }
  health_signature_ = signature;
  health_published_ns_ = now;
  hub_.publish({"health", to_text(json{{"stamp_ns", now},
                                       {"services", list},
                                       {"bridge",
                                        {{"clients", hub_.client_count()},
                                         {"dropped", hub_.dropped_total()},
                                         {"uptime_s", static_cast<double>(now - started_ns_) *
                                                          1e-9}}}})},
               "health");
}

void MonitorService::publisher_loop() {
  const auto world_period = period_of(config_.world_hz);
  std::unique_lock lock(wake_mutex_);
  while (!stopping_) {
    lock.unlock();
    const auto now = Clock::now();
    auto next = now + 1s;  // nothing pending: sleep until woken
    bool world_pending = false;
    {
      std::lock_guard latest(latest_mutex_);
      world_pending = world_fresh_;
    }
    if (world_pending) {
      if (now >= world_sent_ + world_period) {
        world_sent_ = now;
        publish_world();
      } else {
        next = std::min(next, world_sent_ + world_period);
      }
    }
    next = std::min(next, publish_images(now));
    if (teach_changed_.exchange(false)) {
      publish_teach();
    }
    lock.lock();
    wake_cv_.wait_until(lock, next, [&] { return wake_ || stopping_.load(); });
    wake_ = false;
  }
}

void MonitorService::publish_robots() {
  json robots = json::array();
  std::vector<std::pair<std::string, json>> singles;
  {
    std::lock_guard lock(latest_mutex_);
    for (auto& [id, fresh] : sample_fresh_) {
      if (!fresh) {
        continue;
      }
      fresh = false;
      json j = sample_json(samples_[id]);
      singles.emplace_back(id, j);
      robots.push_back(std::move(j));
    }
  }
  if (robots.empty()) {
    return;
  }
  const std::int64_t sent = wall_time_ns();
  hub_.publish({"robots", to_text(json{{"sent_ns", sent}, {"robots", robots}})});
  // A client that connects later gets each robot's newest state at once.
  for (auto& [id, single] : singles) {
    hub_.remember({"robots", to_text(json{{"sent_ns", sent}, {"robots", json::array({single})}})},
                  "robot/" + id);
  }
}

void MonitorService::publish_world() {
  json j;
  {
    std::lock_guard lock(latest_mutex_);
    if (!world_fresh_ || !world_latest_) {
      return;
    }
    world_fresh_ = false;
    j = world_json(world_latest_->get());
    world_parts_.clear();
    for (const auto& p : j["parts"]) {
      world_parts_[p["id"].get<std::string>()] = p;
    }
    if (j["table_height_mm"].is_number()) {
      table_height_mm_ = j["table_height_mm"].get<double>();
    }
  }
  hub_.publish({"world", to_text(j)}, "world");
}

MonitorService::Clock::time_point MonitorService::publish_images(Clock::time_point now) {
  const auto period = period_of(config_.image_hz);
  auto next = now + 1s;
  // Take the due images out of their slots, encode them without holding the lock (a JPEG takes
  // milliseconds; the bus thread must not wait for it), then store the frames.
  std::vector<std::pair<std::string, bus::Owned<cell_vision_Image>>> due;
  {
    std::lock_guard lock(latest_mutex_);
    for (auto& [camera, slot] : images_latest_) {
      if (!slot.latest) {
        continue;
      }
      if (now - slot.last_encoded < period) {
        next = std::min(next, slot.last_encoded + period);
        continue;
      }
      slot.last_encoded = now;
      due.emplace_back(camera, std::move(*slot.latest));
      slot.latest.reset();
    }
  }
  for (auto& [camera, owned] : due) {
    const cell_vision_Image& image = owned.get();
    const auto data = bus::span(image.data);
    const std::string encoding(bus::str(image.encoding));
    const int channels = encoding == "rgb8" ? 3 : encoding == "mono8" ? 1 : 0;
    const auto w = static_cast<int>(image.width_px);
    const auto h = static_cast<int>(image.height_px);
    const bool sane = channels > 0 && w > 0 && h > 0 && w <= 16384 && h <= 16384 &&
                      image.step_bytes >= image.width_px * static_cast<unsigned>(channels) &&
                      data.size() >= static_cast<std::size_t>(image.step_bytes) * image.height_px;
    if (!sane) {
      log::warn("image.skip", "malformed image not shown",
                {{"camera", camera}, {"encoding", encoding}});
      continue;
    }
    std::vector<std::uint8_t> jpeg;
    try {
      cv::Mat view(h, w, channels == 3 ? CV_8UC3 : CV_8UC1,
                   const_cast<std::uint8_t*>(data.data()), image.step_bytes);
      cv::Mat bgr;
      if (channels == 3) {
        cv::cvtColor(view, bgr, cv::COLOR_RGB2BGR);
      } else {
        bgr = view;
      }
      if (!cv::imencode(".jpg", bgr, jpeg, {cv::IMWRITE_JPEG_QUALITY, 80})) {
        continue;
      }
    } catch (const cv::Exception& e) {
      log::warn("image.skip", e.what(), {{"camera", camera}});
      continue;
    }
    json note;
    {
      std::lock_guard lock(latest_mutex_);
      ImageSlot& slot = images_latest_[camera];
      slot.jpeg.assign(jpeg.begin(), jpeg.end());
      ++slot.seq;
      const auto joints = bus::span(image.robot_joints_rad_or_mm);
      note = {{"camera", camera},
              {"seq", slot.seq},
              {"image_seq", image.header.seq},
              {"stamp_ns", image.header.stamp_ns},
              {"width_px", w},
              {"height_px", h},
              {"robot", std::string(bus::str(image.robot_id))},
              {"robot_joints", json(std::vector<double>(joints.begin(), joints.end()))}};
    }
    hub_.publish({"image", to_text(note)}, "image/" + camera);
  }
  return next;
}

void MonitorService::publish_teach() {
  hub_.publish({"teach", to_text(teach_->state())}, "teach");
}

json MonitorService::config_json() const {
  json robots = json::array();
  for (const auto& entry : config_.robots) {  // in the config's order: the first is the default
    const Robot& r = robots_.at(entry.id);
    robots.push_back(robot_model_json(r.model, r.world_T_base));
  }
  json cameras = json::array();
  for (const auto& c : cameras_) {
    cameras.push_back(camera_json(c));
  }
  json templates = json::array();
  for (const auto& t : config_.job_templates) {
    templates.push_back({{"name", t.name},
                         {"description", t.description},
                         {"kind", t.kind},
                         {"robot", t.robot_id},
                         {"camera", t.camera_id},
                         {"belt", t.belt_id},
                         {"spec_file", t.spec_file}});
  }
  double table_z = 0.0;
  {
    std::lock_guard lock(latest_mutex_);
    table_z = table_height_mm_;
  }
  return {{"version", std::string(version())},
          {"robots", robots},
          {"cameras", cameras},
          {"job_templates", templates},
          {"grasps", grasps_},
          {"table",
           {{"x_mm", config_.table.x_mm}, {"y_mm", config_.table.y_mm}, {"height_mm", table_z}}},
          {"stream",
           {{"robot_hz", config_.stream_hz},
            {"world_hz", config_.world_hz},
            {"image_hz", config_.image_hz}}},
          {"approach_mm", config_.approach_mm},
          {"login_available", auth_.has_users()},
          {"bus", {{"domain", ctx_.common().domain_id}, {"partition", ctx_.common().partition}}}};
}

std::optional<SessionInfo> MonitorService::session_of(const httplib::Request& req) {
  const std::string token = cookie_value(req.get_header_value("Cookie"), kCookie);
  if (token.empty()) {
    return std::nullopt;
  }
  return auth_.session(token);
}

bool MonitorService::may_view(const httplib::Request& req, httplib::Response& res) {
  if (!config_.viewers_must_sign_in || session_of(req)) {
    return true;
  }
  reply_json(res, 401, {{"error", "sign in to watch the cell"}});
  return false;
}

bool MonitorService::require_operator(const httplib::Request& req, httplib::Response& res,
                                      SessionInfo& who) {
  // Cross-site requests: the cookie is SameSite=Strict, a JSON content type cannot be sent
  // cross-site without a CORS preflight (which this server never grants), and a foreign
  // Origin is refused outright.
  const std::string origin = req.get_header_value("Origin");
  const std::string host = req.get_header_value("Host");
  if (!origin.empty() && origin != "http://" + host && origin != "https://" + host) {
    reply_json(res, 403, {{"error", "cross-origin command refused"}});
    log::warn("command.reject", "cross-origin", {{"origin", origin.substr(0, 100)}});
    return false;
  }
  auto session = session_of(req);
  if (!session) {
    reply_json(res, 401, {{"error", "sign in as an operator to send commands"}});
    log::warn("command.reject", "not signed in", {{"path", req.path}});
    return false;
  }
  if (session->role != "operator") {
    reply_json(res, 403,
               {{"error", fmt::format("user '{}' may watch but not command (role {})",
                                      session->user, session->role)}});
    return false;
  }
  if (req.get_header_value("Content-Type").rfind("application/json", 0) != 0) {
    reply_json(res, 415, {{"error", "commands are JSON: Content-Type: application/json"}});
    return false;
  }
  who = *session;
  return true;
}

std::optional<json> MonitorService::body_json(const httplib::Request& req,
                                              httplib::Response& res) {
  json body = json::parse(req.body, nullptr, false);
  if (body.is_discarded() || !body.is_object()) {
    reply_json(res, 400, {{"error", "the request body is not a JSON object"}});
    log::warn("command.reject", "malformed JSON", {{"path", req.path}});
    return std::nullopt;
  }
  return body;
}

void MonitorService::audit(const SessionInfo& who, std::string_view what, std::string_view robot,
                           std::string_view job) {
  ctx_.events().publish(cell_health_SEVERITY_INFO, "monitor.command",
                        fmt::format("{}: {}", who.user, what), robot, job);
}

void MonitorService::setup_routes() {
  httplib::Server& s = *server_;
  s.set_exception_handler(
      [](const httplib::Request& req, httplib::Response& res, std::exception_ptr ep) {
        std::string what = "unknown error";
        try {
          std::rethrow_exception(std::move(ep));
        } catch (const std::exception& e) {
          what = e.what();
        } catch (...) {
        }
        log::error("http.exception", what, {{"path", req.path}});
        reply_json(res, 500, {{"error", "internal error: " + what}});
      });
  s.Get("/api/config", [this](const httplib::Request& req, httplib::Response& res) {
    if (may_view(req, res)) {
      reply_json(res, 200, config_json());
    }
  });
  s.Get("/api/status", [this](const httplib::Request&, httplib::Response& res) {
    reply_json(res, 200,
               {{"version", std::string(version())},
                {"clients", hub_.client_count()},
                {"dropped", hub_.dropped_total()},
                {"sessions", auth_.session_count()}});
  });
  s.Get("/api/session", [this](const httplib::Request& req, httplib::Response& res) {
    // 200 either way: a page that is not signed in is normal, not an error to log.
    auto session = session_of(req);
    if (!session) {
      reply_json(res, 200, {{"signed_in", false}, {"login_available", auth_.has_users()}});
      return;
    }
    reply_json(res, 200, {{"signed_in", true}, {"user", session->user}, {"role", session->role}});
  });
  s.Post("/api/login", [this](const httplib::Request& req, httplib::Response& res) {
    handle_login(req, res);
  });
  s.Post("/api/logout", [this](const httplib::Request& req, httplib::Response& res) {
    auth_.sign_out(cookie_value(req.get_header_value("Cookie"), kCookie));
    res.set_header("Set-Cookie",
                   fmt::format("{}=; Path=/; HttpOnly; SameSite=Strict; Max-Age=0", kCookie));
    reply_json(res, 200, {{"signed_out", true}});
  });
  s.Get("/api/stream", [this](const httplib::Request& req, httplib::Response& res) {
    handle_stream(req, res);
  });
  s.Get(R"(/api/image/([A-Za-z0-9_.-]{1,64}))",
        [this](const httplib::Request& req, httplib::Response& res) {
          if (!may_view(req, res)) {
            return;
          }
          std::string jpeg;
          {
            std::lock_guard lock(latest_mutex_);
            auto it = images_latest_.find(req.matches[1].str());
            if (it != images_latest_.end()) {
              jpeg = it->second.jpeg;
            }
          }
          if (jpeg.empty()) {
            reply_json(res, 404, {{"error", "no image from that camera yet"}});
            return;
          }
          res.set_header("Cache-Control", "no-store");
          res.set_content(jpeg, "image/jpeg");
        });
  s.Get("/api/teach", [this](const httplib::Request& req, httplib::Response& res) {
    if (may_view(req, res)) {
      reply_json(res, 200, teach_->state());
    }
  });
  s.Post("/api/motion", [this](const httplib::Request& req, httplib::Response& res) {
    handle_motion(req, res);
  });
  s.Post("/api/goto_part", [this](const httplib::Request& req, httplib::Response& res) {
    handle_goto_part(req, res);
  });
  s.Post("/api/robot/command", [this](const httplib::Request& req, httplib::Response& res) {
    handle_robot_command(req, res);
  });
  s.Post("/api/job/submit", [this](const httplib::Request& req, httplib::Response& res) {
    handle_job_submit(req, res);
  });
  s.Post("/api/job/command", [this](const httplib::Request& req, httplib::Response& res) {
    handle_job_command(req, res);
  });
  s.Post(R"(/api/teach/([a-z_]{1,16}))",
         [this](const httplib::Request& req, httplib::Response& res) {
           handle_teach(req.matches[1].str(), req, res);
         });
  if (std::filesystem::exists(config_.web_root + "/index.html")) {
    s.set_mount_point("/", config_.web_root,
                      {{"Cache-Control", "no-cache"}});  // revalidate: a rebuild shows at once
  } else {
    const std::string root = config_.web_root;
    s.Get("/", [root](const httplib::Request&, httplib::Response& res) {
      res.set_content(
          "<!doctype html><title>cell monitor</title><p>The web app is not built (no " + root +
              "/index.html). Run <code>scripts/install-deps.sh</code> and build the "
              "<code>monitor_web</code> target (<code>npm ci</code> in clients/monitor/web, "
              "then <code>node build.mjs</code>).</p>",
          "text/html");
    });
  }
}

void MonitorService::handle_login(const httplib::Request& req, httplib::Response& res) {
  // Login CSRF: a foreign page must not sign the browser in either.
  const std::string origin = req.get_header_value("Origin");
  const std::string host = req.get_header_value("Host");
  if (!origin.empty() && origin != "http://" + host && origin != "https://" + host) {
    reply_json(res, 403, {{"error", "cross-origin sign-in refused"}});
    return;
  }
  auto body = body_json(req, res);
  if (!body) {
    return;
  }
  auto user = string_field(*body, "user");
  auto password = string_field(*body, "password");
  if (!user || !password) {
    reply_json(res, 400, {{"error", "sign-in needs 'user' and 'password' (strings)"}});
    return;
  }
  auto token = auth_.sign_in(*user, *password);
  if (!token) {
    log::warn("auth.fail", token.error().message, {{"user", user->substr(0, 64)}});
    reply_json(res, token.error().code == Errc::kNotReady ? 429 : 401,
               {{"error", token.error().message}});
    return;
  }
  auto session = auth_.session(*token);
  if (!session) {  // a TTL shorter than the sign-in itself: nothing to hand out
    reply_json(res, 500, {{"error", "the new session expired at once (auth.session_ttl_s)"}});
    return;
  }
  res.set_header("Set-Cookie",
                 fmt::format("{}={}; Path=/; HttpOnly; SameSite=Strict; Max-Age={}{}", kCookie,
                             *token, static_cast<long>(config_.session_ttl_s),
                             config_.secure_cookie ? "; Secure" : ""));
  log::info("auth.sign_in", "signed in", {{"user", session->user}, {"role", session->role}});
  reply_json(res, 200, {{"user", session->user}, {"role", session->role}});
}

void MonitorService::handle_stream(const httplib::Request& req, httplib::Response& res) {
  if (!may_view(req, res)) {
    return;
  }
  auto id = hub_.connect();
  if (!id) {
    reply_json(res, 503, {{"error", "too many live streams open (http.max_stream_clients)"}});
    return;
  }
  // cpp-httplib may compress a text/* body (it is built with zlib and brotli), which buffers
  // it: the stream must go out as it is written, so it is answered without content encoding.
  // The request object is the server's own non-const local; only this handler sees it.
  const_cast<httplib::Request&>(req).headers.erase("Accept-Encoding");
  res.set_header("Cache-Control", "no-store");
  res.set_header("X-Accel-Buffering", "no");
  const std::uint64_t client = *id;
  auto last_write = std::make_shared<Clock::time_point>(Clock::now());
  res.set_chunked_content_provider(
      "text/event-stream",
      [this, client, last_write](std::size_t, httplib::DataSink& sink) {
        if (stopping_) {
          return false;
        }
        auto queue = hub_.queue(client);
        if (!queue) {
          return false;
        }
        std::vector<std::shared_ptr<const std::string>> frames;
        if (!queue->pop_all(frames, 250ms)) {
          return false;
        }
        if (frames.empty()) {
          if (Clock::now() - *last_write < kStreamKeepAlive) {
            return true;
          }
          static constexpr std::string_view kKeepAlive = ": keep-alive\n\n";
          *last_write = Clock::now();
          return sink.write(kKeepAlive.data(), kKeepAlive.size());
        }
        std::string batch;
        for (const auto& f : frames) {
          batch += *f;
        }
        *last_write = Clock::now();
        return sink.write(batch.data(), batch.size());
      },
      [this, client](bool) { hub_.disconnect(client); });
}

void MonitorService::handle_motion(const httplib::Request& req, httplib::Response& res) {
  SessionInfo who;
  if (!require_operator(req, res, who)) {
    return;
  }
  auto body = body_json(req, res);
  if (!body) {
    return;
  }
  auto robot_id = string_field(*body, "robot");
  if (!robot_id) {
    reply_error(res, robot_id.error());
    return;
  }
  auto it = robots_.find(*robot_id);
  if (it == robots_.end()) {
    reply_json(res, 400, {{"error", fmt::format("unknown robot '{}'", robot_id->substr(0, 64))}});
    return;
  }
  const auto latest = latest_sample(*robot_id);
  auto cmd = parse_motion(*body, it->second.model, latest ? &*latest : nullptr);
  if (!cmd) {
    log::warn("command.reject", cmd.error().message, {{"user", who.user}, {"robot", *robot_id}});
    reply_error(res, cmd.error());
    return;
  }
  send_motion(*cmd, who, res);
}

Result<Eigen::Isometry3d> MonitorService::detection_target(const Robot& robot,
                                                           const std::string& camera,
                                                           long long index,
                                                           double grasp_height_mm) {
  json item;
  std::optional<double> plane_z;
  std::string detections_robot;
  double table_z = 0.0;
  {
    std::lock_guard lock(latest_mutex_);
    auto d = detections_latest_.find(camera);
    if (d != detections_latest_.end() && index >= 0 &&
        index < static_cast<long long>(d->second["items"].size())) {
      item = d->second["items"][static_cast<std::size_t>(index)];
      detections_robot = d->second.value("robot", std::string());
    }
    if (auto z = plane_z_.find(camera); z != plane_z_.end()) {
      plane_z = z->second;
    }
    table_z = table_height_mm_;
  }
  if (item.is_null()) {
    return Error{Errc::kInvalidArgument,
                 fmt::format("camera '{}' has no detection {} in its last image", camera, index)};
  }
  const json& bp = item["base_pose"];
  if (!bp.is_object() || !bp["x_mm"].is_number() || !bp["y_mm"].is_number() ||
      !bp["rz_rad"].is_number()) {
    return Error{Errc::kNotReady,
                 fmt::format("detection {} of camera '{}' has no position in the robot's frame: "
                             "is the camera calibrated?",
                             index, camera)};
  }
  if (!detections_robot.empty() && detections_robot != robot.model.id()) {
    return Error{Errc::kInvalidArgument,
                 fmt::format("camera '{}' locates parts for robot '{}', not '{}'", camera,
                             detections_robot, robot.model.id())};
  }
  // The working plane in the base frame: the camera's calibration, else the world's table.
  const double z = plane_z.value_or(table_z - robot.world_T_base.translation().z());
  Eigen::Isometry3d base_T_part = Eigen::Isometry3d::Identity();
  base_T_part.translation() << bp["x_mm"].get<double>(), bp["y_mm"].get<double>(),
      z + grasp_height_mm;
  base_T_part.linear() =
      Eigen::AngleAxisd(bp["rz_rad"].get<double>(), Eigen::Vector3d::UnitZ()).toRotationMatrix();
  return grasp_tool_pose(robot.model, Eigen::Isometry3d::Identity(), base_T_part);
}

void MonitorService::handle_goto_part(const httplib::Request& req, httplib::Response& res) {
  SessionInfo who;
  if (!require_operator(req, res, who)) {
    return;
  }
  auto body = body_json(req, res);
  if (!body) {
    return;
  }
  auto robot_id = string_field(*body, "robot");
  if (!robot_id || robots_.count(*robot_id) == 0) {
    reply_json(res, 400, {{"error", robot_id ? fmt::format("unknown robot '{}'",
                                                           robot_id->substr(0, 64))
                                             : robot_id.error().message}});
    return;
  }
  const Robot& robot = robots_.at(*robot_id);
  MotionCommand cmd;
  cmd.robot_id = *robot_id;
  auto preview = optional_bool(*body, "preview", false);
  auto speed = number_field(*body, "speed", 0.5, 0.01, 1.0, "");
  auto approach = number_field(*body, "approach_mm", config_.approach_mm, 0.0, 500.0, "mm");
  for (const Status& s : {preview ? ok_status() : Status(preview.error()),
                          speed ? ok_status() : Status(speed.error()),
                          approach ? ok_status() : Status(approach.error())}) {
    if (!s) {
      reply_error(res, s.error());
      return;
    }
  }
  cmd.preview = *preview;
  cmd.speed_scale = *speed;
  Result<Eigen::Isometry3d> target = Error{Errc::kInvalidArgument, ""};
  if (body->contains("part")) {
    auto part = string_field(*body, "part");
    if (!part) {
      reply_error(res, part.error());
      return;
    }
    json grasp;
    {
      std::lock_guard lock(latest_mutex_);
      auto p = world_parts_.find(*part);
      if (p != world_parts_.end()) {
        grasp = p->second["grasp"];
      }
    }
    if (grasp.is_null()) {
      reply_json(res, 400,
                 {{"error", fmt::format("no part '{}' in the world", part->substr(0, 64))}});
      return;
    }
    auto world_T_grasp = pose_from_json(grasp);
    target = world_T_grasp ? grasp_tool_pose(robot.model, robot.world_T_base, *world_T_grasp)
                           : Result<Eigen::Isometry3d>(world_T_grasp.error());
    cmd.what = fmt::format("go to the grasp position of part '{}'", *part);
  } else {
    auto camera = string_field(*body, "camera");
    if (!camera || !body->contains("index") || !(*body)["index"].is_number_integer()) {
      reply_json(res, 400, {{"error", "name a world 'part', or a 'camera' and the detection "
                                      "'index' N"}});
      return;
    }
    const auto index = (*body)["index"].get<long long>();
    target = detection_target(robot, *camera, index, config_.grasp_height_mm);
    cmd.what = fmt::format("go to the grasp position of detection {} of {}", index,
                           camera->substr(0, 64));
  }
  if (!target) {
    reply_error(res, target.error());
    return;
  }
  cmd.target = *target;
  if (*approach > 0.0) {
    cmd.kind = cell_motion_MOTION_APPROACH;
    cmd.distance_mm = *approach;
    cmd.what += fmt::format(", {:.0f} mm above it", *approach);
  } else {
    cmd.kind = cell_motion_MOTION_MOVE_POSE;
  }
  send_motion(cmd, who, res);
}

void MonitorService::send_motion(const MotionCommand& cmd, const SessionInfo& who,
                                 httplib::Response& res) {
  const auto& model = robots_.at(cmd.robot_id).model;
  const std::string motion_id =
      fmt::format("monitor-{}-{}-{}", who.user, wall_time_ns(), ++motion_counter_);
  std::vector<double> joints(cmd.joints.data(), cmd.joints.data() + cmd.joints.size());
  cell_motion_MotionRequest request{};
  request.motion_id = bus::borrow(motion_id);
  request.robot_id = bus::borrow(cmd.robot_id);
  request.kind = cmd.kind;
  bus::borrow(request.joints_rad_or_mm, joints);
  request.target = geometry::pose_to_idl(cmd.target);
  request.distance_mm = cmd.distance_mm;
  request.speed_scale = cmd.speed_scale;
  request.preview_only = cmd.preview;
  request.alter_world_frame = true;
  const std::string empty;
  request.branch = bus::borrow(empty);
  std::lock_guard lock(motion_mutex_);
  auto seq = motion_.send(request, ms(kMatchTimeout));
  if (!seq) {
    reply_json(res, 503, {{"error", fmt::format("{} (is the motion service running?)",
                                                seq.error().message)}});
    return;
  }
  log::info("command.motion", cmd.what,
            {{"user", who.user},
             {"robot", cmd.robot_id},
             {"motion", motion_id},
             {"preview", cmd.preview ? "true" : "false"}});
  if (!cmd.preview) {
    audit(who, fmt::format("{} ({})", cmd.what, motion_id), cmd.robot_id);
  }
  // A preview waits for its plan; a move for its acceptance (or refusal), so the page shows a
  // refusal at once; the rest streams as "motion" messages.
  const auto deadline = Clock::now() + kPreviewTimeout;
  auto status = motion_.wait_reply(*seq, deadline, [&](const cell_motion_MotionStatus& s) {
    return !cmd.preview || s.state == cell_motion_MOTION_PREVIEW ||
           s.state == cell_motion_MOTION_REFUSED || s.state == cell_motion_MOTION_FAILED;
  });
  if (!status) {
    reply_json(res, 504,
               {{"error", fmt::format("motion '{}': {}", motion_id, status.error().message)},
                {"motion_id", motion_id}});
    return;
  }
  const cell_motion_MotionStatus& st = status->get();
  json out = motion_status_json(st);
  out["what"] = cmd.what;
  if (st.state == cell_motion_MOTION_REFUSED || st.state == cell_motion_MOTION_FAILED) {
    out["error"] = fmt::format("{}: {}", motion_state_name(st.state), bus::str(st.reason));
    reply_json(res, 409, out);
    return;
  }
  if (st.state == cell_motion_MOTION_PREVIEW) {
    // The plan's tool path, and the joints along it (IK of each pose seeded by the previous
    // one, starting at the robot's current joints) for the page's ghost arm.
    json path = json::array();
    json samples = json::array();
    auto latest = latest_sample(cmd.robot_id);
    std::optional<kinematics::JointVector> seed;
    if (latest && static_cast<int>(latest->q.size()) == model.dof()) {
      seed = to_joint_vector(latest->q);
      samples.push_back(joints_array(*seed));
    }
    for (const auto& p : bus::span(st.path)) {
      auto pose = geometry::pose_from_idl(p);
      if (!pose) {
        continue;
      }
      path.push_back(pose_json(*pose));
      if (seed) {
        if (auto q = model.inverse(*pose, *seed)) {
          seed = *q;
          samples.push_back(joints_array(*q));
        }
      }
    }
    const auto final_q = bus::to_vector(st.final_joints_rad_or_mm);
    if (static_cast<int>(final_q.size()) == model.dof()) {
      samples.push_back(joints_array(to_joint_vector(final_q)));
    }
    out["path"] = path;
    out["samples"] = samples;
    out["final_joints"] = joints_array(to_joint_vector(final_q));
  }
  reply_json(res, 200, out);
}

void MonitorService::handle_robot_command(const httplib::Request& req, httplib::Response& res) {
  SessionInfo who;
  if (!require_operator(req, res, who)) {
    return;
  }
  auto body = body_json(req, res);
  if (!body) {
    return;
  }
  std::vector<std::string> ids;
  for (const auto& [id, r] : robots_) {
    ids.push_back(id);
  }
  auto spec = parse_robot_command(*body, ids);
  if (!spec) {
    reply_error(res, spec.error());
    return;
  }
  cell_robot_RobotCommand command{};
  command.robot_id = bus::borrow(spec->robot_id);
  command.kind = spec->kind;
  command.operator_id = bus::borrow(who.user);
  std::lock_guard lock(robot_mutex_);
  auto reply = robot_commands_.call(command, ms(kMatchTimeout));
  log::info("command.robot", spec->name, {{"user", who.user}, {"robot", spec->robot_id}});
  if (!reply) {
    reply_json(res, 504, {{"error", fmt::format("{} '{}': {} (is gateway.{} running?)", spec->name,
                                                spec->robot_id, reply.error().message,
                                                spec->robot_id)}});
    return;
  }
  const auto& status = (*reply)->status;
  if (!status.accepted) {
    reply_json(res, 409,
               {{"error", fmt::format("{} refused: {}", spec->name, bus::str(status.reason))}});
    return;
  }
  audit(who, fmt::format("robot {}", spec->name), spec->robot_id);
  reply_json(res, 200, {{"robot", spec->robot_id}, {"command", spec->name}, {"accepted", true}});
}

void MonitorService::handle_job_submit(const httplib::Request& req, httplib::Response& res) {
  SessionInfo who;
  if (!require_operator(req, res, who)) {
    return;
  }
  auto body = body_json(req, res);
  if (!body) {
    return;
  }
  auto spec = parse_job_submit(*body, config_.job_templates, wall_time_ns() / 1'000'000);
  if (!spec) {
    reply_error(res, spec.error());
    return;
  }
  const JobTemplate& t = *spec->job_template;
  cell_task_JobRequest request{};
  request.job_id = bus::borrow(spec->job_id);
  request.kind = spec->kind;
  request.robot_id = bus::borrow(t.robot_id);
  request.camera_id = bus::borrow(t.camera_id);
  request.belt_id = bus::borrow(t.belt_id);
  request.spec_yaml = bus::borrow(t.spec_yaml);
  const std::string program = t.program_name.empty() ? t.spec_file : t.program_name;
  request.program_name = bus::borrow(program);
  request.operator_id = bus::borrow(who.user);
  std::lock_guard lock(job_mutex_);
  auto seq = jobs_.send(request, ms(kMatchTimeout));
  if (!seq) {
    reply_json(res, 503, {{"error", fmt::format("no task service on the bus ({}): the job was "
                                                "not submitted",
                                                seq.error().message)}});
    return;
  }
  log::info("command.job_submit", t.name, {{"user", who.user}, {"job", spec->job_id}});
  audit(who, fmt::format("submit job '{}' from template '{}'", spec->job_id, t.name), t.robot_id,
        spec->job_id);
  // The task service answers every request with a JobStatus (queued, or rejected with every
  // reason) under the same request id.
  auto status = jobs_.wait_reply(*seq, Clock::now() + kJobReplyTimeout);
  json out{{"job_id", spec->job_id}, {"template", t.name}, {"published", true}};
  if (!status) {
    out["state"] = "submitted";
    out["warning"] = "the task service has not answered yet: its status will show in the list";
    reply_json(res, 202, out);
    return;
  }
  out["status"] = job_status_json(status->get());
  if (status->get().state == cell_task_JOB_REJECTED) {
    std::string reasons;
    for (const char* r : bus::span(status->get().reasons)) {
      reasons += (reasons.empty() ? "" : "; ") + std::string(bus::str(r));
    }
    out["error"] = "rejected: " + reasons;
    reply_json(res, 409, out);
    return;
  }
  reply_json(res, 200, out);
}

void MonitorService::handle_job_command(const httplib::Request& req, httplib::Response& res) {
  SessionInfo who;
  if (!require_operator(req, res, who)) {
    return;
  }
  auto body = body_json(req, res);
  if (!body) {
    return;
  }
  auto spec = parse_job_command(*body);
  if (!spec) {
    reply_error(res, spec.error());
    return;
  }
  cell_task_JobCommand command{};
  command.job_id = bus::borrow(spec->job_id);
  command.kind = spec->kind;
  command.operator_id = bus::borrow(who.user);
  std::lock_guard lock(job_command_mutex_);
  auto reply = job_commands_.call(command, ms(kJobReplyTimeout));
  log::info("command.job", spec->name, {{"user", who.user}, {"job", spec->job_id}});
  if (!reply) {
    reply_json(res, 504, {{"error", fmt::format("{} job '{}': {} (is the task service running?)",
                                                spec->name, spec->job_id,
                                                reply.error().message)}});
    return;
  }
  const auto& status = (*reply)->status;
  if (!status.accepted) {
    reply_json(res, 409,
               {{"error", fmt::format("{} refused: {}", spec->name, bus::str(status.reason))}});
    return;
  }
  audit(who, fmt::format("{} job '{}'", spec->name, spec->job_id), {}, spec->job_id);
  reply_json(res, 200, {{"job_id", spec->job_id}, {"command", spec->name}, {"accepted", true}});
}

void MonitorService::handle_teach(const std::string& action, const httplib::Request& req,
                                  httplib::Response& res) {
  SessionInfo who;
  if (!require_operator(req, res, who)) {
    return;
  }
  auto body = body_json(req, res);
  if (!body) {
    return;
  }
  const json& b = *body;
  auto index = [&](const char* key) -> Result<std::size_t> {
    if (!b.contains(key) || !b[key].is_number_integer() || b[key].get<long long>() < 0) {
      return Error{Errc::kInvalidArgument, fmt::format("field '{}' must be an index >= 0", key)};
    }
    return static_cast<std::size_t>(b[key].get<long long>());
  };
  auto text = [&](const char* key) -> std::string {
    return b.contains(key) && b[key].is_string() ? b[key].get<std::string>() : "";
  };
  auto preview = optional_bool(b, "preview", true);
  if (!preview) {
    reply_error(res, preview.error());
    return;
  }
  Result<json> result = json{{"ok", true}};
  Status status = ok_status();
  if (action == "create") {
    status = teach_->create(text("robot"), text("name"));
  } else if (action == "open") {
    status = teach_->open(text("file"));
  } else if (action == "save") {
    status = teach_->save(text("file"));
  } else if (action == "record") {
    const std::string move = text("move");
    if (!move.empty() && move != "joint" && move != "line") {
      status = Error{Errc::kInvalidArgument, "field 'move' must be joint or line"};
    } else {
      status = teach_->record(text("name"),
                              move == "line" ? teach::MoveKind::kLine : teach::MoveKind::kJoint);
    }
  } else if (action == "gripper") {
    const std::string a = text("action");
    if (a != "open" && a != "close") {
      status = Error{Errc::kInvalidArgument, "field 'action' must be open or close"};
    } else {
      status = teach_->add_gripper(a == "open" ? teach::GripperAction::kOpen
                                               : teach::GripperAction::kClose);
    }
  } else if (action == "wait") {
    auto seconds = number_field(b, "seconds", std::nan(""), 0.0, 3600.0, "s");
    status = !seconds                ? Status(seconds.error())
             : std::isnan(*seconds) ? Status(Error{Errc::kInvalidArgument,
                                                   "field 'seconds' must be a number"})
                                     : teach_->add_wait(*seconds);
  } else if (action == "delete") {
    auto i = index("index");
    status = i ? teach_->remove(*i) : Status(i.error());
  } else if (action == "move") {
    auto from = index("from");
    auto to = index("to");
    status = !from ? Status(from.error()) : !to ? Status(to.error()) : teach_->move(*from, *to);
  } else if (action == "rename") {
    auto i = index("index");
    status = i ? teach_->rename(*i, text("name")) : Status(i.error());
  } else if (action == "seek") {
    auto i = index("position");
    status = i ? teach_->seek(*i) : Status(i.error());
  } else if (action == "step") {
    const std::string d = text("direction");
    if (d != "forward" && d != "backward") {
      status = Error{Errc::kInvalidArgument, "field 'direction' must be forward or backward"};
    } else {
      result = teach_->step(
          d == "forward" ? teach::Direction::kForward : teach::Direction::kBackward, *preview);
    }
  } else if (action == "run") {
    result = teach_->run(*preview);
  } else if (action == "stop") {
    teach_->stop();
  } else {
    reply_json(res, 404, {{"error", fmt::format("no teach action '{}'", action)}});
    return;
  }
  if (!status) {
    reply_error(res, status.error());
    return;
  }
  if (!result) {
    reply_error(res, result.error());
    return;
  }
  log::info("command.teach", action, {{"user", who.user}});
  if (!*preview && (action == "step" || action == "run")) {
    audit(who, fmt::format("teach {} on the robot", action));
  }
  json out = *result;
  out["state"] = teach_->state();
  reply_json(res, 200, out);
}

}  // namespace cell::monitor
