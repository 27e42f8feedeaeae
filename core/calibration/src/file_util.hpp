#pragma once

// Files and numbers of the calibration library (private).

#include <string>

#include <fmt/format.h>

#include "cell/common/result.hpp"

namespace cell::calibration::detail {

/// Writes `text` to `path` through `path.tmp` and a rename, so a reader never sees half a
/// file; creates the parent directory. Errors: kIo naming the file and the system's reason.
Status write_atomically(const std::string& path, const std::string& text);

/// `v` with every digit a double needs to read back the same (%.17g): calibration files
/// round-trip exactly.
inline std::string exact_number(double v) { return fmt::format("{:.17g}", v); }

}  // namespace cell::calibration::detail
