#include "cell/calibration/belt_calibration.hpp"

#include <algorithm>
#include <array>
#include <cerrno>
#include <cmath>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <map>
#include <numbers>
#include <set>

#include <fmt/format.h>
#include <yaml-cpp/yaml.h>

#include "cell/bus/view.hpp"
#include "cell/config/yaml.hpp"
#include "file_util.hpp"

namespace cell::calibration {
namespace {

using detail::exact_number;

Error invalid_belt(const std::string& belt_id, const std::string& what) {
  return Error{Errc::kInvalidArgument, fmt::format("belt calibration '{}': {}", belt_id, what)};
}

Result<BeltCalibration> parse_belt_document(const config::Document& doc) {
  BeltCalibration b;
  config::MapReader r(doc, doc.root, "");
  r.required("belt_id", b.belt_id);
  r.required("robot_id", b.robot_id);
  r.optional("camera_id", b.camera_id);
  r.optional("version", b.version);
  r.optional("created_utc", b.created_utc);
  r.optional("source", b.source);
  r.required("mm_per_count", b.mm_per_count);
  std::array<double, 3> d{};
  std::array<double, 3> o{};
  r.required("direction", d);
  r.required("origin_mm", o);
  b.direction = Eigen::Vector3d(d[0], d[1], d[2]);
  b.origin_mm = Eigen::Vector3d(o[0], o[1], o[2]);
  if (r.has("quality")) {
    config::MapReader q = r.child("quality", false);
    q.optional("rms_mm", b.rms_mm);
    q.optional("holdout_mm", b.holdout_mm);
    q.optional("sample_count", b.sample_count);
    r.absorb(q);
  }
  CELL_TRY(r.finish());
  if (auto s = b.validate(); !s) {
    return Error{Errc::kConfig, doc.path + ": " + s.error().message};
  }
  return b;
}

}  // namespace

Status BeltCalibration::validate() const {
  if (belt_id.empty()) {
    return Error{Errc::kInvalidArgument, "belt calibration: belt_id is empty"};
  }
  if (robot_id.empty()) {
    return invalid_belt(belt_id, "robot_id is empty (the robot whose base frame it refers to)");
  }
  if (!std::isfinite(mm_per_count) || !(mm_per_count > 0.0)) {
    return invalid_belt(belt_id, fmt::format("mm_per_count must be > 0, got {}", mm_per_count));
  }
  if (!direction.allFinite() || std::abs(direction.norm() - 1.0) > 1e-6) {
    return invalid_belt(belt_id, fmt::format("direction must be a unit vector, got length {}",
                                        direction.norm()));
  }
  if (!origin_mm.allFinite()) {
    return invalid_belt(belt_id, "origin_mm is not finite");
  }
  return ok_status();
}

Eigen::Vector3d BeltCalibration::advance(const Eigen::Vector3d& p, std::int64_t count_then,
                                         std::int64_t count_now) const {
  return p + static_cast<double>(count_now - count_then) * mm_per_count * direction;
}

Result<BeltCalibration> load_belt_calibration(const std::string& path) {
  auto doc = config::load_file(path);
  if (!doc) {
    return std::move(doc).error();
  }
  return parse_belt_document(*doc);
}

Result<BeltCalibration> parse_belt_calibration(const std::string& text, const std::string& origin) {
  auto doc = config::load_string(text, origin);
  if (!doc) {
    return std::move(doc).error();
  }
  return parse_belt_document(*doc);
}

std::string format_belt_calibration(const BeltCalibration& calibration) {
  std::string out;
  out += "# A belt calibration (core/calibration/README.md: keys, frames and units).\n";
  out += fmt::format("belt_id: {}\n", YAML::Dump(YAML::Node(calibration.belt_id)));
  out += fmt::format("robot_id: {}\n", YAML::Dump(YAML::Node(calibration.robot_id)));
  out += fmt::format("camera_id: {}\n", YAML::Dump(YAML::Node(calibration.camera_id)));
  out += fmt::format("version: {}\n", YAML::Dump(YAML::Node(calibration.version)));
  out += fmt::format("created_utc: {}\n", YAML::Dump(YAML::Node(calibration.created_utc)));
  out += fmt::format("source: {}\n", YAML::Dump(YAML::Node(calibration.source)));
  out += fmt::format("mm_per_count: {}\n", exact_number(calibration.mm_per_count));
  out +=
      fmt::format("direction: [{}, {}, {}]   # unit, base frame, for rising counts\n",
                  exact_number(calibration.direction.x()), exact_number(calibration.direction.y()),
                  exact_number(calibration.direction.z()));
  out +=
      fmt::format("origin_mm: [{}, {}, {}]   # the reference part at count 0, base frame\n",
                  exact_number(calibration.origin_mm.x()), exact_number(calibration.origin_mm.y()),
                  exact_number(calibration.origin_mm.z()));
  out += fmt::format("quality:\n  rms_mm: {}\n  holdout_mm: {}\n  sample_count: {}\n",
                     exact_number(calibration.rms_mm), exact_number(calibration.holdout_mm),
                     calibration.sample_count);
  return out;
}

Status save_belt_calibration(const BeltCalibration& calibration, const std::string& path) {
  CELL_TRY(calibration.validate());
  return detail::write_atomically(path, format_belt_calibration(calibration));
}

cell_calibration_BeltCalibration to_idl(const BeltCalibration& calibration,
                                        BeltIdlHolder& holder,
                                        std::int64_t stamp_ns) {
  holder.frame_id = calibration.robot_id + "/base";
  cell_calibration_BeltCalibration m{};
  m.belt_id = bus::borrow(calibration.belt_id);
  m.header.stamp_ns = stamp_ns;
  m.header.frame_id = bus::borrow(holder.frame_id);
  m.robot_id = bus::borrow(calibration.robot_id);
  m.mm_per_count = calibration.mm_per_count;
  m.direction = {calibration.direction.x(), calibration.direction.y(), calibration.direction.z()};
  m.origin_mm = {calibration.origin_mm.x(), calibration.origin_mm.y(), calibration.origin_mm.z()};
  m.rms_mm = calibration.rms_mm;
  m.sample_count = calibration.sample_count;
  m.version = bus::borrow(calibration.version);
  m.created_utc = bus::borrow(calibration.created_utc);
  m.source = bus::borrow(calibration.source);
  m.holdout_mm = calibration.holdout_mm;
  m.camera_id = bus::borrow(calibration.camera_id);
  return m;
}

Result<BeltCalibration> from_idl(const cell_calibration_BeltCalibration& sample) {
  BeltCalibration b;
  b.belt_id = std::string(bus::str(sample.belt_id));
  b.robot_id = std::string(bus::str(sample.robot_id));
  b.mm_per_count = sample.mm_per_count;
  b.direction = Eigen::Vector3d(sample.direction.x, sample.direction.y, sample.direction.z);
  b.origin_mm = Eigen::Vector3d(sample.origin_mm.x, sample.origin_mm.y, sample.origin_mm.z);
  b.rms_mm = sample.rms_mm;
  b.sample_count = sample.sample_count;
  b.version = std::string(bus::str(sample.version));
  b.created_utc = std::string(bus::str(sample.created_utc));
  b.source = std::string(bus::str(sample.source));
  b.holdout_mm = sample.holdout_mm;
  b.camera_id = std::string(bus::str(sample.camera_id));
  CELL_TRY(b.validate());
  return b;
}

Status BeltOptions::validate() const {
  if (!(min_travel_mm > 0.0) || min_samples_per_part < 2 ||
      !(holdout_fraction >= 0.0 && holdout_fraction < 0.5) || !(outlier_mm > 0.0)) {
    return Error{Errc::kInvalidArgument,
                 fmt::format("belt options: min_travel_mm > 0 ({}), min_samples_per_part >= 2 "
                             "({}), holdout_fraction in [0, 0.5) ({}), outlier_mm > 0 ({})",
                             min_travel_mm, min_samples_per_part, holdout_fraction, outlier_mm)};
  }
  return ok_status();
}

std::string BeltReport::brief() const {
  const BeltCalibration& b = calibration;
  return fmt::format(
      "{} mm/count {:.8f}, direction ({:.6f}, {:.6f}, {:.6f}) in {}'s base ({:.3f} deg out of its "
      "xy plane); RMS {:.4f} mm, hold-out {:.4f} mm, {} samples of {} parts over {:.1f} mm",
      b.belt_id, b.mm_per_count, b.direction.x(), b.direction.y(), b.direction.z(), b.robot_id,
      elevation_deg, b.rms_mm, b.holdout_mm, b.sample_count, parts, travel_mm);
}

Result<BeltReport> calibrate_belt(const std::vector<BeltObservation>& samples,
                                  const std::string& belt_id, const std::string& robot_id,
                                  const BeltOptions& options) {
  CELL_TRY(options.validate());
  if (belt_id.empty() || robot_id.empty()) {
    return Error{Errc::kInvalidArgument, "belt calibration needs a belt id and a robot id"};
  }
  BeltReport report;
  report.samples.resize(samples.size());
  std::map<std::string, std::vector<std::size_t>> by_part;
  std::set<std::string> ids;
  for (std::size_t i = 0; i < samples.size(); ++i) {
    ViewReport& r = report.samples[i];
    r.id = samples[i].id;
    r.stamp_ns = samples[i].stamp_ns;
    if (!ids.insert(samples[i].id).second) {
      r.reason = fmt::format("sample id '{}' used twice", samples[i].id);
    } else if (!samples[i].position_mm.allFinite()) {
      r.reason = "its position is not finite";
    } else {
      by_part[samples[i].part].push_back(i);
    }
  }
  // Per part: the first two samples always fit; every k-th further one is held out.
  std::vector<std::vector<std::size_t>> fit_parts;
  std::vector<std::vector<std::size_t>> hold_parts;
  double travel = 0.0;
  for (auto& [part, idx] : by_part) {
    if (static_cast<int>(idx.size()) < options.min_samples_per_part) {
      for (const std::size_t i : idx) {
        report.samples[i].reason =
            fmt::format("part '{}' was located {} times, {} needed", part, idx.size(),
                        options.min_samples_per_part);
      }
      continue;
    }
    std::sort(idx.begin(), idx.end(), [&](std::size_t a, std::size_t b) {
      return samples[a].encoder_count < samples[b].encoder_count;
    });
    std::vector<std::size_t> fit;
    std::vector<std::size_t> hold;
    const std::size_t every =
        options.holdout_fraction > 0.0
            ? std::max<std::size_t>(2, static_cast<std::size_t>(std::lround(1.0 / options.holdout_fraction)))
            : idx.size() + 1;
    for (std::size_t k = 0; k < idx.size(); ++k) {
      // Hold out interior samples only, so the fit spans the part's whole travel.
      const bool out = k > 0 && k + 1 < idx.size() && (k % every) == every / 2 && idx.size() > 3;
      (out ? hold : fit).push_back(idx[k]);
    }
    travel = std::max(travel, (samples[idx.back()].position_mm - samples[idx.front()].position_mm).norm());
    fit_parts.push_back(fit);
    hold_parts.push_back(hold);
  }
  if (fit_parts.empty()) {
    return Error{Errc::kInvalidArgument,
                 fmt::format("belt '{}': no part was located {} times or more ({} samples of {} "
                             "parts)",
                             belt_id, options.min_samples_per_part, samples.size(), by_part.size())};
  }
  // v from the centred samples of every part: sum dc dp / sum dc^2.
  auto fit_v = [&](const std::vector<std::vector<std::size_t>>& parts, Eigen::Vector3d& v,
                   std::vector<Eigen::Vector3d>& a) -> Status {
    Eigen::Vector3d num_v = Eigen::Vector3d::Zero();
    double den = 0.0;
    std::vector<std::pair<double, Eigen::Vector3d>> means;
    for (const auto& idx : parts) {
      double mc = 0.0;
      Eigen::Vector3d mp = Eigen::Vector3d::Zero();
      for (const std::size_t i : idx) {
        mc += static_cast<double>(samples[i].encoder_count);
        mp += samples[i].position_mm;
      }
      mc /= static_cast<double>(idx.size());
      mp /= static_cast<double>(idx.size());
      means.emplace_back(mc, mp);
      for (const std::size_t i : idx) {
        const double dc = static_cast<double>(samples[i].encoder_count) - mc;
        num_v += dc * (samples[i].position_mm - mp);
        den += dc * dc;
      }
    }
    if (den <= 0.0) {
      return Error{Errc::kInvalidArgument,
                   fmt::format("belt '{}' did not move: every sample of a part has the same "
                               "encoder count",
                               belt_id)};
    }
    v = num_v / den;
    a.clear();
    for (const auto& [mc, mp] : means) {
      a.push_back(mp - mc * v);
    }
    return ok_status();
  };
  Eigen::Vector3d v;
  std::vector<Eigen::Vector3d> a;
  CELL_TRY(fit_v(fit_parts, v, a));
  if (travel < options.min_travel_mm) {
    return Error{Errc::kInvalidArgument,
                 fmt::format("belt '{}' moved the part only {:.1f} mm between its samples, at "
                             "least {} mm needed",
                             belt_id, travel, options.min_travel_mm)};
  }
  // Outliers (a wrong part located, a count latched late) out, once.
  bool dropped = false;
  for (std::size_t p = 0; p < fit_parts.size(); ++p) {
    std::vector<std::size_t> kept;
    for (const std::size_t i : fit_parts[p]) {
      const double e = (samples[i].position_mm -
                        (a[p] + static_cast<double>(samples[i].encoder_count) * v))
                           .norm();
      if (e > options.outlier_mm) {
        report.samples[i].reason =
            fmt::format("outlier: {:.3f} mm from the fitted line (limit {} mm)", e, options.outlier_mm);
        report.samples[i].rms_px = e;
        dropped = true;
      } else {
        kept.push_back(i);
      }
    }
    fit_parts[p] = kept;
  }
  if (dropped) {
    fit_parts.erase(std::remove_if(fit_parts.begin(), fit_parts.end(),
                                   [](const auto& f) { return f.size() < 2; }),
                    fit_parts.end());
    if (fit_parts.empty()) {
      return Error{Errc::kInvalidArgument,
                   fmt::format("belt '{}': after removing outliers no part has two samples", belt_id)};
    }
    CELL_TRY(fit_v(fit_parts, v, a));
  }
  const double scale = v.norm();
  if (!(scale > 0.0) || !v.allFinite()) {
    return Error{Errc::kInvalidArgument, fmt::format("belt '{}' did not move", belt_id)};
  }
  BeltCalibration& b = report.calibration;
  b.belt_id = belt_id;
  b.robot_id = robot_id;
  b.mm_per_count = scale;
  b.direction = v / scale;
  b.origin_mm = a.front();
  double sum = 0.0;
  std::size_t n = 0;
  for (std::size_t p = 0; p < fit_parts.size(); ++p) {
    for (const std::size_t i : fit_parts[p]) {
      const double e =
          (samples[i].position_mm - (a[p] + static_cast<double>(samples[i].encoder_count) * v))
              .norm();
      report.samples[i].used = true;
      report.samples[i].rms_px = e;
      sum += e * e;
      ++n;
    }
  }
  b.rms_mm = std::sqrt(sum / static_cast<double>(n));
  b.sample_count = static_cast<std::uint32_t>(n);
  // Hold-out: each held-out sample predicted from its part's first fitted sample.
  double hold = 0.0;
  std::size_t hold_n = 0;
  for (std::size_t p = 0; p < hold_parts.size(); ++p) {
    for (const std::size_t i : hold_parts[p]) {
      // The fitted part with the same key (parts removed as outliers have no prediction).
      const auto it = std::find_if(fit_parts.begin(), fit_parts.end(), [&](const auto& f) {
        return !f.empty() && samples[f.front()].part == samples[i].part;
      });
      if (it == fit_parts.end()) {
        report.samples[i].reason = "held out, but its part has no fit";
        continue;
      }
      const std::size_t ref = it->front();
      const Eigen::Vector3d predicted =
          b.advance(samples[ref].position_mm, samples[ref].encoder_count, samples[i].encoder_count);
      const double e = (predicted - samples[i].position_mm).norm();
      report.samples[i].held_out = true;
      report.samples[i].rms_px = e;
      hold += e * e;
      ++hold_n;
    }
  }
  b.holdout_mm = hold_n > 0 ? std::sqrt(hold / static_cast<double>(hold_n)) : 0.0;
  report.travel_mm = travel;
  report.parts = static_cast<int>(fit_parts.size());
  report.elevation_deg =
      std::asin(std::clamp(b.direction.z(), -1.0, 1.0)) * 180.0 / std::numbers::pi;
  return report;
}

geometry::Pose2 part_location(const geometry::Pose2& to_cam, const geometry::Pose2& vis_loc,
                              const geometry::Pose2& grip_part, const BeltCalibration& belt,
                              std::int64_t count_image, std::int64_t count_now) {
  geometry::Pose2 loc = to_cam * vis_loc * grip_part;
  const Eigen::Vector3d shift =
      static_cast<double>(count_now - count_image) * belt.mm_per_count * belt.direction;
  loc.x += shift.x();
  loc.y += shift.y();
  return loc;
}

}  // namespace cell::calibration
