#pragma once

#include <string>

namespace cell::service {

/// The checkout (or install) root that relative config paths are resolved against:
/// $CELL_HOME if set, else the source directory this binary was built from.
std::string cell_home();

/// `path` if it is absolute or exists relative to the working directory; otherwise
/// cell_home()/path.
std::string resolve_path(const std::string& path);

}  // namespace cell::service
