#pragma once

#include <array>
#include <cstdint>
#include <map>
#include <memory>
#include <optional>
#include <set>
#include <string>
#include <utility>
#include <vector>

#include <yaml-cpp/yaml.h>

#include "cell/common/result.hpp"

namespace cell::config {

/// A parsed YAML document plus the file it came from (for error locations). Copied or moved,
/// never assigned: yaml-cpp's Node assignment re-points every node that shares the old root's
/// data at the new one (Node::AssignNode's set_ref), which can also throw.
struct Document {
  Document(std::string file, const YAML::Node& node) : path(std::move(file)), root(node) {}
  Document(const Document&) = default;
  Document(Document&&) = default;
  Document& operator=(const Document&) = delete;
  Document& operator=(Document&&) = delete;
  ~Document() = default;

  std::string path;
  YAML::Node root;
};

/// Loads and parses a YAML file. Errors (kConfig): missing or unreadable file ("<path>: cannot
/// open: No such file or directory"), syntax error ("<path>:<line>:<col>: <what>").
Result<Document> load_file(const std::string& path);

/// Parses YAML text; `origin` names it in errors (e.g. "<job spec>").
Result<Document> load_string(const std::string& text, const std::string& origin);

/// "<path>:<line>:<col>" of a node (1-based), or just the path when the node has no mark.
std::string location(const std::string& path, const YAML::Node& node);

/// Reads one YAML mapping with strict checking: every key read is recorded; `finish()` reports
/// keys that were never read (unknown keys, i.e. typos) and every error met on the way, all
/// at once, each as "file:line:col: key 'a.b': what was wrong". Not thread-safe.
///
///   MapReader r(doc, doc.root, "");
///   r.required("domain_id", cfg.domain_id);
///   r.optional("partition", cfg.partition);
///   if (auto s = r.finish(); !s) return s.error();
class MapReader {
 public:
  /// `prefix` is the dotted path of this map in the document ("" for the root).
  MapReader(std::shared_ptr<const Document> doc, const YAML::Node& map, std::string prefix);
  MapReader(const Document& doc, const YAML::Node& map, std::string prefix);

  /// Reads `key` into `out`; records an error when missing or of the wrong type.
  template <typename T>
  void required(const std::string& key, T& out) {
    read(key, out, true);
  }
  /// Reads `key` into `out` if present; `out` keeps its default otherwise.
  template <typename T>
  void optional(const std::string& key, T& out) {
    read(key, out, false);
  }
  /// Reads an angle given in degrees under `key` (which should end in _deg) into radians.
  void optional_deg(const std::string& key, double& out_rad);
  void required_deg(const std::string& key, double& out_rad);

  /// True when the map has `key` (marks it as known).
  bool has(const std::string& key);

  /// The sub-map under `key`, for nested readers. When absent and !required, an empty map.
  /// Errors in the child are collected into this reader when the child finishes.
  MapReader child(const std::string& key, bool required = true);

  /// The sequence under `key` (empty when absent and !required); records an error if the
  /// node is not a sequence.
  std::vector<YAML::Node> sequence(const std::string& key, bool required = true);

  /// A MapReader over an element of a sequence (the element must be a map).
  MapReader element(const YAML::Node& node, const std::string& dotted_name);

  /// Records an error at `key` (or at the map if `key` is empty): for rules a reader checks
  /// itself, e.g. "must be > 0, got -250".
  void fail(const std::string& key, const std::string& what);

  /// Merges a child's errors and unknown keys into this reader.
  void absorb(MapReader& child);

  /// Ok, or kConfig with every error and every unknown key, one per line.
  Status finish();

  /// Location "file:line:col" of `key`'s value (or of the map).
  std::string where(const std::string& key) const;

  const std::string& path() const { return doc_->path; }
  const YAML::Node& node() const { return map_; }

 private:
  template <typename T>
  void read(const std::string& key, T& out, bool is_required);
  bool convert_scalar(const std::string& key, const YAML::Node& node, std::string& out);
  bool convert_scalar(const std::string& key, const YAML::Node& node, bool& out);
  bool convert_scalar(const std::string& key, const YAML::Node& node, double& out);
  bool convert_scalar(const std::string& key, const YAML::Node& node, std::int64_t& out);
  bool convert_scalar(const std::string& key, const YAML::Node& node, std::uint32_t& out);
  bool convert_scalar(const std::string& key, const YAML::Node& node, int& out);
  template <typename T>
  bool convert_scalar(const std::string& key, const YAML::Node& node, std::vector<T>& out);
  template <typename T, std::size_t N>
  bool convert_scalar(const std::string& key, const YAML::Node& node, std::array<T, N>& out);
  std::string dotted(const std::string& key) const;

  std::shared_ptr<const Document> doc_;
  YAML::Node map_;
  std::string prefix_;
  std::set<std::string> known_;
  std::vector<std::string> errors_;
  bool is_map_ = true;
};

template <typename T>
void MapReader::read(const std::string& key, T& out, bool is_required) {
  known_.insert(key);
  if (!is_map_) {
    return;
  }
  const YAML::Node node = map_[key];
  if (!node.IsDefined() || node.IsNull()) {
    if (is_required) {
      fail("", "missing required key '" + dotted(key) + "'");
    }
    return;
  }
  (void)convert_scalar(key, node, out);
}

template <typename T>
bool MapReader::convert_scalar(const std::string& key, const YAML::Node& node,
                               std::vector<T>& out) {
  if (!node.IsSequence()) {
    fail(key, "expected a list");
    return false;
  }
  std::vector<T> values;
  for (std::size_t i = 0; i < node.size(); ++i) {
    T value{};
    if (!convert_scalar(key + "[" + std::to_string(i) + "]", node[i], value)) {
      return false;
    }
    values.push_back(value);
  }
  out = std::move(values);
  return true;
}

template <typename T, std::size_t N>
bool MapReader::convert_scalar(const std::string& key, const YAML::Node& node,
                               std::array<T, N>& out) {
  if (!node.IsSequence() || node.size() != N) {
    fail(key, "expected a list of " + std::to_string(N) + " values");
    return false;
  }
  for (std::size_t i = 0; i < N; ++i) {
    if (!convert_scalar(key + "[" + std::to_string(i) + "]", node[i], out[i])) {
      return false;
    }
  }
  return true;
}

}  // namespace cell::config
