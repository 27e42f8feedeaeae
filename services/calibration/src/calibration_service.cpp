#include "calibration_service.hpp"

#include <fmt/format.h>

#include <chrono>
#include <cstring>
#include <exception>

#include "cell/bus/view.hpp"
#include "cell/bus/waitset.hpp"
#include "cell/common/log.hpp"
#include "cell/common/time.hpp"
#include "cell/service/paths.hpp"

namespace cell::calibration_service {
namespace {

namespace cal = cell::calibration;
using Clock = std::chrono::steady_clock;

bool immediate(cell_calibration_CalibrationProcedure p) {
  return p == cell_calibration_PROCEDURE_LIST || p == cell_calibration_PROCEDURE_SHOW ||
         p == cell_calibration_PROCEDURE_ROLLBACK || p == cell_calibration_PROCEDURE_CANCEL;
}

std::string key_text(const std::string& client, std::uint64_t seq) {
  return fmt::format("{}#{}", client, seq);
}

/// The board a request names, if any. Errors: a malformed one (named).
Result<std::optional<cal::BoardSpec>> board_of(const cell_calibration_BoardTarget& t) {
  const std::string kind(bus::str(t.kind));
  if (kind.empty() && t.columns == 0 && t.rows == 0) {
    return std::optional<cal::BoardSpec>{};
  }
  cal::BoardSpec b;
  if (kind.empty() || kind == "chessboard") {
    b.kind = cal::BoardKind::kChessboard;
  } else if (kind == "charuco") {
    b.kind = cal::BoardKind::kCharuco;
  } else {
    return Error{Errc::kInvalidArgument,
                 fmt::format("target kind must be chessboard or charuco, got '{}'", kind)};
  }
  b.columns = static_cast<int>(std::min<std::uint32_t>(t.columns, 1000));
  b.rows = static_cast<int>(std::min<std::uint32_t>(t.rows, 1000));
  b.square_mm = t.square_mm;
  b.marker_mm = t.marker_mm;
  if (const std::string d(bus::str(t.dictionary)); !d.empty()) {
    b.dictionary = d;
  }
  CELL_TRY(b.validate());
  return std::optional<cal::BoardSpec>(b);
}

}  // namespace

std::string_view procedure_name(const cell_calibration_CalibrationProcedure& field) noexcept {
  switch (bus::raw(field)) {  // any value may come off the wire
    case cell_calibration_PROCEDURE_INTRINSICS:
      return "intrinsics";
    case cell_calibration_PROCEDURE_HAND_EYE:
      return "hand_eye";
    case cell_calibration_PROCEDURE_BELT:
      return "belt";
    case cell_calibration_PROCEDURE_PLANAR:
      return "planar";
    case cell_calibration_PROCEDURE_LIST:
      return "list";
    case cell_calibration_PROCEDURE_SHOW:
      return "show";
    case cell_calibration_PROCEDURE_ROLLBACK:
      return "rollback";
    case cell_calibration_PROCEDURE_CANCEL:
      return "cancel";
  }
  return "unknown";
}

CalibrationService::CalibrationService(service::Context& ctx, const CalibrationConfig& config)
    : ctx_(ctx),
      config_(config),
      store_(service::resolve_path(config.store_dir)),
      request_topic_(ctx.participant(), bus::topics::kCalibrationRequest),
      progress_topic_(ctx.participant(), bus::topics::kCalibrationProgress),
      result_topic_(ctx.participant(), bus::topics::kCalibrationResult),
      camera_topic_(ctx.participant(), bus::topics::kCameraCalibration),
      belt_topic_(ctx.participant(), bus::topics::kBeltCalibration),
      requests_(ctx.participant(), request_topic_, bus::topics::kCalibrationRequest),
      progress_writer_(ctx.participant(), progress_topic_, bus::topics::kCalibrationProgress),
      result_writer_(ctx.participant(), result_topic_, bus::topics::kCalibrationResult),
      camera_writer_(ctx.participant(), camera_topic_, bus::topics::kCameraCalibration),
      belt_writer_(ctx.participant(), belt_topic_, bus::topics::kBeltCalibration),
      link_(std::make_unique<CellLink>(ctx.participant(), config.timeouts, cancel_)) {
  publish_current();
}

CalibrationService::~CalibrationService() {
  cancel_ = true;
  if (worker_.joinable()) {
    worker_.join();
  }
}

cal::CameraCalibration CalibrationService::current_camera(const std::string& id) const {
  if (auto c = store_.current_camera(id); c) {
    return *c;
  }
  const CameraEntry* e = config_.camera(id);
  return e != nullptr ? e->nominal : cal::CameraCalibration{};
}

void CalibrationService::publish_current() {
  for (const CameraEntry& e : config_.cameras) {
    auto stored = store_.current_camera(e.camera.id);
    if (!stored && stored.error().code != Errc::kNotReady) {
      // A stored file that does not load: say so, and fall back to the nominal.
      log::error("store", stored.error().message, {{"camera", e.camera.id}});
      ctx_.events().publish(cell_health_SEVERITY_ERROR, "calibration.store_unreadable",
                            stored.error().message);
    }
    const cal::CameraCalibration& c = stored ? *stored : e.nominal;
    if (auto s = publish_camera(c); !s) {
      log::error("publish", s.error().message, {{"camera", c.camera_id}});
    } else {
      log::info("publish", "camera calibration",
                {{"camera", c.camera_id}, {"version", c.version.empty() ? "nominal" : c.version}});
    }
    if (auto planar = store_.current_camera(e.camera.id + ".planar"); planar) {
      (void)publish_camera(*planar);
    }
  }
  for (const BeltEntry& b : config_.belts) {
    if (auto stored = store_.current_belt(b.belt_id); stored) {
      if (auto s = publish_belt(*stored); !s) {
        log::error("publish", s.error().message, {{"belt", b.belt_id}});
      }
    }
  }
}

Status CalibrationService::publish_camera(const cal::CameraCalibration& c) {
  cal::IdlHolder holder;
  const cell_calibration_CameraCalibration m = cal::to_idl(c, holder, wall_time_ns());
  return camera_writer_.write(m);
}

Status CalibrationService::publish_belt(const cal::BeltCalibration& b) {
  cal::BeltIdlHolder holder;
  const cell_calibration_BeltCalibration m = cal::to_idl(b, holder, wall_time_ns());
  return belt_writer_.write(m);
}

void CalibrationService::progress(const Key& key, cell_calibration_CalibrationProcedure p,
                                  const std::string& device, std::string_view stage,
                                  std::size_t step, std::size_t total, std::string_view message) {
  const std::string stage_s(stage);
  const std::string message_s(message);
  const std::string frame = "calibration";
  cell_calibration_CalibrationProgress m{};
  m.request_id.client_id = bus::borrow(key.client_id);
  m.request_id.seq = key.seq;
  m.header.stamp_ns = wall_time_ns();
  m.header.frame_id = bus::borrow(frame);
  m.procedure = p;
  m.device_id = bus::borrow(device);
  m.stage = bus::borrow(stage_s);
  m.step = static_cast<std::uint32_t>(step);
  m.total = static_cast<std::uint32_t>(total);
  m.message = bus::borrow(message_s);
  if (auto s = progress_writer_.write(m); !s) {
    log::warn("progress", s.error().message);
  }
}

void CalibrationService::result(const Key& key,
                                const cell_calibration_CalibrationProcedure& p,
                                const std::string& device,
                                const Outcome* outcome,
                                const Error* error,
                                const std::string& version,
                                bool stored,
                                double elapsed_s) {
  std::string code;
  std::string reason;
  if (error != nullptr) {
    code = std::string(to_string(error->code));
    reason = error->message;
  }
  std::vector<cell_calibration_ViewResult> views;
  std::vector<std::string> view_ids;
  std::vector<std::string> view_reasons;
  cal::IdlHolder camera_holder;
  cal::BeltIdlHolder belt_holder;
  cell_calibration_CalibrationResult m{};
  if (outcome != nullptr) {
    view_ids.reserve(outcome->views.size());
    view_reasons.reserve(outcome->views.size());
    for (const auto& v : outcome->views) {
      view_ids.push_back(v.id);
      view_reasons.push_back(v.reason);
    }
    for (std::size_t i = 0; i < outcome->views.size(); ++i) {
      cell_calibration_ViewResult r{};
      r.view_id = bus::borrow(view_ids[i]);
      r.used = outcome->views[i].used;
      r.held_out = outcome->views[i].held_out;
      r.rms_px = outcome->views[i].rms_px;
      r.reason = bus::borrow(view_reasons[i]);
      views.push_back(r);
    }
    m.rms_px = outcome->rms_px;
    m.holdout_rms_px = outcome->holdout_rms_px;
    m.holdout_mm = outcome->holdout_mm;
    for (const auto& v : outcome->views) {
      if (v.used) {
        ++m.views_used;
      } else if (!v.held_out) {
        ++m.views_rejected;
      }
    }
    if (outcome->camera) {
      m.has_camera = true;
      m.camera = cal::to_idl(*outcome->camera, camera_holder, wall_time_ns());
    }
    if (outcome->belt) {
      m.has_belt = true;
      m.belt = cal::to_idl(*outcome->belt, belt_holder, wall_time_ns());
    }
  }
  // Unset strings of nested samples must not be null for the serialiser.
  const std::string empty;
  if (!m.has_camera) {
    m.camera.camera_id = bus::borrow(empty);
    m.camera.header.frame_id = bus::borrow(empty);
    m.camera.robot_id = bus::borrow(empty);
    m.camera.version = bus::borrow(empty);
    m.camera.mount_frame = bus::borrow(empty);
    m.camera.source = bus::borrow(empty);
    m.camera.extrinsics.orientation.w = 1.0;
  }
  if (!m.has_belt) {
    m.belt.belt_id = bus::borrow(empty);
    m.belt.header.frame_id = bus::borrow(empty);
    m.belt.robot_id = bus::borrow(empty);
    m.belt.version = bus::borrow(empty);
    m.belt.created_utc = bus::borrow(empty);
    m.belt.source = bus::borrow(empty);
    m.belt.camera_id = bus::borrow(empty);
  }
  m.request_id.client_id = bus::borrow(key.client_id);
  m.request_id.seq = key.seq;
  m.status.accepted = error == nullptr;
  m.status.error_code = bus::borrow(code);
  m.status.reason = bus::borrow(reason);
  std::memcpy(&m.procedure, &p, sizeof p);  // as received (see result's declaration)
  m.device_id = bus::borrow(device);
  m.version = bus::borrow(version);
  m.stored = stored;
  bus::borrow(m.views, views);
  const std::string summary = outcome != nullptr ? outcome->summary : reason;
  const std::string details = outcome != nullptr ? outcome->details : std::string();
  m.summary = bus::borrow(summary);
  m.details = bus::borrow(details);
  m.elapsed_s = elapsed_s;
  if (auto s = result_writer_.write(m); !s) {
    log::error("result", s.error().message);
  }
}

void CalibrationService::run(service::Context& ctx) {
  constexpr dds_attach_t kStop = 1;
  constexpr dds_attach_t kRequest = 2;
  bus::WaitSet waitset(ctx.participant());
  waitset.attach(ctx.stop_guard().get(), kStop);
  waitset.attach(requests_.condition(), kRequest);
  ctx.health().set(cell_health_HEALTH_SERVING);
  for (;;) {
    const bus::Fired fired = waitset.wait(std::chrono::milliseconds(200));
    if (fired.contains(kStop)) {
      break;
    }
    reap_worker();
    if (fired.contains(kRequest)) {
      (void)requests_.take_each(
          [&](const cell_calibration_CalibrationRequest& r, const dds_sample_info_t&) {
            try {
              handle(r);
            } catch (const std::exception& e) {
              const Key key{std::string(bus::str(r.request_id.client_id)), r.request_id.seq};
              const Error err{Errc::kInvalidArgument, std::string("internal error: ") + e.what()};
              log::error("reject", err.message);
              result(key, r.procedure, "", nullptr, &err, "", false, 0.0);
            }
          });
    }
    ctx.health().tick();
  }
  cancel_ = true;
  if (worker_.joinable()) {
    worker_.join();
  }
}

void CalibrationService::reap_worker() {
  if (worker_done_.exchange(false) && worker_.joinable()) {
    worker_.join();
    busy_ = false;
  }
}

void CalibrationService::handle(const cell_calibration_CalibrationRequest& r) {
  const Key key{std::string(bus::str(r.request_id.client_id)), r.request_id.seq};
  const std::string name(procedure_name(r.procedure));
  const std::string device = !std::string(bus::str(r.belt_id)).empty()
                                 ? std::string(bus::str(r.belt_id))
                                 : std::string(bus::str(r.camera_id));
  log::info("request", name, {{"request", key_text(key.client_id, key.seq)}, {"device", device}});
  auto refuse = [&](Errc code, const std::string& why) {
    const Error err{code, why};
    log::warn("reject", why, {{"request", key_text(key.client_id, key.seq)}, {"procedure", name}});
    result(key, r.procedure, device, nullptr, &err, "", false, 0.0);
  };
  if (name == "unknown") {
    refuse(Errc::kInvalidArgument,
           fmt::format("unknown procedure {} (intrinsics, hand_eye, belt, planar, list, show, "
                       "rollback, cancel)",
                       bus::raw(r.procedure)));
    return;
  }
  if (immediate(r.procedure)) {
    answer_now(key, r);
    return;
  }
  if (busy_) {
    std::lock_guard lock(mutex_);
    refuse(Errc::kNotReady, fmt::format("busy: {} is running (cancel it first: cellctl calibration "
                                        "cancel)",
                                        running_));
    return;
  }
  Request req;
  req.procedure = name;
  req.camera_id = std::string(bus::str(r.camera_id));
  req.robot_id = std::string(bus::str(r.robot_id));
  req.belt_id = std::string(bus::str(r.belt_id));
  req.images_dir = std::string(bus::str(r.images_dir));
  req.pose_count = static_cast<int>(std::min<std::uint32_t>(r.pose_count, 1000));
  req.dry_run = r.dry_run;
  auto board = board_of(r.target);
  if (!board) {
    refuse(board.error().code, "target: " + board.error().message);
    return;
  }
  req.board = *board;
  for (const auto& reading : bus::span(r.readings)) {
    req.readings.push_back({reading.j1_rad, reading.j2_rad, {reading.x_mm, reading.y_mm}});
  }
  // What each procedure needs, checked before anything moves.
  if (r.procedure == cell_calibration_PROCEDURE_BELT) {
    if (req.belt_id.empty() || config_.belt_entry(req.belt_id) == nullptr) {
      refuse(Errc::kInvalidArgument, fmt::format("belt: unknown belt '{}'", req.belt_id));
      return;
    }
    if (config_.belt_for(req.belt_id) == nullptr) {
      refuse(Errc::kInvalidArgument,
             fmt::format("belt: no procedure for belt '{}' in the config", req.belt_id));
      return;
    }
  } else if (r.procedure != cell_calibration_PROCEDURE_INTRINSICS || !req.camera_id.empty()) {
    if (config_.camera(req.camera_id) == nullptr) {
      std::string known;
      for (const auto& c : config_.cameras) {
        known += (known.empty() ? "" : ", ") + c.camera.id;
      }
      refuse(Errc::kInvalidArgument,
             fmt::format("{}: unknown camera '{}' (known: {})", name, req.camera_id, known));
      return;
    }
    const bool guided = req.images_dir.empty();
    if (r.procedure == cell_calibration_PROCEDURE_HAND_EYE && guided &&
        config_.hand_eye_for(req.camera_id) == nullptr) {
      refuse(Errc::kInvalidArgument,
             fmt::format("hand_eye: no guided procedure for camera '{}' in the config; give a "
                         "recorded data set (images_dir with poses.yaml)",
                         req.camera_id));
      return;
    }
    if (r.procedure == cell_calibration_PROCEDURE_PLANAR &&
        config_.planar_for(req.camera_id) == nullptr) {
      refuse(Errc::kInvalidArgument,
             fmt::format("planar: no planar procedure for camera '{}' in the config",
                         req.camera_id));
      return;
    }
  }
  start(key, r.procedure, std::move(req));
}

void CalibrationService::start(const Key& key, cell_calibration_CalibrationProcedure p,
                               Request req) {
  reap_worker();
  if (worker_.joinable()) {
    worker_.join();
  }
  {
    std::lock_guard lock(mutex_);
    running_ = fmt::format("{} of '{}' (request {})", req.procedure,
                           req.belt_id.empty() ? req.camera_id : req.belt_id,
                           key_text(key.client_id, key.seq));
  }
  busy_ = true;
  cancel_ = false;
  worker_done_ = false;
  const std::string device = req.belt_id.empty() ? req.camera_id : req.belt_id;
  progress(key, p, device, "accepted", 0, 0, fmt::format("{} of '{}'", req.procedure, device));
  worker_ = std::thread([this, key, p, req = std::move(req)]() mutable {
    work(key, p, std::move(req));
    worker_done_ = true;
  });
}

void CalibrationService::work(Key key, cell_calibration_CalibrationProcedure p, Request req) {
  const auto t0 = Clock::now();
  const std::string device = req.belt_id.empty() ? req.camera_id : req.belt_id;
  auto elapsed = [&]() { return std::chrono::duration<double>(Clock::now() - t0).count(); };
  cal::ProgressFn fn = [&](std::string_view stage, std::size_t step, std::size_t total,
                           std::string_view message) {
    progress(key, p, device, stage, step, total, message);
  };
  Procedures procedures(
      config_, [this](const std::string& id) { return current_camera(id); }, link_.get(), fn,
      cancel_);
  Result<Outcome> outcome = Error{Errc::kInvalidArgument, "not run"};
  try {
    switch (p) {
      case cell_calibration_PROCEDURE_INTRINSICS:
        outcome = procedures.intrinsics(req);
        break;
      case cell_calibration_PROCEDURE_HAND_EYE:
        outcome = procedures.hand_eye(req);
        break;
      case cell_calibration_PROCEDURE_PLANAR:
        outcome = procedures.planar(req);
        break;
      case cell_calibration_PROCEDURE_BELT:
        outcome = procedures.belt(req);
        break;
      default:
        outcome = Error{Errc::kInvalidArgument, "not a procedure"};
        break;
    }
  } catch (const std::exception& e) {
    outcome = Error{Errc::kInvalidArgument, std::string("internal error: ") + e.what()};
  }
  if (!outcome) {
    const Error& err = outcome.error();
    log::warn("failed", err.message,
              {{"request", key_text(key.client_id, key.seq)}, {"procedure", req.procedure},
               {"device", device}});
    ctx_.events().publish(cell_health_SEVERITY_WARNING, "calibration.failed",
                          fmt::format("{} of '{}' failed: {} (the current calibration stays)",
                                      req.procedure, device, err.message));
    result(key, p, device, nullptr, &err, "", false, elapsed());
    return;
  }
  // Store, then publish: a calibration the store could not keep is not made current.
  std::string version;
  bool stored = false;
  if (!req.dry_run && !outcome->device_id.empty()) {
    if (outcome->camera) {
      auto c = store_.add_camera(*outcome->camera, outcome->details);
      if (!c) {
        result(key, p, device, nullptr, &c.error(), "", false, elapsed());
        return;
      }
      outcome->camera = *c;
      version = c->version;
      if (auto s = publish_camera(*c); !s) {
        log::error("publish", s.error().message);
      }
    } else if (outcome->belt) {
      auto b = store_.add_belt(*outcome->belt, outcome->details);
      if (!b) {
        result(key, p, device, nullptr, &b.error(), "", false, elapsed());
        return;
      }
      outcome->belt = *b;
      version = b->version;
      if (auto s = publish_belt(*b); !s) {
        log::error("publish", s.error().message);
      }
    }
    stored = !version.empty();
  }
  log::info("done", outcome->summary,
            {{"request", key_text(key.client_id, key.seq)}, {"procedure", req.procedure},
             {"device", outcome->device_id}, {"version", version}});
  result(key, p, outcome->device_id.empty() ? device : outcome->device_id, &*outcome, nullptr,
         version, stored, elapsed());
}

void CalibrationService::answer_now(const Key& key, const cell_calibration_CalibrationRequest& r) {
  const std::string camera_id(bus::str(r.camera_id));
  const std::string belt_id(bus::str(r.belt_id));
  const std::string version(bus::str(r.version));
  const std::string device = belt_id.empty() ? camera_id : belt_id;
  const cal::DeviceKind kind = belt_id.empty() ? cal::DeviceKind::kCamera : cal::DeviceKind::kBelt;
  auto fail = [&](const Error& e) { result(key, r.procedure, device, nullptr, &e, "", false, 0.0); };
  switch (r.procedure) {
    case cell_calibration_PROCEDURE_CANCEL: {
      if (!busy_) {
        fail(Error{Errc::kNotReady, "nothing is running"});
        return;
      }
      cancel_ = true;
      Outcome o;
      {
        std::lock_guard lock(mutex_);
        o.summary = "cancelling " + running_;
      }
      result(key, r.procedure, device, &o, nullptr, "", false, 0.0);
      return;
    }
    case cell_calibration_PROCEDURE_LIST: {
      auto all = store_.list(device.empty() ? std::nullopt : std::optional<cal::DeviceKind>(kind),
                             device);
      if (!all) {
        fail(all.error());
        return;
      }
      // The versions travel in the result's `versions` sequence.
      std::vector<cell_calibration_CalibrationVersion> versions;
      std::vector<std::array<std::string, 4>> strings;
      strings.reserve(all->size());
      for (const auto& v : *all) {
        strings.push_back({v.device_id, std::string(cal::to_string(v.kind)), v.version,
                           v.created_utc});
      }
      std::vector<std::string> sources;
      sources.reserve(all->size());
      for (std::size_t i = 0; i < all->size(); ++i) {
        const auto& v = (*all)[i];
        sources.push_back(v.source);
        cell_calibration_CalibrationVersion m{};
        m.device_id = bus::borrow(strings[i][0]);
        m.kind = bus::borrow(strings[i][1]);
        m.version = bus::borrow(strings[i][2]);
        m.created_utc = bus::borrow(strings[i][3]);
        m.source = bus::borrow(sources[i]);
        m.current = v.current;
        m.rms_px = v.rms_px;
        m.holdout_rms_px = v.holdout_rms_px;
        m.holdout_mm = v.holdout_mm;
        versions.push_back(m);
      }
      // Reuse the writer path: build the result by hand (versions are list-only).
      const std::string empty;
      const std::string summary = fmt::format("{} stored calibration versions in {}",
                                              all->size(), store_.directory());
      cell_calibration_CalibrationResult m{};
      m.request_id.client_id = bus::borrow(key.client_id);
      m.request_id.seq = key.seq;
      m.status.accepted = true;
      m.status.error_code = bus::borrow(empty);
      m.status.reason = bus::borrow(empty);
      m.procedure = r.procedure;
      m.device_id = bus::borrow(device);
      m.version = bus::borrow(empty);
      m.camera.camera_id = bus::borrow(empty);
      m.camera.header.frame_id = bus::borrow(empty);
      m.camera.robot_id = bus::borrow(empty);
      m.camera.version = bus::borrow(empty);
      m.camera.mount_frame = bus::borrow(empty);
      m.camera.source = bus::borrow(empty);
      m.camera.extrinsics.orientation.w = 1.0;
      m.belt.belt_id = bus::borrow(empty);
      m.belt.header.frame_id = bus::borrow(empty);
      m.belt.robot_id = bus::borrow(empty);
      m.belt.version = bus::borrow(empty);
      m.belt.created_utc = bus::borrow(empty);
      m.belt.source = bus::borrow(empty);
      m.belt.camera_id = bus::borrow(empty);
      bus::borrow(m.versions, versions);
      m.summary = bus::borrow(summary);
      m.details = bus::borrow(empty);
      if (auto s = result_writer_.write(m); !s) {
        log::error("result", s.error().message);
      }
      return;
    }
    case cell_calibration_PROCEDURE_SHOW: {
      if (device.empty()) {
        fail(Error{Errc::kInvalidArgument, "show: name a camera_id or a belt_id"});
        return;
      }
      Outcome o;
      o.device_id = device;
      std::string shown_version;
      if (kind == cal::DeviceKind::kBelt) {
        auto b = version.empty() ? store_.current_belt(device) : store_.belt(device, version);
        if (!b) {
          fail(b.error());
          return;
        }
        o.belt = *b;
        shown_version = b->version;
        o.summary = fmt::format("belt '{}' {}: {:.8f} mm/count, direction ({:.6f}, {:.6f}, "
                                "{:.6f}); {}",
                                device, b->version, b->mm_per_count, b->direction.x(),
                                b->direction.y(), b->direction.z(), b->source);
      } else {
        const bool known = config_.camera(device) != nullptr ||
                           (device.size() > 7 && device.ends_with(".planar"));
        if (!known) {
          fail(Error{Errc::kInvalidArgument, fmt::format("show: unknown camera '{}'", device)});
          return;
        }
        Result<cal::CameraCalibration> c =
            version.empty() ? store_.current_camera(device) : store_.camera(device, version);
        if (!c && version.empty() && c.error().code == Errc::kNotReady &&
            config_.camera(device) != nullptr) {
          c = config_.camera(device)->nominal;  // nothing stored yet: what is published
        }
        if (!c) {
          fail(c.error());
          return;
        }
        o.camera = *c;
        shown_version = c->version;
        o.summary = fmt::format("camera '{}' {}: {}", device,
                                c->version.empty() ? "(nominal)" : c->version, c->source);
      }
      result(key, r.procedure, device, &o, nullptr, shown_version, !shown_version.empty(), 0.0);
      return;
    }
    case cell_calibration_PROCEDURE_ROLLBACK: {
      if (device.empty() || version.empty()) {
        fail(Error{Errc::kInvalidArgument, "rollback: name the device and the version"});
        return;
      }
      if (busy_) {
        std::lock_guard lock(mutex_);
        fail(Error{Errc::kNotReady, "busy: " + running_});
        return;
      }
      auto v = store_.rollback(kind, device, version);
      if (!v) {
        fail(v.error());
        return;
      }
      Outcome o;
      o.device_id = device;
      if (kind == cal::DeviceKind::kBelt) {
        auto b = store_.current_belt(device);
        if (!b) {
          fail(b.error());
          return;
        }
        (void)publish_belt(*b);
        o.belt = *b;
      } else {
        auto c = store_.current_camera(device);
        if (!c) {
          fail(c.error());
          return;
        }
        (void)publish_camera(*c);
        o.camera = *c;
      }
      o.summary = fmt::format("{} '{}' is back at {}", cal::to_string(kind), device, v->version);
      log::info("rollback", o.summary);
      result(key, r.procedure, device, &o, nullptr, v->version, true, 0.0);
      return;
    }
    default:
      return;
  }
}

}  // namespace cell::calibration_service
