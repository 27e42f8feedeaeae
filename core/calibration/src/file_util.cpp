#include "file_util.hpp"

#include <cerrno>
#include <cstring>
#include <filesystem>
#include <fstream>

#include <fmt/format.h>

namespace cell::calibration::detail {

Status write_atomically(const std::string& path, const std::string& text) {
  namespace fs = std::filesystem;
  std::error_code ec;
  const fs::path parent = fs::path(path).parent_path();
  if (!parent.empty()) {
    fs::create_directories(parent, ec);
    if (ec) {
      return Error{Errc::kIo, fmt::format("{}: cannot create: {}", parent.string(), ec.message())};
    }
  }
  const std::string tmp = path + ".tmp";
  {
    std::ofstream f(tmp, std::ios::trunc);
    if (!f) {
      return Error{Errc::kIo, fmt::format("{}: cannot write: {}", tmp, std::strerror(errno))};
    }
    f << text;
    f.flush();
    if (!f) {
      return Error{Errc::kIo, fmt::format("{}: write failed: {}", tmp, std::strerror(errno))};
    }
  }
  fs::rename(tmp, path, ec);
  if (ec) {
    return Error{Errc::kIo, fmt::format("{}: cannot rename to {}: {}", tmp, path, ec.message())};
  }
  return ok_status();
}

}  // namespace cell::calibration::detail
