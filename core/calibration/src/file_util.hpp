#pragma once

// Files of the calibration library (private).

#include <string>

#include "cell/common/result.hpp"

namespace cell::calibration::detail {

/// Writes `text` to `path` through `path.tmp` and a rename, so a reader never sees half a
/// file; creates the parent directory. Errors: kIo naming the file and the system's reason.
Status write_atomically(const std::string& path, const std::string& text);

}  // namespace cell::calibration::detail
