#include "cell/config/yaml.hpp"

#include <cerrno>
#include <cmath>
#include <cstring>
#include <fstream>
#include <numbers>
#include <sstream>

#include <fmt/format.h>

namespace cell::config {
namespace {

Error config_error(std::string message) { return Error{Errc::kConfig, std::move(message)}; }

std::string describe(const YAML::Node& node) {
  if (node.IsScalar()) {
    return "'" + node.Scalar() + "'";
  }
  if (node.IsSequence()) {
    return "a list";
  }
  if (node.IsMap()) {
    return "a map";
  }
  return "nothing";
}

}  // namespace

Result<Document> load_string(const std::string& text, const std::string& origin) {
  try {
    Document doc{origin, YAML::Load(text)};
    if (!doc.root.IsDefined() || doc.root.IsNull()) {
      doc.root = YAML::Node(YAML::NodeType::Map);
    }
    return doc;
  } catch (const YAML::Exception& e) {
    return config_error(fmt::format("{}:{}:{}: YAML syntax error: {}", origin, e.mark.line + 1,
                                    e.mark.column + 1, e.msg));
  }
}

Result<Document> load_file(const std::string& path) {
  std::ifstream in(path);
  if (!in) {
    return config_error(fmt::format("{}: cannot open: {}", path, std::strerror(errno)));
  }
  std::stringstream buffer;
  buffer << in.rdbuf();
  return load_string(buffer.str(), path);
}

std::string location(const std::string& path, const YAML::Node& node) {
  if (!node.IsDefined() || node.Mark().is_null()) {
    return path;
  }
  return fmt::format("{}:{}:{}", path, node.Mark().line + 1, node.Mark().column + 1);
}

// A YAML::Node is a handle (it has no move constructor): copying it shares the node.
MapReader::MapReader(std::shared_ptr<const Document> doc, const YAML::Node& map, std::string prefix)
    : doc_(std::move(doc)), map_(map), prefix_(std::move(prefix)) {
  if (!map_.IsDefined() || map_.IsNull()) {
    map_ = YAML::Node(YAML::NodeType::Map);
  } else if (!map_.IsMap()) {
    is_map_ = false;
    errors_.push_back(fmt::format("{}: '{}' must be a map, got {}", location(doc_->path, map_),
                                  prefix_.empty() ? "<document>" : prefix_, describe(map_)));
  }
}

MapReader::MapReader(const Document& doc, const YAML::Node& map, std::string prefix)
    : MapReader(std::make_shared<const Document>(doc), map, std::move(prefix)) {}

std::string MapReader::dotted(const std::string& key) const {
  return prefix_.empty() ? key : prefix_ + "." + key;
}

std::string MapReader::where(const std::string& key) const {
  if (!key.empty() && is_map_) {
    const std::string base = key.substr(0, key.find('['));
    const YAML::Node node = map_[base];
    if (node.IsDefined()) {
      return location(doc_->path, node);
    }
  }
  return location(doc_->path, map_);
}

void MapReader::fail(const std::string& key, const std::string& what) {
  if (key.empty()) {
    errors_.push_back(fmt::format("{}: {}", where(key), what));
  } else {
    errors_.push_back(fmt::format("{}: key '{}': {}", where(key), dotted(key), what));
  }
}

bool MapReader::has(const std::string& key) {
  known_.insert(key);
  return is_map_ && map_[key].IsDefined() && !map_[key].IsNull();
}

bool MapReader::convert_scalar(const std::string& key, const YAML::Node& node, std::string& out) {
  if (!node.IsScalar()) {
    fail(key, "expected a string, got " + describe(node));
    return false;
  }
  out = node.Scalar();
  return true;
}

bool MapReader::convert_scalar(const std::string& key, const YAML::Node& node, bool& out) {
  if (node.IsScalar()) {
    const std::string& s = node.Scalar();
    if (s == "true" || s == "yes" || s == "on") {
      out = true;
      return true;
    }
    if (s == "false" || s == "no" || s == "off") {
      out = false;
      return true;
    }
  }
  fail(key, "expected true or false, got " + describe(node));
  return false;
}

bool MapReader::convert_scalar(const std::string& key, const YAML::Node& node, double& out) {
  if (node.IsScalar()) {
    const std::string& s = node.Scalar();
    char* end = nullptr;
    errno = 0;
    const double value = std::strtod(s.c_str(), &end);
    if (!s.empty() && end == s.c_str() + s.size() && errno == 0 && std::isfinite(value)) {
      out = value;
      return true;
    }
  }
  fail(key, "expected a finite number, got " + describe(node));
  return false;
}

bool MapReader::convert_scalar(const std::string& key, const YAML::Node& node,
                               std::int64_t& out) {
  if (node.IsScalar()) {
    const std::string& s = node.Scalar();
    char* end = nullptr;
    errno = 0;
    const long long value = std::strtoll(s.c_str(), &end, 0);
    if (!s.empty() && end == s.c_str() + s.size() && errno == 0) {
      out = value;
      return true;
    }
  }
  fail(key, "expected an integer, got " + describe(node));
  return false;
}

bool MapReader::convert_scalar(const std::string& key, const YAML::Node& node, int& out) {
  std::int64_t wide = 0;
  if (!convert_scalar(key, node, wide)) {
    return false;
  }
  if (wide < INT32_MIN || wide > INT32_MAX) {
    fail(key, fmt::format("{} does not fit a 32-bit integer", wide));
    return false;
  }
  out = static_cast<int>(wide);
  return true;
}

bool MapReader::convert_scalar(const std::string& key, const YAML::Node& node,
                               std::uint32_t& out) {
  std::int64_t wide = 0;
  if (!node.IsScalar() || node.Scalar().starts_with('-')) {
    fail(key, "expected an unsigned integer, got " + describe(node));
    return false;
  }
  if (!convert_scalar(key, node, wide)) {
    return false;
  }
  if (wide > UINT32_MAX) {
    fail(key, fmt::format("{} does not fit a 32-bit unsigned integer", wide));
    return false;
  }
  out = static_cast<std::uint32_t>(wide);
  return true;
}

void MapReader::optional_deg(const std::string& key, double& out_rad) {
  double deg = out_rad * 180.0 / std::numbers::pi;
  known_.insert(key);
  if (has(key) && convert_scalar(key, map_[key], deg)) {
    out_rad = deg * std::numbers::pi / 180.0;
  }
}

void MapReader::required_deg(const std::string& key, double& out_rad) {
  if (!has(key)) {
    fail("", "missing required key '" + dotted(key) + "'");
    return;
  }
  optional_deg(key, out_rad);
}

MapReader MapReader::child(const std::string& key, bool required) {
  known_.insert(key);
  YAML::Node node = is_map_ ? map_[key] : YAML::Node();
  if ((!node.IsDefined() || node.IsNull()) && required) {
    fail("", "missing required section '" + dotted(key) + "'");
  }
  return MapReader(doc_, node, dotted(key));
}

std::vector<YAML::Node> MapReader::sequence(const std::string& key, bool required) {
  known_.insert(key);
  std::vector<YAML::Node> out;
  const YAML::Node node = is_map_ ? map_[key] : YAML::Node();
  if (!node.IsDefined() || node.IsNull()) {
    if (required) {
      fail("", "missing required list '" + dotted(key) + "'");
    }
    return out;
  }
  if (!node.IsSequence()) {
    fail(key, "expected a list, got " + describe(node));
    return out;
  }
  for (const auto& item : node) {
    out.push_back(item);
  }
  return out;
}

MapReader MapReader::element(const YAML::Node& node, const std::string& dotted_name) {
  return MapReader(doc_, node, prefix_.empty() ? dotted_name : prefix_ + "." + dotted_name);
}

void MapReader::absorb(MapReader& child) {
  auto status = child.finish();
  if (!status) {
    errors_.push_back(status.error().message);
  }
}

Status MapReader::finish() {
  if (is_map_) {
    for (const auto& entry : map_) {
      const std::string key = entry.first.as<std::string>("");
      if (known_.count(key) == 0) {
        errors_.push_back(fmt::format("{}: unknown key '{}'", location(doc_->path, entry.first),
                                      dotted(key)));
      }
    }
  }
  is_map_ = false;  // report once
  if (errors_.empty()) {
    return ok_status();
  }
  std::string message;
  for (const auto& e : errors_) {
    if (!message.empty()) {
      message += '\n';
    }
    message += e;
  }
  errors_.clear();
  return config_error(std::move(message));
}

}  // namespace cell::config
