#include "cell/protocols/excalibur/dialect.hpp"

#include <fmt/format.h>

#include <algorithm>
#include <cctype>
#include <cmath>
#include <iterator>
#include <optional>
#include <set>

#include "line_template.hpp"

namespace cell::protocols::excalibur {
namespace {

using detail::bit;
using detail::Field;
using detail::kAngleFields;
using detail::LineTemplate;
using detail::Values;

constexpr std::array<std::string_view, kModes> kModeNames = {"host", "manual", "teach", "playback"};
constexpr std::array<std::string_view, kCommandKinds> kCommandNames = {
    "move_joints", "query_joints", "read_master",  "set_mode",     "set_tolerance",
    "set_timeout", "reset",        "gripper_open", "gripper_close"};
constexpr std::array<std::string_view, kMessageKinds> kMessageNames = {
    "ok", "joints", "master", "error", "move_not_achieved", "line_error", "ready"};
constexpr std::array<std::string_view, kErrorReasons> kErrorNames = {"syntax", "checksum",
                                                                     "overrun", "range", "mode"};
constexpr std::array<std::string_view, kErrorReasons> kErrorTexts = {
    "syntax error (garbled line)", "checksum error", "input overrun (characters too fast)",
    "value out of range", "not allowed in the current mode"};
constexpr std::array<std::string_view, kNotAchievedReasons> kNotAchievedNames = {
    "limits", "timeout", "stopped"};
constexpr std::array<std::string_view, kNotAchievedReasons> kNotAchievedTexts = {
    "target outside the controller's joint limits",
    "not within tolerance when the controller's timeout expired",
    "motion stopped on the way (obstruction or servo fault)"};
constexpr std::array<std::string_view, kLineErrorReasons> kLineErrorNames = {"overrun",
                                                                             "buffer_full"};
constexpr std::array<std::string_view, kLineErrorReasons> kLineErrorTexts = {
    "characters lost (controller overrun)", "line longer than the controller's buffer"};

/// Placeholders each command / message uses (allowed = required here, except the codes of
/// unsolicited messages, which a dialect may leave out).
struct Shape {
  std::uint32_t allowed;
  std::uint32_t required;
};
constexpr std::array<Shape, kCommandKinds> kCommandShapes = {{
    {kAngleFields, kAngleFields},
    {0, 0},
    {0, 0},
    {bit(Field::kMode), bit(Field::kMode)},
    {bit(Field::kTolerance), bit(Field::kTolerance)},
    {bit(Field::kTimeout), bit(Field::kTimeout)},
    {0, 0},
    {0, 0},
    {0, 0},
}};
constexpr std::array<Shape, kMessageKinds> kMessageShapes = {{
    {0, 0},
    {kAngleFields, kAngleFields},
    {kAngleFields, kAngleFields},
    {bit(Field::kCode), bit(Field::kCode)},
    {bit(Field::kCode), 0},
    {bit(Field::kCode), 0},
    {0, 0},
}};

bool is_control(char c) noexcept { return static_cast<unsigned char>(c) < 0x20; }

std::size_t checksum_digits(ChecksumKind kind) noexcept {
  switch (kind) {
    case ChecksumKind::kNone:
      return 0;
    case ChecksumKind::kCrc16:
      return 4;
    default:
      return 2;
  }
}

Values values_of(const Command& c) {
  Values v;
  v.q = c.angles_deg;
  v.mode_index = static_cast<std::size_t>(c.mode);
  v.tolerance = c.tolerance_deg;
  v.timeout = c.timeout_s;
  return v;
}

Values values_of(const Message& m) {
  Values v;
  v.q = m.angles_deg;
  v.code = m.code;
  return v;
}

int hex_value(char c) noexcept {
  if (c >= '0' && c <= '9') {
    return c - '0';
  }
  if (c >= 'A' && c <= 'F') {
    return c - 'A' + 10;
  }
  if (c >= 'a' && c <= 'f') {
    return c - 'a' + 10;
  }
  return -1;
}

}  // namespace

std::string_view to_string(Mode mode) noexcept {
  return kModeNames[static_cast<std::size_t>(mode)];
}
std::string_view to_string(CommandKind kind) noexcept {
  return kCommandNames[static_cast<std::size_t>(kind)];
}
std::string_view to_string(MessageKind kind) noexcept {
  return kMessageNames[static_cast<std::size_t>(kind)];
}
std::string_view to_string(ErrorReason reason) noexcept {
  return kErrorNames[static_cast<std::size_t>(reason)];
}
std::string_view to_string(NotAchievedReason reason) noexcept {
  return kNotAchievedNames[static_cast<std::size_t>(reason)];
}
std::string_view to_string(LineErrorReason reason) noexcept {
  return kLineErrorNames[static_cast<std::size_t>(reason)];
}

std::uint16_t checksum(ChecksumKind kind, std::string_view body) noexcept {
  switch (kind) {
    case ChecksumKind::kNone:
      return 0;
    case ChecksumKind::kXor8: {
      unsigned x = 0;
      for (char c : body) {
        x ^= static_cast<unsigned char>(c);
      }
      return static_cast<std::uint16_t>(x & 0xFFU);
    }
    case ChecksumKind::kSum8: {
      unsigned s = 0;
      for (char c : body) {
        s += static_cast<unsigned char>(c);
      }
      return static_cast<std::uint16_t>(s & 0xFFU);
    }
    case ChecksumKind::kCrc16: {
      std::uint16_t crc = 0xFFFF;
      for (char c : body) {
        crc = static_cast<std::uint16_t>(crc ^ (static_cast<unsigned char>(c) << 8));
        for (int b = 0; b < 8; ++b) {
          crc = (crc & 0x8000U) != 0 ? static_cast<std::uint16_t>((crc << 1) ^ 0x1021U)
                                     : static_cast<std::uint16_t>(crc << 1);
        }
      }
      return crc;
    }
  }
  return 0;
}

std::string quote_line(std::string_view line) {
  std::string out = "\"";
  for (char c : line) {
    const auto u = static_cast<unsigned char>(c);
    if (c == '\r') {
      out += "\\r";
    } else if (c == '\n') {
      out += "\\n";
    } else if (c == '\t') {
      out += "\\t";
    } else if (c == '"' || c == '\\') {
      out += '\\';
      out += c;
    } else if (u < 0x20 || u > 0x7E) {
      out += fmt::format("\\x{:02X}", u);
    } else {
      out += c;
    }
  }
  out += '"';
  return out;
}

// --- construction --------------------------------------------------------------------------

Dialect::Dialect() = default;
Dialect::Dialect(Dialect&&) noexcept = default;
Dialect& Dialect::operator=(Dialect&&) noexcept = default;
Dialect::~Dialect() = default;

Dialect::Dialect(const Dialect& other)
    : name_(other.name_),
      framing_(other.framing_),
      numbers_(other.numbers_),
      timing_(other.timing_),
      defaults_(other.defaults_),
      mode_words_(other.mode_words_),
      error_codes_(other.error_codes_),
      not_achieved_codes_(other.not_achieved_codes_),
      line_error_codes_(other.line_error_codes_),
      longest_command_(other.longest_command_),
      longest_message_(other.longest_message_) {
  for (std::size_t i = 0; i < kCommandKinds; ++i) {
    if (other.commands_[i]) {
      commands_[i] = std::make_unique<LineTemplate>(*other.commands_[i]);
    }
  }
  for (std::size_t i = 0; i < kMessageKinds; ++i) {
    if (other.messages_[i]) {
      messages_[i] = std::make_unique<LineTemplate>(*other.messages_[i]);
    }
  }
}

Dialect& Dialect::operator=(const Dialect& other) {
  if (this != &other) {
    Dialect copy(other);
    *this = std::move(copy);
  }
  return *this;
}

/// Reads the dialect file into a Dialect, collecting every problem with its location.
class DialectBuilder {
 public:
  static Result<Dialect> build(const config::Document& doc) {
    Dialect d;
    config::MapReader root(doc, doc.root, "");
    root.required("dialect", d.name_);
    read_framing(root, d);
    read_numbers(root, d);
    read_timing(root, d);
    read_controller(root, d);
    read_modes(root, d);
    read_templates(root, "commands", kCommandNames, kCommandShapes, d.commands_,
                   {CommandKind::kGripperOpen, CommandKind::kGripperClose});
    read_messages(root, d);
    read_codes(root, "error_codes", kErrorNames, d.error_codes_);
    read_codes(root, "move_not_achieved_codes", kNotAchievedNames, d.not_achieved_codes_);
    read_codes(root, "line_error_codes", kLineErrorNames, d.line_error_codes_);
    CELL_TRY(root.finish());
    CELL_TRY(self_test(doc.path, d));
    return d;
  }

 private:
  static void read_framing(config::MapReader& root, Dialect& d) {
    config::MapReader r = root.child("framing");
    Framing& f = d.framing_;
    r.required("host_terminator", f.host_terminator);
    r.required("controller_terminator", f.controller_terminator);
    r.required("end_chars", f.end_chars);
    int max_line = static_cast<int>(f.max_line_chars);
    r.optional("max_line_chars", max_line);
    r.optional("unsolicited_prefix", f.unsolicited_prefix);
    std::string checksum = "none";
    r.optional("checksum", checksum);
    std::string separator(1, f.checksum_separator);
    r.optional("checksum_separator", separator);
    if (f.end_chars.empty() || !std::all_of(f.end_chars.begin(), f.end_chars.end(), is_control)) {
      r.fail("end_chars", "must be one or more control characters, e.g. \"\\r\\n\"");
    }
    for (const auto* key : {"host_terminator", "controller_terminator"}) {
      const std::string& t =
          std::string_view(key) == "host_terminator" ? f.host_terminator : f.controller_terminator;
      if (t.empty() || t.find_first_not_of(f.end_chars) != std::string::npos) {
        r.fail(key, fmt::format("must be non-empty and made of end_chars {}, got {}",
                                quote_line(f.end_chars), quote_line(t)));
      }
    }
    if (max_line < 8 || max_line > 1024) {
      r.fail("max_line_chars", fmt::format("must be in [8, 1024], got {}", max_line));
    } else {
      f.max_line_chars = static_cast<std::size_t>(max_line);
    }
    if (std::any_of(f.unsolicited_prefix.begin(), f.unsolicited_prefix.end(),
                    [](char c) { return c <= ' ' || c > '~'; })) {
      r.fail("unsolicited_prefix", "must be printable ASCII without blanks");
    }
    if (checksum == "none") {
      f.checksum = ChecksumKind::kNone;
    } else if (checksum == "xor8") {
      f.checksum = ChecksumKind::kXor8;
    } else if (checksum == "sum8") {
      f.checksum = ChecksumKind::kSum8;
    } else if (checksum == "crc16") {
      f.checksum = ChecksumKind::kCrc16;
    } else {
      r.fail("checksum", fmt::format("must be one of none, xor8, sum8, crc16; got '{}'", checksum));
    }
    if (separator.size() != 1 || separator[0] <= ' ' || separator[0] > '~' ||
        std::isalnum(static_cast<unsigned char>(separator[0])) != 0) {
      r.fail("checksum_separator",
             fmt::format("must be one printable non-alphanumeric character, got {}",
                         quote_line(separator)));
    } else {
      f.checksum_separator = separator[0];
    }
    root.absorb(r);
  }

  static void read_numbers(config::MapReader& root, Dialect& d) {
    config::MapReader r = root.child("numbers");
    NumberFormat& n = d.numbers_;
    r.optional("angle_decimals", n.angle_decimals);
    r.optional("tolerance_decimals", n.tolerance_decimals);
    r.optional("timeout_decimals", n.timeout_decimals);
    r.optional("plus_sign", n.plus_sign);
    r.optional("strict_decimals", n.strict_decimals);
    r.optional("max_abs_angle_deg", n.max_abs_angle_deg);
    for (const auto& [key, value] : {std::pair{"angle_decimals", n.angle_decimals},
                                     std::pair{"tolerance_decimals", n.tolerance_decimals},
                                     std::pair{"timeout_decimals", n.timeout_decimals}}) {
      if (value < 0 || value > 4) {
        r.fail(key, fmt::format("must be in [0, 4], got {}", value));
      }
    }
    if (!(n.max_abs_angle_deg >= 180.0 && n.max_abs_angle_deg < 1e6)) {
      r.fail("max_abs_angle_deg",
             fmt::format("must be in [180, 1e6) (a joint turns at least half a turn), got {}",
                         n.max_abs_angle_deg));
    }
    root.absorb(r);
  }

  static void read_timing(config::MapReader& root, Dialect& d) {
    config::MapReader r = root.child("timing");
    double char_ms = 0;
    double command_ms = 0;
    double reply_ms = 200;
    r.optional("char_delay_ms", char_ms);
    r.optional("command_delay_ms", command_ms);
    r.optional("reply_timeout_ms", reply_ms);
    if (!(char_ms >= 0 && char_ms <= 100)) {
      r.fail("char_delay_ms", fmt::format("must be in [0, 100], got {}", char_ms));
    }
    if (!(command_ms >= 0 && command_ms <= 2000)) {
      r.fail("command_delay_ms", fmt::format("must be in [0, 2000], got {}", command_ms));
    }
    if (!(reply_ms > 0 && reply_ms <= 10000)) {
      r.fail("reply_timeout_ms", fmt::format("must be in (0, 10000], got {}", reply_ms));
    }
    d.timing_.char_delay_s = char_ms * 1e-3;
    d.timing_.command_delay_s = command_ms * 1e-3;
    d.timing_.reply_timeout_s = reply_ms * 1e-3;
    root.absorb(r);
  }

  static void read_controller(config::MapReader& root, Dialect& d) {
    config::MapReader r = root.child("controller");
    ControllerDefaults& c = d.defaults_;
    r.optional("default_tolerance_deg", c.tolerance_deg);
    r.optional("default_timeout_s", c.timeout_s);
    std::array<double, 2> tol{c.min_tolerance_deg, c.max_tolerance_deg};
    std::array<double, 2> timeout{c.min_timeout_s, c.max_timeout_s};
    r.optional("tolerance_range_deg", tol);
    r.optional("timeout_range_s", timeout);
    if (!(tol[0] > 0 && tol[1] > tol[0])) {
      r.fail("tolerance_range_deg",
             fmt::format("must be [min > 0, max > min], got [{}, {}]", tol[0], tol[1]));
    }
    if (!(timeout[0] > 0 && timeout[1] > timeout[0])) {
      r.fail("timeout_range_s",
             fmt::format("must be [min > 0, max > min], got [{}, {}]", timeout[0], timeout[1]));
    }
    c.min_tolerance_deg = tol[0];
    c.max_tolerance_deg = tol[1];
    c.min_timeout_s = timeout[0];
    c.max_timeout_s = timeout[1];
    if (!(c.tolerance_deg >= c.min_tolerance_deg && c.tolerance_deg <= c.max_tolerance_deg)) {
      r.fail("default_tolerance_deg",
             fmt::format("must be within tolerance_range_deg, got {}", c.tolerance_deg));
    }
    if (!(c.timeout_s >= c.min_timeout_s && c.timeout_s <= c.max_timeout_s)) {
      r.fail("default_timeout_s",
             fmt::format("must be within timeout_range_s, got {}", c.timeout_s));
    }
    root.absorb(r);
  }

  static void read_modes(config::MapReader& root, Dialect& d) {
    config::MapReader r = root.child("modes");
    std::set<std::string> seen;
    for (std::size_t m = 0; m < kModes; ++m) {
      const std::string key(kModeNames[m]);
      std::string& word = d.mode_words_[m];
      r.required(key, word);
      if (word.empty()) {
        continue;  // missing: already reported
      }
      if (!std::all_of(word.begin(), word.end(),
                       [](char c) { return std::isalnum(static_cast<unsigned char>(c)) != 0; })) {
        r.fail(key, fmt::format("must be letters and digits, got {}", quote_line(word)));
      } else if (!seen.insert(word).second) {
        r.fail(key, fmt::format("'{}' is already the word of another mode", word));
      }
    }
    root.absorb(r);
  }

  template <std::size_t N>
  static void read_templates(config::MapReader& root,
                             const char* section,
                             const std::array<std::string_view, N>& names,
                             const std::array<Shape, N>& shapes,
                             std::array<std::unique_ptr<LineTemplate>, N>& out,
                             std::initializer_list<CommandKind> optional_commands) {
    config::MapReader r = root.child(section);
    for (std::size_t i = 0; i < N; ++i) {
      const std::string key(names[i]);
      bool optional = false;
      for (CommandKind k : optional_commands) {
        optional = optional || static_cast<std::size_t>(k) == i;
      }
      std::string text;
      if (optional) {
        r.optional(key, text);
        if (text.empty()) {
          continue;
        }
      } else {
        r.required(key, text);
        if (text.empty()) {
          continue;
        }
      }
      auto t = LineTemplate::compile(text, shapes[i].allowed, shapes[i].required);
      if (!t) {
        r.fail(key, t.error().message);
        continue;
      }
      out[i] = std::make_unique<LineTemplate>(std::move(*t));
    }
    root.absorb(r);
  }

  static void read_messages(config::MapReader& root, Dialect& d) {
    // Replies and unsolicited messages live in two sections of one table.
    std::array<std::unique_ptr<LineTemplate>, kMessageKinds>& out = d.messages_;
    for (const char* section : {"replies", "unsolicited"}) {
      const bool unsolicited_section = std::string_view(section) == "unsolicited";
      config::MapReader r = root.child(section);
      for (std::size_t i = 0; i < kMessageKinds; ++i) {
        if (is_unsolicited(static_cast<MessageKind>(i)) != unsolicited_section) {
          continue;
        }
        const std::string key(kMessageNames[i]);
        std::string text;
        r.required(key, text);
        if (text.empty()) {
          continue;
        }
        auto t = LineTemplate::compile(text, kMessageShapes[i].allowed, kMessageShapes[i].required);
        if (!t) {
          r.fail(key, t.error().message);
          continue;
        }
        const std::string& prefix = d.framing_.unsolicited_prefix;
        const bool has_prefix = !prefix.empty() && text.rfind(prefix, 0) == 0;
        if (!prefix.empty() && unsolicited_section && !has_prefix) {
          r.fail(key, fmt::format("unsolicited messages must start with unsolicited_prefix '{}'",
                                  prefix));
        } else if (!unsolicited_section && has_prefix) {
          r.fail(key, fmt::format("replies must not start with unsolicited_prefix '{}'", prefix));
        }
        out[i] = std::make_unique<LineTemplate>(std::move(*t));
      }
      root.absorb(r);
    }
  }

  template <std::size_t N>
  static void read_codes(config::MapReader& root,
                         const char* section,
                         const std::array<std::string_view, N>& names,
                         std::array<int, N>& out) {
    config::MapReader r = root.child(section);
    std::set<int> seen;
    for (std::size_t i = 0; i < N; ++i) {
      const std::string key(names[i]);
      int code = -1;
      r.required(key, code);
      if (code < 0) {
        if (r.node()[key].IsDefined()) {
          r.fail(key, fmt::format("must be >= 0, got {}", code));
        }
        continue;
      }
      if (!seen.insert(code).second) {
        r.fail(key, fmt::format("code {} is used twice in {}", code, section));
      }
      out[i] = code;
    }
    root.absorb(r);
  }

  /// Renders every template with sample values and parses it back: catches templates that
  /// parse as each other ("OK" vs "OK {code}") and formats that cannot round-trip.
  static Status self_test(const std::string& path, Dialect& d) {
    std::string line;
    std::string problems;
    const auto problem = [&](std::string what) {
      problems += fmt::format("{}{}: {}", problems.empty() ? "" : "\n", path, what);
    };
    const ControllerAngles widest = {-d.numbers_.max_abs_angle_deg, 12.5, -150.25, 0.0, 5.0, 7.0};
    for (std::size_t i = 0; i < kCommandKinds; ++i) {
      if (!d.commands_[i]) {
        continue;
      }
      Command c;
      c.kind = static_cast<CommandKind>(i);
      c.angles_deg = widest;
      c.mode = Mode::kTeach;
      c.tolerance_deg = 1.25;
      c.timeout_s = 10.5;
      if (auto s = d.format(c, line); !s) {
        problem(fmt::format("commands.{}: cannot render: {}", kCommandNames[i], s.error().message));
        continue;
      }
      d.longest_command_ =
          std::max(d.longest_command_, line.size() + d.framing_.host_terminator.size());
      ErrorReason reason{};
      auto back = d.parse_command(line, reason);
      if (!back || back->kind != c.kind) {
        problem(fmt::format("commands.{}: {} does not parse back as itself ({})", kCommandNames[i],
                            quote_line(line),
                            back ? std::string("parsed as ") + std::string(to_string(back->kind))
                                 : back.error().message));
      }
    }
    for (std::size_t i = 0; i < kMessageKinds; ++i) {
      if (!d.messages_[i]) {
        continue;
      }
      Message m;
      m.kind = static_cast<MessageKind>(i);
      m.angles_deg = widest;
      m.code = 42;
      if (auto s = d.format(m, line); !s) {
        problem(fmt::format("{}: cannot render: {}", kMessageNames[i], s.error().message));
        continue;
      }
      d.longest_message_ =
          std::max(d.longest_message_, line.size() + d.framing_.controller_terminator.size());
      auto back = d.parse(line);
      if (!back || back->kind != m.kind) {
        problem(fmt::format("{} template: {} does not parse back as itself ({})", kMessageNames[i],
                            quote_line(line),
                            back ? std::string("parsed as ") + std::string(to_string(back->kind))
                                 : back.error().message));
      }
      if (line.size() + d.framing_.controller_terminator.size() > d.framing_.max_line_chars) {
        problem(
            fmt::format("{} template: the longest line has {} characters, more than "
                        "framing.max_line_chars = {}",
                        kMessageNames[i], line.size(), d.framing_.max_line_chars));
      }
    }
    if (!problems.empty()) {
      return Error{Errc::kConfig, problems};
    }
    return ok_status();
  }
};

Result<Dialect> Dialect::load(const std::string& path) {
  auto doc = config::load_file(path);
  if (!doc) {
    return std::move(doc).error();
  }
  return parse(*doc);
}

Result<Dialect> Dialect::parse(const config::Document& doc) { return DialectBuilder::build(doc); }

bool Dialect::has(CommandKind kind) const noexcept {
  return commands_[static_cast<std::size_t>(kind)] != nullptr;
}

// --- formatting ----------------------------------------------------------------------------

namespace {

void append_checksum(const Framing& f, std::string& out) {
  if (f.checksum == ChecksumKind::kNone) {
    return;
  }
  const std::uint16_t sum = checksum(f.checksum, out);
  out += f.checksum_separator;
  if (checksum_digits(f.checksum) == 4) {
    fmt::format_to(std::back_inserter(out), "{:04X}", sum);
  } else {
    fmt::format_to(std::back_inserter(out), "{:02X}", sum);
  }
}

/// Checks printability and length, strips and verifies the checksum; returns the body.
Result<std::string_view> open_line(const Framing& f, std::string_view line, ErrorReason& reason) {
  reason = ErrorReason::kSyntax;
  if (line.empty()) {
    return Error{Errc::kProtocol, "empty line"};
  }
  if (line.size() > f.max_line_chars) {
    return Error{Errc::kProtocol,
                 fmt::format("line {} is {} characters long, more than {}",
                             quote_line(line.substr(0, 40)), line.size(), f.max_line_chars)};
  }
  for (std::size_t i = 0; i < line.size(); ++i) {
    const auto u = static_cast<unsigned char>(line[i]);
    if ((u < 0x20 && u != '\t') || u > 0x7E) {
      return Error{Errc::kProtocol, fmt::format("line {}: non-printable byte 0x{:02X} at column {}",
                                                quote_line(line), u, i + 1)};
    }
  }
  if (f.checksum == ChecksumKind::kNone) {
    return line;
  }
  const std::size_t sep = line.rfind(f.checksum_separator);
  const std::size_t digits = checksum_digits(f.checksum);
  if (sep == std::string_view::npos) {
    reason = ErrorReason::kChecksum;
    return Error{Errc::kProtocol, fmt::format("line {}: no checksum ('{}' and {} hex digits)",
                                              quote_line(line), f.checksum_separator, digits)};
  }
  const std::string_view hex = line.substr(sep + 1);
  unsigned got = 0;
  bool hex_ok = hex.size() == digits;
  for (char c : hex) {
    const int v = hex_value(c);
    hex_ok = hex_ok && v >= 0;
    got = (got << 4) | static_cast<unsigned>(v < 0 ? 0 : v);
  }
  reason = ErrorReason::kChecksum;
  if (!hex_ok) {
    return Error{Errc::kProtocol,
                 fmt::format("line {}: checksum must be {} hex digits after '{}', got {}",
                             quote_line(line), digits, f.checksum_separator, quote_line(hex))};
  }
  const std::string_view body = line.substr(0, sep);
  const std::uint16_t want = checksum(f.checksum, body);
  if (got != want) {
    return Error{Errc::kProtocol,
                 fmt::format("line {}: checksum mismatch: line says {:0{}X}, body gives {:0{}X}",
                             quote_line(line), got, digits, want, digits)};
  }
  reason = ErrorReason::kSyntax;
  return body;
}

template <std::size_t N>
std::string mnemonics(const std::array<std::unique_ptr<LineTemplate>, N>& templates) {
  std::string out;
  for (const auto& t : templates) {
    if (t) {
      out += fmt::format("{}{}", out.empty() ? "" : ", ", t->head());
    }
  }
  return out;
}

/// Tries every template whose mnemonic starts the body; the first full match wins. Without a
/// match, the error of the candidate with the longest mnemonic is the most telling.
template <std::size_t N>
Result<std::pair<std::size_t, Values>> match_any(
    const std::array<std::unique_ptr<LineTemplate>, N>& templates,
    std::string_view line,
    std::string_view body,
    const NumberFormat& numbers,
    const std::array<std::string, kModes>& mode_words,
    const char* what) {
  std::optional<Error> best;
  std::size_t best_head = 0;
  for (std::size_t i = 0; i < N; ++i) {
    const auto& t = templates[i];
    if (!t || !t->head_matches(body)) {
      continue;
    }
    auto values = t->match(body, numbers, mode_words);
    if (values) {
      return std::pair{i, *values};
    }
    if (!best || t->head().size() > best_head) {
      best = Error{Errc::kProtocol,
                   fmt::format("line {}: {}", quote_line(line), values.error().message)};
      best_head = t->head().size();
    }
  }
  if (best) {
    return *best;
  }
  return Error{Errc::kProtocol, fmt::format("line {}: unknown {} (expected one of: {})",
                                            quote_line(line), what, mnemonics(templates))};
}

}  // namespace

Status Dialect::format(const Command& command, std::string& out) const {
  out.clear();
  const auto& t = commands_[static_cast<std::size_t>(command.kind)];
  if (!t) {
    return Error{Errc::kNotReady,
                 fmt::format("dialect '{}' has no '{}' command", name_, to_string(command.kind))};
  }
  CELL_TRY(t->render(values_of(command), numbers_, mode_words_, out));
  append_checksum(framing_, out);
  return ok_status();
}

Result<std::string> Dialect::format(const Command& command) const {
  std::string out;
  CELL_TRY(format(command, out));
  return out;
}

Status Dialect::format(const Message& message, std::string& out) const {
  out.clear();
  const auto& t = messages_[static_cast<std::size_t>(message.kind)];
  if (!t) {
    return Error{Errc::kNotReady,
                 fmt::format("dialect '{}' has no '{}' message", name_, to_string(message.kind))};
  }
  CELL_TRY(t->render(values_of(message), numbers_, mode_words_, out));
  append_checksum(framing_, out);
  return ok_status();
}

Result<std::string> Dialect::format(const Message& message) const {
  std::string out;
  CELL_TRY(format(message, out));
  return out;
}

// --- parsing -------------------------------------------------------------------------------

Result<Message> Dialect::parse(std::string_view line) const {
  ErrorReason reason{};
  auto body = open_line(framing_, line, reason);
  if (!body) {
    return std::move(body).error();
  }
  auto matched = match_any(messages_, line, *body, numbers_, mode_words_, "message");
  if (!matched) {
    return std::move(matched).error();
  }
  Message m;
  m.kind = static_cast<MessageKind>(matched->first);
  m.angles_deg = matched->second.q;
  m.code = matched->second.code;
  return m;
}

Result<Command> Dialect::parse_command(std::string_view line, ErrorReason& reason) const {
  auto body = open_line(framing_, line, reason);
  if (!body) {
    return std::move(body).error();
  }
  reason = ErrorReason::kSyntax;
  auto matched = match_any(commands_, line, *body, numbers_, mode_words_, "command");
  if (!matched) {
    return std::move(matched).error();
  }
  Command c;
  c.kind = static_cast<CommandKind>(matched->first);
  c.angles_deg = matched->second.q;
  c.mode = static_cast<Mode>(matched->second.mode_index);
  c.tolerance_deg = matched->second.tolerance;
  c.timeout_s = matched->second.timeout;
  return c;
}

bool Dialect::looks_unsolicited(std::string_view line) const noexcept {
  const std::string& prefix = framing_.unsolicited_prefix;
  if (!prefix.empty() && line.substr(0, prefix.size()) == prefix) {
    return true;
  }
  for (std::size_t i = 0; i < kMessageKinds; ++i) {
    if (is_unsolicited(static_cast<MessageKind>(i)) && messages_[i] &&
        messages_[i]->head_matches(line)) {
      return true;
    }
  }
  return false;
}

// --- codes ---------------------------------------------------------------------------------

bool Dialect::error_reason(int code, ErrorReason& out) const noexcept {
  for (std::size_t i = 0; i < kErrorReasons; ++i) {
    if (error_codes_[i] == code) {
      out = static_cast<ErrorReason>(i);
      return true;
    }
  }
  return false;
}

std::string Dialect::describe_error(int code) const {
  ErrorReason reason{};
  if (error_reason(code, reason)) {
    return fmt::format("{} (code {})", kErrorTexts[static_cast<std::size_t>(reason)], code);
  }
  return fmt::format("unknown error code {}", code);
}

bool Dialect::not_achieved_reason(int code, NotAchievedReason& out) const noexcept {
  for (std::size_t i = 0; i < kNotAchievedReasons; ++i) {
    if (not_achieved_codes_[i] == code) {
      out = static_cast<NotAchievedReason>(i);
      return true;
    }
  }
  return false;
}

std::string Dialect::describe_not_achieved(int code) const {
  NotAchievedReason reason{};
  if (not_achieved_reason(code, reason)) {
    return fmt::format("{} (code {})", kNotAchievedTexts[static_cast<std::size_t>(reason)], code);
  }
  return fmt::format("unknown reason code {}", code);
}

std::string Dialect::describe_line_error(int code) const {
  for (std::size_t i = 0; i < kLineErrorReasons; ++i) {
    if (line_error_codes_[i] == code) {
      return fmt::format("{} (code {})", kLineErrorTexts[i], code);
    }
  }
  return fmt::format("unknown line error code {}", code);
}

int Dialect::code_of(ErrorReason reason) const noexcept {
  return error_codes_[static_cast<std::size_t>(reason)];
}
int Dialect::code_of(NotAchievedReason reason) const noexcept {
  return not_achieved_codes_[static_cast<std::size_t>(reason)];
}
int Dialect::code_of(LineErrorReason reason) const noexcept {
  return line_error_codes_[static_cast<std::size_t>(reason)];
}

}  // namespace cell::protocols::excalibur
