#include "camera_config.hpp"

#include <cmath>

#include <fmt/format.h>

#include "cell/service/paths.hpp"

namespace cell::camera {

std::string_view to_string(SourceKind kind) noexcept {
  switch (kind) {
    case SourceKind::kSim:
      return "sim";
    case SourceKind::kFiles:
      return "files";
    case SourceKind::kDevice:
      return "device";
  }
  return "unknown";
}

Result<CameraConfig> load_config(const config::Document& doc) {
  CameraConfig c;
  config::MapReader root(doc, doc.root, "");
  service::read_common(root, c.common);
  root.required("camera_id", c.camera_id);
  if (c.common.service_id.empty() && !c.camera_id.empty()) {
    c.common.service_id = "camera." + c.camera_id;
  }
  std::string source = "sim";
  root.optional("source", source);
  if (source == "sim") {
    c.source = SourceKind::kSim;
  } else if (source == "files") {
    c.source = SourceKind::kFiles;
  } else if (source == "device") {
    c.source = SourceKind::kDevice;
  } else {
    root.fail("source", fmt::format("must be sim, files or device, got '{}'", source));
  }
  root.optional("camera_file", c.camera_file);
  if (c.source == SourceKind::kSim && c.camera_file.empty()) {
    root.fail("camera_file", "a sim camera needs its camera file (config/cameras/<id>.yaml)");
  }
  config::MapReader sim = root.child("sim", false);
  sim.optional("noise_sigma", c.sim.noise_sigma);
  std::int64_t seed = 1;
  sim.optional("seed", seed);
  c.sim.seed = static_cast<std::uint64_t>(seed);
  sim.optional("gain", c.sim.gain);
  sim.optional("exposure_s", c.sim.exposure_s);
  sim.optional("robot_config", c.sim.robot_config);
  if (!(std::isfinite(c.sim.noise_sigma) && c.sim.noise_sigma >= 0 && c.sim.noise_sigma <= 64)) {
    sim.fail("noise_sigma", fmt::format("must be in [0, 64] grey levels, got {}", c.sim.noise_sigma));
  }
  if (!(std::isfinite(c.sim.gain) && c.sim.gain > 0 && c.sim.gain <= 100)) {
    sim.fail("gain", fmt::format("must be in (0, 100], got {}", c.sim.gain));
  }
  if (sim.has("exposure_s") && !(c.sim.exposure_s >= 0 && c.sim.exposure_s <= 10)) {
    sim.fail("exposure_s", fmt::format("must be in [0, 10] s, got {}", c.sim.exposure_s));
  }
  root.absorb(sim);
  config::MapReader files = root.child("files", false);
  files.optional("directory", c.files.directory);
  files.optional("loop", c.files.loop);
  if (c.source == SourceKind::kFiles && c.files.directory.empty()) {
    files.fail("directory", "a files camera needs the directory of its images");
  }
  root.absorb(files);
  config::MapReader device = root.child("device", false);
  device.optional("index", c.device.index);
  device.optional("path", c.device.path);
  if (c.source == SourceKind::kDevice && c.device.path.empty() && c.device.index < 0) {
    device.fail("", "a device camera needs `index` (>= 0) or `path`");
  }
  root.absorb(device);
  config::MapReader trigger = root.child("trigger", false);
  std::string mode = "request";
  trigger.optional("mode", mode);
  if (mode == "request") {
    c.trigger.mode = TriggerMode::kRequest;
  } else if (mode == "free") {
    c.trigger.mode = TriggerMode::kFree;
  } else if (mode == "photocell") {
    c.trigger.mode = TriggerMode::kPhotocell;
  } else {
    trigger.fail("mode", fmt::format("must be request, free or photocell, got '{}'", mode));
  }
  trigger.optional("rate_hz", c.trigger.rate_hz);
  std::string edge = "leave";
  trigger.optional("photocell_edge", edge);
  if (edge == "leave" || edge == "enter") {
    c.trigger.on_leave = edge == "leave";
  } else {
    trigger.fail("photocell_edge", fmt::format("must be leave or enter, got '{}'", edge));
  }
  trigger.optional("delay_s", c.trigger.delay_s);
  trigger.optional("delay_mm", c.trigger.delay_mm);
  trigger.optional("photocell_timeout_s", c.trigger.photocell_timeout_s);
  if (!(std::isfinite(c.trigger.rate_hz) && c.trigger.rate_hz > 0 && c.trigger.rate_hz <= 200)) {
    trigger.fail("rate_hz", fmt::format("must be in (0, 200], got {}", c.trigger.rate_hz));
  }
  if (!(c.trigger.delay_s >= 0 && c.trigger.delay_s <= 60)) {
    trigger.fail("delay_s", fmt::format("must be in [0, 60] s, got {}", c.trigger.delay_s));
  }
  if (!(c.trigger.delay_mm >= 0 && c.trigger.delay_mm <= 10000)) {
    trigger.fail("delay_mm", fmt::format("must be in [0, 10000] mm, got {}", c.trigger.delay_mm));
  }
  if (c.trigger.delay_s > 0 && c.trigger.delay_mm > 0) {
    trigger.fail("delay_mm", "give delay_s or delay_mm, not both");
  }
  if (!(c.trigger.photocell_timeout_s > 0 && c.trigger.photocell_timeout_s <= 3600)) {
    trigger.fail("photocell_timeout_s",
                 fmt::format("must be in (0, 3600] s, got {}", c.trigger.photocell_timeout_s));
  }
  root.absorb(trigger);
  root.optional("belt_id", c.belt_id);
  if (c.trigger.mode == TriggerMode::kPhotocell && c.belt_id.empty()) {
    root.fail("belt_id", "a photocell-triggered camera needs the belt whose photocell fires it");
  }
  root.optional("robot_id", c.robot_id);
  root.optional("robot_state_timeout_s", c.robot_state_timeout_s);
  root.optional("world_state_timeout_s", c.world_state_timeout_s);
  root.optional("preview_hz", c.preview_hz);
  if (!(c.preview_hz >= 0.0 && c.preview_hz <= 100.0)) {
    root.fail("preview_hz", fmt::format("must be in [0, 100] (0: no previews), got {}",
                                        c.preview_hz));
  }
  root.optional("refuse_unknown_cameras", c.refuse_unknown_cameras);
  for (const auto& [key, value] : {std::pair{"robot_state_timeout_s", c.robot_state_timeout_s},
                                   std::pair{"world_state_timeout_s", c.world_state_timeout_s}}) {
    if (!(value > 0 && value <= 60)) {
      root.fail(key, fmt::format("must be in (0, 60] s, got {}", value));
    }
  }
  CELL_TRY(root.finish());
  if (!c.camera_file.empty()) {
    c.camera_file = service::resolve_path(c.camera_file);
  }
  if (!c.sim.robot_config.empty()) {
    c.sim.robot_config = service::resolve_path(c.sim.robot_config);
  }
  if (!c.files.directory.empty()) {
    c.files.directory = service::resolve_path(c.files.directory);
  }
  return c;
}

}  // namespace cell::camera
