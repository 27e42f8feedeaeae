#include "cell/protocols/excalibur/controller_model.hpp"

#include <fmt/format.h>

#include <algorithm>
#include <cmath>

namespace cell::protocols::excalibur {
namespace {

constexpr double kInf = std::numeric_limits<double>::infinity();
/// The controller re-tries a move that settled outside its tolerance after this long.
constexpr double kResettleS = 0.1;

double smoothstep(double u) noexcept {
  u = std::clamp(u, 0.0, 1.0);
  return u * u * (3.0 - 2.0 * u);
}

}  // namespace

Status ControllerSettings::validate() const {
  const auto bad = [](std::string what) { return Error{Errc::kInvalidArgument, std::move(what)}; };
  for (std::size_t j = 0; j < kJointCount; ++j) {
    if (!(lower_deg[j] < upper_deg[j])) {
      return bad(fmt::format("joint {}: lower limit {} deg must be below upper limit {} deg", j + 1,
                             lower_deg[j], upper_deg[j]));
    }
    if (!(speed_deg_s[j] > 0) || !std::isfinite(speed_deg_s[j])) {
      return bad(fmt::format("joint {}: speed must be > 0 deg/s, got {}", j + 1, speed_deg_s[j]));
    }
    if (!std::isfinite(initial_deg[j]) || !std::isfinite(master_deg[j])) {
      return bad(fmt::format("joint {}: initial and master angles must be finite", j + 1));
    }
  }
  if (!(accuracy_deg >= 0 && accuracy_deg < 10)) {
    return bad(fmt::format("accuracy must be in [0, 10) deg, got {}", accuracy_deg));
  }
  if (!(min_char_interval_s >= 0 && min_char_interval_s < 1) ||
      !(busy_after_line_s >= 0 && busy_after_line_s < 10) ||
      !(reply_delay_s >= 0 && reply_delay_s < 10)) {
    return bad("min_char_interval_s, busy_after_line_s and reply_delay_s must be >= 0 and small");
  }
  if (!(gripper_time_s >= 0 && gripper_time_s <= 10)) {
    return bad(fmt::format("gripper time must be in [0, 10] s, got {}", gripper_time_s));
  }
  if (!(move_not_achieved_probability >= 0 && move_not_achieved_probability <= 1)) {
    return bad(fmt::format("move-not-achieved probability must be in [0, 1], got {}",
                           move_not_achieved_probability));
  }
  if (!(teach_rate_hz > 0 && teach_rate_hz <= 1000) || teach_capacity == 0) {
    return bad("teach rate must be in (0, 1000] Hz and teach capacity > 0");
  }
  return ok_status();
}

ControllerModel::ControllerModel(Dialect dialect, ControllerSettings settings, double now_s)
    : dialect_(std::move(dialect)),
      settings_(settings),
      rng_(settings_.seed),
      noise_in_(settings_.seed * 7919 + 1),
      noise_out_(settings_.seed * 104729 + 2) {
  mode_ = settings_.power_up_mode;
  tolerance_deg_ = dialect_.defaults().tolerance_deg;
  timeout_s_ = dialect_.defaults().timeout_s;
  segment_ = Segment{settings_.initial_deg, settings_.initial_deg, now_s, 0.0};
  target_ = settings_.initial_deg;
  last_advance_s_ = now_s;
  line_.reserve(dialect_.framing().max_line_chars + 1);
  if (mode_ == Mode::kManual || mode_ == Mode::kTeach) {
    start_segment(settings_.master_deg, now_s);
  }
  send_unsolicited(Message{MessageKind::kReady, {}, 0}, now_s);
}

void ControllerModel::set_noise(const NoiseSettings& noise) noexcept {
  noise_in_.set(noise);
  noise_out_.set(noise);
}

void ControllerModel::set_move_not_achieved_probability(double p) noexcept {
  settings_.move_not_achieved_probability = std::clamp(p, 0.0, 1.0);
}

void ControllerModel::set_reply_delay(double seconds) noexcept {
  settings_.reply_delay_s = std::clamp(seconds, 0.0, 9.999);
}

// --- motion ----------------------------------------------------------------------------------

ControllerAngles ControllerModel::position(const Segment& s, double t) noexcept {
  if (s.duration <= 0.0 || t >= s.t0 + s.duration) {
    return s.to;
  }
  const double k = smoothstep((t - s.t0) / s.duration);
  ControllerAngles q{};
  for (std::size_t j = 0; j < kJointCount; ++j) {
    q[j] = s.from[j] + (s.to[j] - s.from[j]) * k;
  }
  return q;
}

ControllerAngles ControllerModel::angles(double now_s) const noexcept {
  return position(segment_, now_s);
}

void ControllerModel::start_segment(const ControllerAngles& to, double now) {
  const ControllerAngles from = position(segment_, now);
  double duration = 0.0;
  for (std::size_t j = 0; j < kJointCount; ++j) {
    // Smoothstep peaks at 1.5 x the mean speed: the peak is the joint's speed limit.
    duration = std::max(duration, 1.5 * std::abs(to[j] - from[j]) / settings_.speed_deg_s[j]);
  }
  segment_ = Segment{from, to, now, duration};
}

void ControllerModel::freeze(double t) {
  const ControllerAngles here = position(segment_, t);
  segment_ = Segment{here, here, t, 0.0};
}

ControllerAngles ControllerModel::with_settle_error(const ControllerAngles& target) {
  ControllerAngles q = target;
  for (std::size_t j = 0; j < kJointCount; ++j) {
    q[j] += settings_.bias_deg[j];
  }
  if (settings_.accuracy_deg <= 0) {
    return q;
  }
  std::uniform_real_distribution<double> err(-settings_.accuracy_deg, settings_.accuracy_deg);
  for (double& v : q) {
    v += err(rng_);
  }
  return q;
}

void ControllerModel::start_move(const ControllerAngles& target, double now) {
  ++counters_.moves;
  target_ = target;
  move_active_ = true;
  move_deadline_s_ = now + timeout_s_;
  resettle_at_s_ = kInf;
  start_segment(with_settle_error(target), now);
  stop_at_s_ = kInf;
  if (settings_.move_not_achieved_probability > 0) {
    std::bernoulli_distribution stop(settings_.move_not_achieved_probability);
    if (stop(rng_)) {
      std::uniform_real_distribution<double> when(0.1, 0.9);
      stop_at_s_ = now + when(rng_) * std::max(segment_.duration, 0.01);
    }
  }
}

void ControllerModel::advance(double now_s) {
  if (gripper_moving_ && now_s >= gripper_done_s_) {
    gripper_moving_ = false;
  }
  if (mode_ == Mode::kHost && move_active_) {
    const double end = segment_end();
    if (stop_at_s_ <= now_s && stop_at_s_ <= std::min(end, move_deadline_s_)) {
      freeze(stop_at_s_);
      move_active_ = false;
      send_unsolicited(
          Message{MessageKind::kMoveNotAchieved, {}, dialect_.code_of(NotAchievedReason::kStopped)},
          stop_at_s_);
    } else if (end <= move_deadline_s_ && now_s >= end) {
      const ControllerAngles reached = segment_.to;
      bool within = true;  // without its own check the controller trusts its servos
      for (std::size_t j = 0; j < kJointCount && settings_.own_check; ++j) {
        within = within && std::abs(reached[j] - target_[j]) <= tolerance_deg_;
      }
      if (within) {
        move_active_ = false;  // achieved: the controller says nothing
      } else if (resettle_at_s_ == kInf) {
        resettle_at_s_ = end + kResettleS;
      }
      if (move_active_ && now_s >= resettle_at_s_) {
        const double t = resettle_at_s_;
        resettle_at_s_ = kInf;
        if (t < move_deadline_s_) {
          start_segment(with_settle_error(target_), t);
        }
      }
    }
    if (move_active_ && now_s >= move_deadline_s_) {
      freeze(move_deadline_s_);
      move_active_ = false;
      send_unsolicited(
          Message{MessageKind::kMoveNotAchieved, {}, dialect_.code_of(NotAchievedReason::kTimeout)},
          move_deadline_s_);
    }
  }
  const double period = 1.0 / settings_.teach_rate_hz;
  if (mode_ == Mode::kTeach) {
    while (now_s >= next_sample_s_ && taught_.size() < settings_.teach_capacity) {
      taught_.push_back(position(segment_, next_sample_s_));
      next_sample_s_ += period;
    }
    if (taught_.size() >= settings_.teach_capacity) {
      next_sample_s_ = kInf;  // memory full: recording stops
    }
  } else if (mode_ == Mode::kPlayback) {
    while (now_s >= next_sample_s_ && playback_index_ < taught_.size()) {
      start_segment(taught_[playback_index_++], next_sample_s_);
      next_sample_s_ += period;
    }
    if (playback_index_ >= taught_.size()) {
      next_sample_s_ = kInf;
    }
  }
  last_advance_s_ = std::max(last_advance_s_, now_s);
}

double ControllerModel::next_event_s() const noexcept {
  double t = kInf;
  if (!out_.empty()) {
    t = std::min(t, out_.front().at);
  }
  const auto future = [&](double v) {
    if (v > last_advance_s_) {
      t = std::min(t, v);
    }
  };
  if (move_active_) {
    future(segment_end());
    future(move_deadline_s_);
    future(stop_at_s_);
    future(resettle_at_s_);
  }
  if (gripper_moving_) {
    future(gripper_done_s_);
  }
  future(next_sample_s_);
  return t;
}

// --- input -----------------------------------------------------------------------------------

void ControllerModel::receive(std::string_view bytes, double window_start_s, double now_s) {
  std::string chunk(bytes);
  counters_.noise_faults_in += static_cast<std::uint64_t>(noise_in_.corrupt_bytes(chunk));
  if (chunk.empty()) {
    return;
  }
  // The generous reading: every byte is given the earliest arrival time consistent with the
  // window (window_start_s, now_s], the 6809's pace (one character per min_char_interval) and
  // its busy time after a line. Only bytes that cannot fit even so were certainly too fast: a
  // slow caller (a late read) never causes a false overrun. As in a UART overrun, the latest
  // characters survive (so the terminator does and the line is answered with an overrun).
  const double mi = settings_.min_char_interval_s;
  const double first = std::max({window_start_s, earliest_next_s_, deaf_until_s_});
  std::size_t fit = 0;
  if (now_s >= first) {
    fit = mi > 0 ? std::min(chunk.size(), static_cast<std::size_t>((now_s - first) / mi + 1e-9) + 1)
                 : chunk.size();
  }
  if (fit < chunk.size()) {
    counters_.overruns += chunk.size() - fit;
    line_overrun_ = true;
  }
  double at = first;
  for (std::size_t i = chunk.size() - fit; i < chunk.size(); ++i) {
    if (i > chunk.size() - fit) {
      at = std::max(at + mi, deaf_until_s_);  // after a terminator: wait out the busy time
    }
    if (at > now_s) {
      ++counters_.overruns;  // arrived while the controller was busy with the line before
      line_overrun_ = true;
      continue;
    }
    earliest_next_s_ = at + mi;
    feed(chunk[i], at);
  }
}

void ControllerModel::feed(char c, double now) {
  const Framing& f = dialect_.framing();
  if (f.end_chars.find(c) != std::string::npos) {
    if (line_.empty() && !line_overrun_ && !line_overlong_) {
      return;  // an empty line (the "\n" of "\r\n", or a bare terminator): ignored
    }
    if (line_overlong_) {
      line_.clear();
      line_overlong_ = false;
      line_overrun_ = false;
      deaf_until_s_ = now + settings_.busy_after_line_s;
      return;
    }
    // Per-line noise hits the line with its terminator; a damaged terminator runs this line
    // into the next one, as on a real wire.
    if (noise_in_.settings().probability_per_line > 0) {
      std::string raw = line_;
      raw.push_back(c);
      const int faults = noise_in_.corrupt_line(raw);
      if (faults > 0) {
        counters_.noise_faults_in += static_cast<std::uint64_t>(faults);
        line_.clear();
        for (char r : raw) {
          if (f.end_chars.find(r) != std::string::npos) {
            if (!line_.empty() || line_overrun_) {
              end_line(now);
            }
          } else if (line_.size() < f.max_line_chars) {
            line_.push_back(r);
          }
        }
        return;
      }
    }
    end_line(now);
    return;
  }
  if (line_overlong_) {
    return;
  }
  if (line_.size() >= f.max_line_chars) {
    line_overlong_ = true;
    send_unsolicited(
        Message{MessageKind::kLineError, {}, dialect_.code_of(LineErrorReason::kBufferFull)}, now);
    return;
  }
  line_.push_back(c);
}

void ControllerModel::end_line(double now) {
  const std::string text = std::move(line_);
  line_.clear();
  const bool overrun = line_overrun_;
  line_overrun_ = false;
  process_line(text, overrun, now);
  deaf_until_s_ = now + settings_.busy_after_line_s;
}

void ControllerModel::process_line(const std::string& text, bool overrun, double now) {
  ++counters_.lines_in;
  const auto refuse = [&](ErrorReason reason, std::string why) {
    ++counters_.errors_sent;
    last_rejected_ = fmt::format("{} -> {}: {}", quote_line(text),
                                 dialect_.describe_error(dialect_.code_of(reason)), why);
    reply(Message{MessageKind::kError, {}, dialect_.code_of(reason)}, now);
  };
  if (overrun) {
    refuse(ErrorReason::kOverrun, "characters arrived faster than the controller can take them");
    return;
  }
  ErrorReason reason{};
  auto command = dialect_.parse_command(text, reason);
  if (!command) {
    refuse(reason, command.error().message);
    return;
  }
  advance(now);
  const Command& c = *command;
  switch (c.kind) {
    case CommandKind::kMoveJoints: {
      if (mode_ != Mode::kHost) {
        refuse(ErrorReason::kMode,
               fmt::format("moves need host mode, the controller is in {} mode", to_string(mode_)));
        return;
      }
      ++counters_.commands_ok;
      reply(Message{MessageKind::kOk, {}, 0}, now);
      bool inside = true;
      for (std::size_t j = 0; j < kJointCount; ++j) {
        inside = inside && c.angles_deg[j] >= settings_.lower_deg[j] &&
                 c.angles_deg[j] <= settings_.upper_deg[j];
      }
      if (!inside) {
        freeze(now);
        move_active_ = false;
        target_ = c.angles_deg;
        send_unsolicited(
            Message{
                MessageKind::kMoveNotAchieved, {}, dialect_.code_of(NotAchievedReason::kLimits)},
            now);
        return;
      }
      start_move(c.angles_deg, now);
      return;
    }
    case CommandKind::kSetTolerance: {
      const auto& d = dialect_.defaults();
      if (!(c.tolerance_deg >= d.min_tolerance_deg && c.tolerance_deg <= d.max_tolerance_deg)) {
        refuse(ErrorReason::kRange,
               fmt::format("tolerance {} deg outside [{}, {}]", c.tolerance_deg,
                           d.min_tolerance_deg, d.max_tolerance_deg));
        return;
      }
      tolerance_deg_ = c.tolerance_deg;
      break;
    }
    case CommandKind::kSetTimeout: {
      const auto& d = dialect_.defaults();
      if (!(c.timeout_s >= d.min_timeout_s && c.timeout_s <= d.max_timeout_s)) {
        refuse(ErrorReason::kRange, fmt::format("timeout {} s outside [{}, {}]", c.timeout_s,
                                                d.min_timeout_s, d.max_timeout_s));
        return;
      }
      timeout_s_ = c.timeout_s;
      break;
    }
    default:
      break;
  }
  ++counters_.commands_ok;
  execute(c, now);
}

void ControllerModel::execute(const Command& c, double now) {
  switch (c.kind) {
    case CommandKind::kQueryJoints:
      reply(Message{MessageKind::kJoints, angles(now), 0}, now);
      return;
    case CommandKind::kReadMaster:
      reply(Message{MessageKind::kMaster, settings_.master_deg, 0}, now);
      return;
    case CommandKind::kSetMode:
      freeze(now);
      move_active_ = false;
      mode_ = c.mode;
      next_sample_s_ = kInf;
      if (mode_ == Mode::kManual || mode_ == Mode::kTeach) {
        start_segment(settings_.master_deg, now);
      }
      if (mode_ == Mode::kTeach) {
        taught_.clear();
        next_sample_s_ = now;
      } else if (mode_ == Mode::kPlayback) {
        playback_index_ = 0;
        next_sample_s_ = now;
      }
      reply(Message{MessageKind::kOk, {}, 0}, now);
      return;
    case CommandKind::kReset:
      ++counters_.resets;
      freeze(now);
      move_active_ = false;
      mode_ = settings_.power_up_mode;
      tolerance_deg_ = dialect_.defaults().tolerance_deg;
      timeout_s_ = dialect_.defaults().timeout_s;
      next_sample_s_ = kInf;
      if (mode_ == Mode::kManual || mode_ == Mode::kTeach) {
        start_segment(settings_.master_deg, now);
      }
      reply(Message{MessageKind::kOk, {}, 0}, now);
      send_unsolicited(Message{MessageKind::kReady, {}, 0}, now);
      return;
    case CommandKind::kGripperOpen:
    case CommandKind::kGripperClose:
      gripper_closed_ = c.kind == CommandKind::kGripperClose;
      gripper_moving_ = true;
      gripper_done_s_ = now + settings_.gripper_time_s;
      reply(Message{MessageKind::kOk, {}, 0}, now);
      return;
    case CommandKind::kSetTolerance:
    case CommandKind::kSetTimeout:
    case CommandKind::kMoveJoints:
      reply(Message{MessageKind::kOk, {}, 0}, now);
      return;
  }
}

// --- output ----------------------------------------------------------------------------------

void ControllerModel::queue(const Message& message, double at) {
  if (!out_.empty()) {
    at = std::max(at, out_.back().at);  // lines leave in order
  }
  if (auto s = dialect_.format(message, scratch_); !s) {
    // A value that does not fit the wire (an angle beyond the field): say so as garbage-free
    // as possible rather than sending nothing.
    (void)dialect_.format(Message{MessageKind::kError, {}, dialect_.code_of(ErrorReason::kRange)},
                          scratch_);
  }
  out_.push_back(Outgoing{at, scratch_ + dialect_.framing().controller_terminator});
}

void ControllerModel::reply(const Message& message, double now) {
  queue(message, now + settings_.reply_delay_s);
}

void ControllerModel::send_unsolicited(const Message& message, double now) {
  if (message.kind == MessageKind::kMoveNotAchieved) {
    ++counters_.not_achieved;
  } else if (message.kind == MessageKind::kLineError) {
    ++counters_.line_errors_sent;
  }
  queue(message, now);
}

bool ControllerModel::pop_output(double now_s, std::string& line) {
  if (out_.empty() || out_.front().at > now_s) {
    return false;
  }
  line = std::move(out_.front().line);
  out_.pop_front();
  counters_.noise_faults_out += static_cast<std::uint64_t>(noise_out_.corrupt_line(line));
  return true;
}

ControllerStatus ControllerModel::status(double now_s) const {
  ControllerStatus s;
  s.angles_deg = angles(now_s);
  s.target_deg = target_;
  s.mode = mode_;
  s.moving = move_active_ || (segment_.duration > 0 && now_s < segment_end());
  s.gripper_closed = gripper_closed_;
  s.gripper_moving = gripper_moving_;
  s.tolerance_deg = tolerance_deg_;
  s.timeout_s = timeout_s_;
  s.taught_samples = taught_.size();
  s.counters = counters_;
  s.last_rejected = last_rejected_;
  return s;
}

}  // namespace cell::protocols::excalibur
